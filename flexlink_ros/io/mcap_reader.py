"""
A bounded, salvaging reader of MCAP files for ``mcap-info``, ``mcap-recover`` and ``replay``.

It reads any MCAP file, whole, truncated or damaged, and yields every intact record, skipping
what is damaged with a counted, one-line reason; it never allocates beyond stated bounds:

- A chunk may declare at most ``MAX_CHUNK_BYTES`` (64 MiB) uncompressed, and at most
  ``MAX_CHUNK_RATIO`` (1000) times its compressed size once above ``CHUNK_RATIO_FLOOR``
  (64 KiB). It is decompressed with that bound on the output (zstd: the frame's own content
  size is checked first, since zstandard allocates it without looking at ``max_output_size``),
  then its CRC and every record in it are checked before any of its records is used: a chunk
  is used whole or not at all.
- At most ``MAX_CHUNK_RATIO`` times the file's size plus ``MAX_CHUNK_BYTES`` is decompressed
  per file in all (so overlapping candidates met while resynchronising cannot add up).
- Record lengths are checked against what contains them (the file, the chunk); strings, maps
  and schema data against their record. The file itself is memory-mapped, never read whole.

Salvage. A chunk whose length, decompression, CRC or records fail is skipped and reported
with its offset and reason; reading goes on at the chunk's end if a plausible record starts
there, else at the next chunk record (found by scanning for its opcode) whose lengths agree and
whose CRC checks. Schemas and channels come from the chunks and, if the file has an intact
summary, from the summary's repeated copies (so messages after a damaged first chunk keep
their channel). A file cut short ends at its last complete chunk.
"""

import dataclasses
import mmap
import os
import stat
import struct
import zlib

import numpy as np

from .mcap_records import (
    CHANNEL, CHUNK, CHUNK_HEAD, DATA_END, DATA_OPCODES, decode_chunk, decompression_budget, FOOTER,
    HEADER, KNOWN_OPCODES, MCAP_MAGIC, MESSAGE, MESSAGE_HEAD_SIZE, MESSAGE_INDEX, opcode_name,
    parse_channel, parse_schema, read_strings, RECORD_PREFIX, records_in, SCHEMA, STATISTICS,
)
from ..errors import DamagedRecord, McapFileError

MAX_DAMAGE_REPORTED = 1000  # damaged places listed per file (all are counted)


@dataclasses.dataclass
class Salvage:
    """What a walk over one file found besides its messages (filled while iterating)."""

    size: int = 0
    profile: str = None
    library: str = None
    schemas: dict = dataclasses.field(default_factory=dict)
    channels: dict = dataclasses.field(default_factory=dict)
    chunk_count: int = 0          # intact chunks read
    damaged: list = dataclasses.field(default_factory=list)   # (offset, reason)
    damaged_count: int = 0
    summary: dict = None          # 'message_count', 'chunk_count' of an intact summary
    channel_counts: dict = None   # channel id -> messages, from an intact summary's statistics
    budget: list = None           # [bytes still to decompress]; set by iter_messages
    end_reason: str = 'empty'
    readable_bytes: int = 0       # offset where reading ended

    def damage(self, offset, reason):
        self.damaged_count += 1
        if len(self.damaged) < MAX_DAMAGE_REPORTED:
            self.damaged.append((offset, reason))


def map_file(path):
    """
    Map a file into memory, read-only (an empty file gives ``b''``).

    Raises
    ------
    McapFileError
        The path is not a regular file (a FIFO, a device) or does not start with the MCAP
        magic.

    """
    # Without blocking (a FIFO would wait for a writer for ever), and only a regular file.
    descriptor = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC)
    with os.fdopen(descriptor, 'rb') as stream:
        if not stat.S_ISREG(os.fstat(descriptor).st_mode):
            raise McapFileError(f'{path} is not a regular file')
        if stream.read(len(MCAP_MAGIC)) != MCAP_MAGIC:
            raise McapFileError(f'{path} is not an MCAP file (bad magic)')
        return mmap.mmap(stream.fileno(), 0, access=mmap.ACCESS_READ)


def iter_messages(buffer, salvage):
    """
    Yield the messages of every intact part of an MCAP file, in file order.

    Parameters
    ----------
    buffer : bytes or mmap
        The whole file (starting with the magic).
    salvage : Salvage
        Filled as reading goes on (schemas and channels are there before their messages).

    Yields
    ------
    (records, start, end) : (bytes, int, int)
        A message record's body ``records[start:end]`` (channel id, sequence, log and
        publish time, data; :func:`message_fields`), at least ``MESSAGE_HEAD_SIZE`` long.

    """
    for records, messages in iter_message_units(buffer, salvage):
        for start, end in messages:
            yield records, start, end


def iter_message_units(buffer, salvage):
    """
    Yield the messages of every intact part of an MCAP file a unit (a chunk) at a time.

    As :func:`iter_messages`, for readers that take a chunk's messages together.

    Yields
    ------
    (records, messages) : (bytes, list of (int, int))
        The unit's records (a decompressed chunk, or the file for a message outside chunks)
        and the (start, end) of each message body in them, in file order.

    """
    size = salvage.size = len(buffer)
    salvage.budget = [decompression_budget(size)]
    read_summary(buffer, salvage)
    offset = len(MCAP_MAGIC)
    while True:
        salvage.readable_bytes = offset
        if offset + RECORD_PREFIX.size > size:
            salvage.end_reason = ('end of file without footer' if offset == size
                                  else 'truncated record prefix')
            return
        opcode, length = RECORD_PREFIX.unpack_from(buffer, offset)
        end = offset + RECORD_PREFIX.size + length
        if _data_section_ends(buffer, offset, opcode, length):
            salvage.end_reason = 'complete'
            return
        if end > size or (opcode not in DATA_OPCODES and opcode < 0x80):
            resume = find_chunk(buffer, offset + 1, salvage.budget)
            if resume is None:
                salvage.end_reason = (f'truncated inside a {opcode_name(opcode)} record '
                                      f'at offset {offset}' if end > size else
                                      f'unknown {opcode_name(opcode)} at offset {offset}')
                return
            what = 'does not fit in the file' if end > size else 'is not an MCAP record'
            salvage.damage(offset, f'{opcode_name(opcode)} of {length} bytes {what}; '
                           f'resumed at the chunk at {resume}')
            offset = resume
            continue
        try:
            unit = _records(buffer, offset, end, opcode, salvage)
        except DamagedRecord as exc:
            resume = (end if _plausible_record(buffer, end)
                      else find_chunk(buffer, offset + 1, salvage.budget))
            where = 'end of file' if resume is None else resume
            salvage.damage(offset, f'{opcode_name(opcode)}: {exc}; skipped to {where}')
            if resume is None:
                salvage.readable_bytes, salvage.end_reason = size, 'end of file without footer'
                return
            end = resume
        else:
            if unit[1]:
                yield unit
        offset = end


def _data_section_ends(buffer, offset, opcode, length):
    # A data end record of its size, or the footer where it belongs (a damaged opcode that
    # reads as one of these must not end salvage early).
    if opcode == DATA_END:
        return length == 4 and offset + RECORD_PREFIX.size + length <= len(buffer)
    return opcode == FOOTER and length == 20 and \
        offset + RECORD_PREFIX.size + length + len(MCAP_MAGIC) == len(buffer)


def _records(buffer, offset, end, opcode, salvage):
    # (records, [(start, end)] of its messages) of one top-level record (a chunk's after
    # checking all of it).
    if opcode == CHUNK:
        payload = decode_chunk(buffer, offset + RECORD_PREFIX.size, end, salvage.budget)
        records, start, stop = payload, 0, len(payload)
    else:
        records, start, stop = buffer, offset, end
    messages = []
    schemas, channels = {}, {}
    header = None
    for code, body, position in records_in(records, start, stop):
        length = position - body
        if code == MESSAGE:
            if length < MESSAGE_HEAD_SIZE:
                raise DamagedRecord(f'message of {length} bytes')
            messages.append((body, position))
            # A chunk's messages all of one length (one topic, one publisher) are the rest of
            # it, as a rule: checked and listed at once, not walked one by one.
            run = equal_messages(records, position, stop) if len(messages) == 1 and (
                opcode == CHUNK) else None
            if run is not None:
                messages += run
                break
        elif code == CHANNEL:
            channel = parse_channel(records, body, position)
            channels[channel.id] = channel
        elif code == SCHEMA:
            schema = parse_schema(records, body, position)
            schemas[schema.id] = schema
        elif code == HEADER:
            header = read_strings(records, body, position, 2)[0]
        elif code == MESSAGE_INDEX:
            entries = struct.unpack_from('<I', records, body + 2)[0] if length >= 6 else -1
            if entries != length - 6 or entries % 16:
                raise DamagedRecord(f'message index of {length} bytes lists {entries}')
    # Only now, with every record of it checked, is the unit used.
    if opcode == CHUNK:
        salvage.chunk_count += 1
    if header is not None and salvage.profile is None:
        salvage.profile, salvage.library = header
    salvage.schemas.update(schemas)
    salvage.channels.update(channels)
    return records, messages


def equal_messages(records, start, stop):
    """
    Return the (body start, end) of every record of ``records[start:stop]``, all messages.

    Only where all are message records of one length (at least a message head), checked with
    numpy at once; else None (the records are then walked one by one).
    """
    if start == stop:
        return []
    if stop - start < RECORD_PREFIX.size:
        return None
    code, length = RECORD_PREFIX.unpack_from(records, start)
    size = RECORD_PREFIX.size + length
    if code != MESSAGE or length < MESSAGE_HEAD_SIZE or (stop - start) % size:
        return None
    prefixes = np.frombuffer(records, dtype=np.uint8, count=stop - start, offset=start).reshape(
        -1, size)[:, :RECORD_PREFIX.size]
    if not (np.all(prefixes[:, 0] == MESSAGE)
            and np.all(prefixes[:, 1:].copy().view('<u8') == length)):
        return None
    bodies = start + RECORD_PREFIX.size + size * np.arange(len(prefixes), dtype=np.int64)
    return list(zip(bodies.tolist(), (bodies + length).tolist()))


def _plausible_record(buffer, offset):
    # A record that fits could start at offset (or the file ends there).
    if offset == len(buffer):
        return True
    if offset + RECORD_PREFIX.size > len(buffer):
        return False
    opcode, length = RECORD_PREFIX.unpack_from(buffer, offset)
    return (opcode in KNOWN_OPCODES or opcode >= 0x80) and \
        offset + RECORD_PREFIX.size + length <= len(buffer)


def find_chunk(buffer, offset, budget=None):
    """Offset of the next chunk record at or after ``offset`` that decodes with a CRC; or None."""
    size = len(buffer)
    while True:
        offset = buffer.find(b'\x06', offset)
        if offset < 0 or offset + RECORD_PREFIX.size + CHUNK_HEAD.size + 8 > size:
            return None
        (length,) = struct.unpack_from('<Q', buffer, offset + 1)
        end = offset + RECORD_PREFIX.size + length
        if end <= size and _chunk_with_crc(buffer, offset + RECORD_PREFIX.size, end, budget):
            return offset
        offset += 1


def _chunk_with_crc(buffer, start, end, budget):
    if end - start < CHUNK_HEAD.size + 8 or CHUNK_HEAD.unpack_from(buffer, start)[3] == 0:
        return False
    try:
        decode_chunk(buffer, start, end, budget)
    except DamagedRecord:
        return False
    return True


def read_summary(buffer, salvage):
    """Fill ``salvage`` from an intact summary section (schemas, channels, statistics)."""
    size = len(buffer)
    footer = size - len(MCAP_MAGIC) - RECORD_PREFIX.size - 20
    if footer < len(MCAP_MAGIC) or buffer[size - len(MCAP_MAGIC):] != MCAP_MAGIC:
        return
    opcode, length = RECORD_PREFIX.unpack_from(buffer, footer)
    summary_start, _, crc = struct.unpack_from('<QQI', buffer, footer + RECORD_PREFIX.size)
    if opcode != FOOTER or length != 20 or summary_start == 0:
        return
    if not len(MCAP_MAGIC) <= summary_start <= footer:
        return
    if crc and zlib.crc32(buffer[summary_start:footer + RECORD_PREFIX.size + 16]) != crc:
        return
    schemas, channels, statistics, channel_counts = {}, {}, None, None
    try:
        for code, body, offset in records_in(buffer, summary_start, footer):
            length = offset - body
            if code == SCHEMA:
                schema = parse_schema(buffer, body, offset)
                schemas[schema.id] = schema
            elif code == CHANNEL:
                channel = parse_channel(buffer, body, offset)
                channels[channel.id] = channel
            elif code == STATISTICS and length >= 42:
                message_count, *_, chunk_count = struct.unpack_from('<QHIIII', buffer, body)
                statistics = {'message_count': message_count, 'chunk_count': chunk_count}
                channel_counts = _channel_message_counts(buffer, body + 42, offset)
    except (DamagedRecord, struct.error):
        return
    salvage.schemas.update(schemas)
    salvage.channels.update(channels)
    salvage.summary = statistics or {}
    salvage.channel_counts = channel_counts


def _channel_message_counts(buffer, offset, end):
    # The statistics' map of channel id (uint16) -> message count (uint64), or None.
    if offset + 4 > end:
        return None
    (length,) = struct.unpack_from('<I', buffer, offset)
    if length % 10 or offset + 4 + length > end:
        raise DamagedRecord('statistics: channel message counts do not fit their record')
    return dict(struct.iter_unpack('<HQ', bytes(buffer[offset + 4:offset + 4 + length])))
