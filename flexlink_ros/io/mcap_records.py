"""
MCAP records, read and checked: prefixes, schemas, channels, messages and chunks.

The building blocks of :mod:`flexlink_ros.io.mcap_reader`: every length is checked against what
contains it (the file, the chunk, the record) and a chunk is decompressed with a bound on its
output (:func:`chunk_bound`; zstd: the frame's own content size is checked first, since
zstandard allocates it without looking at ``max_output_size``), then its CRC is checked. What
does not fit raises :class:`~flexlink_ros.errors.DamagedRecord`. zstandard and lz4 are needed
only for chunks compressed with them.
"""

import dataclasses
import struct
import zlib

from ..errors import DamagedRecord

try:
    import lz4.frame
except ImportError:   # needed only for lz4 chunks
    lz4 = None
try:
    import zstandard
except ImportError:   # needed only for zstd chunks
    zstandard = None

MCAP_MAGIC = b'\x89MCAP0\r\n'
MAX_CHUNK_BYTES = 64 * 2**20  # largest uncompressed chunk read (the recorder writes 128 KiB)
MAX_CHUNK_RATIO = 1000  # largest uncompressed / compressed size of a chunk above the floor
CHUNK_RATIO_FLOOR = 64 * 2**10  # chunks up to this size are not held to the ratio
MAX_COMPRESSION_NAME = 32  # bytes of a chunk's compression name ('zstd', 'lz4', '')

HEADER, FOOTER, SCHEMA, CHANNEL, MESSAGE, CHUNK = 0x01, 0x02, 0x03, 0x04, 0x05, 0x06
STATISTICS, DATA_END = 0x0B, 0x0F
MESSAGE_INDEX = 0x07
KNOWN_OPCODES = frozenset(range(0x01, 0x10))  # 0x80-0xff are user records, skipped by length
# What the data section holds (the rest belongs to the summary; anything else there is damage).
DATA_OPCODES = frozenset((HEADER, SCHEMA, CHANNEL, MESSAGE, CHUNK, MESSAGE_INDEX, 0x09, 0x0C))
RECORD_PREFIX = struct.Struct('<BQ')
CHUNK_HEAD = struct.Struct('<QQQII')  # start, end, uncompressed size, crc, name length
MESSAGE_HEAD = struct.Struct('<HIQQ')  # channel id, sequence, log time, publish time
MESSAGE_HEAD_SIZE = MESSAGE_HEAD.size
OPCODE_NAMES = {HEADER: 'header', FOOTER: 'footer', SCHEMA: 'schema', CHANNEL: 'channel',
                MESSAGE: 'message', CHUNK: 'chunk', MESSAGE_INDEX: 'message index',
                0x08: 'chunk index', 0x09: 'attachment', 0x0A: 'attachment index',
                STATISTICS: 'statistics', 0x0C: 'metadata', 0x0D: 'metadata index',
                0x0E: 'summary offset', DATA_END: 'data end'}


@dataclasses.dataclass
class SchemaRecord:
    id: int   # noqa: A003  the MCAP specification's field name
    name: str
    encoding: str
    data: bytes


@dataclasses.dataclass
class ChannelRecord:
    id: int   # noqa: A003  the MCAP specification's field name
    schema_id: int
    topic: str
    message_encoding: str
    metadata: dict


def opcode_name(opcode):
    """Readable name of a record opcode."""
    return OPCODE_NAMES.get(opcode, f'opcode {opcode:#04x}')


def records_in(buffer, start, stop):
    """
    Yield (opcode, body start, end) of each record in ``buffer[start:stop]``, lengths checked.

    Raises DamagedRecord where a record's prefix or body does not fit in ``stop``.
    """
    position = start
    while position < stop:
        if position + RECORD_PREFIX.size > stop:
            raise DamagedRecord(f'record prefix cut at {position}')
        code, length = RECORD_PREFIX.unpack_from(buffer, position)
        body, position = position + RECORD_PREFIX.size, position + RECORD_PREFIX.size + length
        if position > stop:
            raise DamagedRecord(f'{opcode_name(code)} of {length} bytes overruns its container')
        yield code, body, position


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
    Return the checked, uncompressed records of a chunk record's body ``buffer[start:end]``.

    ``budget``, if given, is ``[bytes]`` still allowed to be decompressed (reduced here).

    Raises
    ------
    DamagedRecord
        Lengths that disagree, a size beyond :func:`chunk_bound`, unknown compression, a
        decompression error or a CRC mismatch.

    """
    if end - start < CHUNK_HEAD.size + 8:
        raise DamagedRecord(f'chunk record of {end - start} bytes')
    _, _, raw_size, crc, name_length = CHUNK_HEAD.unpack_from(buffer, start)
    position = start + CHUNK_HEAD.size
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
    if zstandard is None:
        raise ImportError('a zstd chunk needs the zstandard package')
    try:
        # zstandard allocates a frame's declared content size whatever max_output_size says.
        declared = zstandard.frame_content_size(data)
        if declared not in (-1, raw_size):
            raise DamagedRecord(f'zstd frame declares {declared} bytes, the chunk {raw_size}')
        return zstandard.ZstdDecompressor().decompress(data, max_output_size=raw_size)
    except zstandard.ZstdError as exc:
        raise DamagedRecord(f'zstd: {exc}') from None


def _lz4(data, raw_size):
    if lz4 is None:
        raise ImportError('an lz4 chunk needs the lz4 package')
    decompressor = lz4.frame.LZ4FrameDecompressor()
    try:
        payload = decompressor.decompress(data, max_length=raw_size)
    except RuntimeError as exc:
        raise DamagedRecord(f'lz4: {exc}') from None
    if not decompressor.eof:
        raise DamagedRecord(f'lz4 frame does not end after the {raw_size} bytes declared'
                            if len(payload) >= raw_size else 'lz4 frame cut short')
    return payload


def read_strings(buffer, offset, end, count):
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
    """Parse a schema record's body ``buffer[start:end]`` (checked against its length)."""
    if start + 2 > end:
        raise DamagedRecord('schema record too short')
    (schema_id,) = struct.unpack_from('<H', buffer, start)
    (name, encoding), offset = read_strings(buffer, start + 2, end, 2)
    data, _ = _read_bytes(buffer, offset, end, 4)
    return SchemaRecord(schema_id, name, encoding, data)


def parse_channel(buffer, start, end):
    """Parse a channel record's body ``buffer[start:end]`` (checked against its length)."""
    if start + 4 > end:
        raise DamagedRecord('channel record too short')
    channel_id, schema_id = struct.unpack_from('<HH', buffer, start)
    (topic, encoding), offset = read_strings(buffer, start + 4, end, 2)
    entries, _ = _read_bytes(buffer, offset, end, 4)
    metadata, position = {}, 0
    while position < len(entries):
        (key, value), position = read_strings(entries, position, len(entries), 2)
        metadata[key] = value
    return ChannelRecord(channel_id, schema_id, topic, encoding, metadata)
