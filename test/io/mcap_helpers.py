"""Hand-made MCAP records: zstd frames of zeros and chunk records around them."""

import struct

from flexlink_ros.io import mcap_records
import zstandard

T0_NS = 1_700_000_000_000_000_000


def zstd_zeros(size):
    """Compress ``size`` zero bytes into a zstd frame (content size in its header), streaming."""
    compressor = zstandard.ZstdCompressor(level=1).compressobj(size=size)
    block = bytes(1 << 20)
    parts = [compressor.compress(block) for _ in range(size >> 20)]
    return b''.join(parts) + compressor.flush()


def chunk_record(records_compressed, uncompressed_size, crc=0, compression=b'zstd'):
    body = struct.pack('<QQQII', T0_NS, T0_NS, uncompressed_size, crc, len(compression)) + \
        compression + struct.pack('<Q', len(records_compressed)) + records_compressed
    return struct.pack('<BQ', mcap_records.CHUNK, len(body)) + body
