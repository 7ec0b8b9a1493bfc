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
import struct
import zlib

from ..errors import DamagedRecord, FlexlinkError, McapFileError

MCAP_MAGIC = b'\x89MCAP0\r\n'
MAX_CHUNK_BYTES = 64 * 2**20  # largest uncompressed chunk read (the recorder writes 128 KiB)
MAX_CHUNK_RATIO = 1000  # largest uncompressed / compressed size of a chunk above the floor
CHUNK_RATIO_FLOOR = 64 * 2**10  # chunks up to this size are not held to the ratio
MAX_COMPRESSION_NAME = 32  # bytes of a chunk's compression name ('zstd', 'lz4', '')
MAX_DAMAGE_REPORTED = 1000  # damaged places listed per file (all are counted)

HEADER, FOOTER, SCHEMA, CHANNEL, MESSAGE, CHUNK = 0x01, 0x02, 0x03, 0x04, 0x05, 0x06
STATISTICS, DATA_END = 0x0B, 0x0F
MESSAGE_INDEX = 0x07
KNOWN_OPCODES = frozenset(range(0x01, 0x10))  # 0x80-0xff are user records, skipped by length
# What the data section holds (the rest belongs to the summary; anything else there is damage).
DATA_OPCODES = frozenset((HEADER, SCHEMA, CHANNEL, MESSAGE, CHUNK, MESSAGE_INDEX, 0x09, 0x0C))
_PREFIX = struct.Struct('<BQ')
_CHUNK_HEAD = struct.Struct('<QQQII')  # start, end, uncompressed size, crc, name length
MESSAGE_HEAD = struct.Struct('<HIQQ')  # channel id, sequence, log time, publish time
MESSAGE_HEAD_SIZE = MESSAGE_HEAD.size
OPCODE_NAMES = {HEADER: 'header', FOOTER: 'footer', SCHEMA: 'schema', CHANNEL: 'channel',
                MESSAGE: 'message', CHUNK: 'chunk', MESSAGE_INDEX: 'message index',
                0x08: 'chunk index', 0x09: 'attachment', 0x0A: 'attachment index',
                STATISTICS: 'statistics', 0x0C: 'metadata', 0x0D: 'metadata index',
                0x0E: 'summary offset', DATA_END: 'data end'}


@dataclasses.dataclass
class SchemaRecord:
    id: int
    name: str
    encoding: str
    data: bytes


@dataclasses.dataclass
class ChannelRecord:
    id: int
    schema_id: int
    topic: str
    message_encoding: str
    metadata: dict


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
    budget: list = None           # [bytes still to decompress]; set by iter_messages
    end_reason: str = 'empty'
    readable_bytes: int = 0       # offset where reading ended

    def damage(self, offset, reason):
        self.damaged_count += 1
        if len(self.damaged) < MAX_DAMAGE_REPORTED:
            self.damaged.append((offset, reason))


def opcode_name(opcode):
    """Readable name of a record opcode."""
    return OPCODE_NAMES.get(opcode, f'opcode {opcode:#04x}')


def map_file(path):
    """
    The bytes of a file, memory-mapped (an empty file gives ``b''``).

    Raises
    ------
    McapFileError
        The file does not start with the MCAP magic.

    """
    with open(path, 'rb') as stream:
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
    size = salvage.size = len(buffer)
    salvage.budget = [decompression_budget(size)]
    _read_summary(buffer, salvage)
    offset = len(MCAP_MAGIC)
    while True:
        salvage.readable_bytes = offset
        if offset + _PREFIX.size > size:
            salvage.end_reason = ('end of file without footer' if offset == size
                                  else 'truncated record prefix')
            return
        opcode, length = _PREFIX.unpack_from(buffer, offset)
        end = offset + _PREFIX.size + length
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
            yield from _records(buffer, offset, end, opcode, salvage)
        except DamagedRecord as exc:
            resume = (end if _plausible_record(buffer, end)
                      else find_chunk(buffer, offset + 1, salvage.budget))
            where = 'end of file' if resume is None else resume
            salvage.damage(offset, f'{opcode_name(opcode)}: {exc}; skipped to {where}')
            if resume is None:
                salvage.readable_bytes, salvage.end_reason = size, 'end of file without footer'
                return
            end = resume
        offset = end


def _data_section_ends(buffer, offset, opcode, length):
    # A data end record of its size, or the footer where it belongs (a damaged opcode that
    # reads as one of these must not end salvage early).
    if opcode == DATA_END:
        return length == 4 and offset + _PREFIX.size + length <= len(buffer)
    return opcode == FOOTER and length == 20 and \
        offset + _PREFIX.size + length + len(MCAP_MAGIC) == len(buffer)


def records_in(buffer, start, stop):
    """(opcode, body start, end) of each record in ``buffer[start:stop]``, lengths checked.

    Raises DamagedRecord where a record's prefix or body does not fit in ``stop``.
    """
    position = start
    while position < stop:
        if position + _PREFIX.size > stop:
            raise DamagedRecord(f'record prefix cut at {position}')
        code, length = _PREFIX.unpack_from(buffer, position)
        body, position = position + _PREFIX.size, position + _PREFIX.size + length
        if position > stop:
            raise DamagedRecord(f'{opcode_name(code)} of {length} bytes overruns its container')
        yield code, body, position


def _records(buffer, offset, end, opcode, salvage):
    # The messages of one top-level record (a chunk's after checking all of it).
    if opcode == CHUNK:
        payload = decode_chunk(buffer, offset + _PREFIX.size, end, salvage.budget)
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
        elif code == CHANNEL:
            channel = parse_channel(records, body, position)
            channels[channel.id] = channel
        elif code == SCHEMA:
            schema = parse_schema(records, body, position)
            schemas[schema.id] = schema
        elif code == HEADER:
            header = _read_strings(records, body, position, 2)[0]
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
    for body, stop in messages:
        yield records, body, stop


def message_fields(records, start, end):
    """(channel_id, sequence, log_time_ns, publish_time_ns, data) of a message body."""
    return MESSAGE_HEAD.unpack_from(records, start) + (
        bytes(records[start + MESSAGE_HEAD_SIZE:end]),)


def decompression_budget(file_size):
    """Bytes decompressed per file at most (chunks and resynchronisation candidates together)."""
    return MAX_CHUNK_RATIO * file_size + MAX_CHUNK_BYTES


def chunk_bound(compressed_size):
    """Largest uncompressed size accepted for a chunk of this compressed size [bytes]."""
    return min(MAX_CHUNK_BYTES, max(CHUNK_RATIO_FLOOR, MAX_CHUNK_RATIO * compressed_size))


def decode_chunk(buffer, start, end, budget=None):
    """
    The checked, uncompressed records of a chunk record's body ``buffer[start:end]``.

    ``budget``, if given, is ``[bytes]`` still allowed to be decompressed (reduced here).

    Raises
    ------
    DamagedRecord
        Lengths that disagree, a size beyond :func:`chunk_bound`, unknown compression, a
        decompression error or a CRC mismatch.

    """
    if end - start < _CHUNK_HEAD.size + 8:
        raise DamagedRecord(f'chunk record of {end - start} bytes')
    _, _, raw_size, crc, name_length = _CHUNK_HEAD.unpack_from(buffer, start)
    position = start + _CHUNK_HEAD.size
    if name_length > MAX_COMPRESSION_NAME or position + name_length + 8 > end:
        raise DamagedRecord(f'compression name of {name_length} bytes')
    compression = bytes(buffer[position:position + name_length])
    position += name_length
    (length,) = struct.unpack_from('<Q', buffer, position)
    position += 8
    if position + length != end:
        raise DamagedRecord(f'records of {length} bytes in a chunk of {end - start}')
    bound = chunk_bound(length)
    if raw_size > bound:
        raise DamagedRecord(f'declares {raw_size} bytes uncompressed from {length} '
                            f'(bound {bound}: at most {MAX_CHUNK_BYTES >> 20} MiB and '
                            f'{MAX_CHUNK_RATIO}x the compressed size)')
    if budget is not None and compression and raw_size > budget[0]:
        raise DamagedRecord(f'decompression budget of the file exhausted '
                            f'({budget[0]} bytes left, {raw_size} declared)')
    if budget is not None and compression:
        budget[0] -= raw_size
    data = buffer[position:end]
    if compression == b'':
        payload = data
    elif compression == b'zstd':
        payload = _zstd(data, raw_size)
    elif compression == b'lz4':
        payload = _lz4(data, raw_size)
    else:
        raise DamagedRecord(f'unknown compression {compression[:MAX_COMPRESSION_NAME]!r}')
    if len(payload) != raw_size:
        raise DamagedRecord(f'{len(payload)} bytes uncompressed, {raw_size} declared')
    if crc and zlib.crc32(payload) != crc:
        raise DamagedRecord('CRC mismatch')
    return payload


def _zstd(data, raw_size):
    import zstandard
    try:
        # zstandard allocates a frame's declared content size whatever max_output_size says.
        declared = zstandard.frame_content_size(data)
        if declared not in (-1, raw_size):
            raise DamagedRecord(f'zstd frame declares {declared} bytes, the chunk {raw_size}')
        return zstandard.ZstdDecompressor().decompress(data, max_output_size=raw_size)
    except zstandard.ZstdError as exc:
        raise DamagedRecord(f'zstd: {exc}') from None


def _lz4(data, raw_size):
    import lz4.frame
    decompressor = lz4.frame.LZ4FrameDecompressor()
    try:
        payload = decompressor.decompress(data, max_length=raw_size)
    except RuntimeError as exc:
        raise DamagedRecord(f'lz4: {exc}') from None
    if not decompressor.eof:
        raise DamagedRecord(f'lz4 frame does not end after the {raw_size} bytes declared'
                            if len(payload) >= raw_size else 'lz4 frame cut short')
    return payload


def _plausible_record(buffer, offset):
    # A record that fits could start at offset (or the file ends there).
    if offset == len(buffer):
        return True
    if offset + _PREFIX.size > len(buffer):
        return False
    opcode, length = _PREFIX.unpack_from(buffer, offset)
    return (opcode in KNOWN_OPCODES or opcode >= 0x80) and \
        offset + _PREFIX.size + length <= len(buffer)


def find_chunk(buffer, offset, budget=None):
    """Offset of the next chunk record at or after ``offset`` that decodes with a CRC; or None."""
    size = len(buffer)
    while True:
        offset = buffer.find(b'\x06', offset)
        if offset < 0 or offset + _PREFIX.size + _CHUNK_HEAD.size + 8 > size:
            return None
        (length,) = struct.unpack_from('<Q', buffer, offset + 1)
        end = offset + _PREFIX.size + length
        if end <= size and _chunk_with_crc(buffer, offset + _PREFIX.size, end, budget):
            return offset
        offset += 1


def _chunk_with_crc(buffer, start, end, budget):
    if end - start < _CHUNK_HEAD.size + 8 or _CHUNK_HEAD.unpack_from(buffer, start)[3] == 0:
        return False
    try:
        decode_chunk(buffer, start, end, budget)
    except DamagedRecord:
        return False
    return True


def _read_strings(buffer, offset, end, count):
    # count length-prefixed UTF-8 strings from offset, within end: (strings, new offset).
    values = []
    for _ in range(count):
        data, offset = _read_bytes(buffer, offset, end, 4)
        try:
            values.append(data.decode('utf-8'))
        except UnicodeDecodeError:
            raise DamagedRecord(f'string is not UTF-8 at {offset}') from None
    return values, offset


def _read_bytes(buffer, offset, end, prefix):
    if offset + prefix > end:
        raise DamagedRecord(f'length cut at {offset}')
    (length,) = struct.unpack_from('<I' if prefix == 4 else '<Q', buffer, offset)
    offset += prefix
    if offset + length > end:
        raise DamagedRecord(f'{length} bytes declared at {offset - prefix}, '
                            f'{end - offset} left in the record')
    return bytes(buffer[offset:offset + length]), offset + length


def parse_schema(buffer, start, end):
    """A schema record's body ``buffer[start:end]`` (checked against its length)."""
    if start + 2 > end:
        raise DamagedRecord('schema record too short')
    (schema_id,) = struct.unpack_from('<H', buffer, start)
    (name, encoding), offset = _read_strings(buffer, start + 2, end, 2)
    data, _ = _read_bytes(buffer, offset, end, 4)
    return SchemaRecord(schema_id, name, encoding, data)


def parse_channel(buffer, start, end):
    """A channel record's body ``buffer[start:end]`` (checked against its length)."""
    if start + 4 > end:
        raise DamagedRecord('channel record too short')
    channel_id, schema_id = struct.unpack_from('<HH', buffer, start)
    (topic, encoding), offset = _read_strings(buffer, start + 4, end, 2)
    entries, _ = _read_bytes(buffer, offset, end, 4)
    metadata, position = {}, 0
    while position < len(entries):
        (key, value), position = _read_strings(entries, position, len(entries), 2)
        metadata[key] = value
    return ChannelRecord(channel_id, schema_id, topic, encoding, metadata)


def _read_summary(buffer, salvage):
    # Schemas, channels and statistics of an intact summary section (else nothing).
    size = len(buffer)
    footer = size - len(MCAP_MAGIC) - _PREFIX.size - 20
    if footer < len(MCAP_MAGIC) or buffer[size - len(MCAP_MAGIC):] != MCAP_MAGIC:
        return
    opcode, length = _PREFIX.unpack_from(buffer, footer)
    summary_start, _, crc = struct.unpack_from('<QQI', buffer, footer + _PREFIX.size)
    if opcode != FOOTER or length != 20 or summary_start == 0:
        return
    if not len(MCAP_MAGIC) <= summary_start <= footer:
        return
    if crc and zlib.crc32(buffer[summary_start:footer + _PREFIX.size + 16]) != crc:
        return
    schemas, channels, statistics = {}, {}, None
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
    except (DamagedRecord, struct.error):
        return
    salvage.schemas.update(schemas)
    salvage.channels.update(channels)
    salvage.summary = statistics or {}
