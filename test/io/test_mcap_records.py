"""mcap_records: chunk decompression bounded by size and ratio, for zstd and lz4."""

import math
import random
import struct
import zlib

from flexlink_ros.io import mcap_records
from mcap_helpers import chunk_record, zstd_zeros
import pytest
import zstandard


def test_a_bomb_within_the_size_bound_but_beyond_the_ratio_is_refused(tmp_path):
    declared = 32 * 2**20      # under 64 MiB, but about 3000 times its compressed size
    frame = zstd_zeros(declared)
    assert declared > mcap_records.MAX_CHUNK_RATIO * len(frame)
    with pytest.raises(mcap_records.DamagedRecord, match='bound'):
        mcap_records.decode_chunk(chunk_record(frame, declared), 9,
                                  len(chunk_record(frame, declared)))
    # A frame that claims less than the chunk, or more, is refused before decompressing.
    noise = random.Random(1).randbytes(2**16)
    frame = zstandard.ZstdCompressor().compress(noise)
    for claimed in (2**16 - 1, 2**16 + 1):
        record = chunk_record(frame, claimed)
        with pytest.raises(mcap_records.DamagedRecord, match='zstd frame declares 65536 bytes'):
            mcap_records.decode_chunk(record, 9, len(record))
    record = chunk_record(frame, 2**16, zlib.crc32(noise))
    assert mcap_records.decode_chunk(record, 9, len(record)) == noise
    records = b''.join(bytes([mcap_records.MESSAGE]) + struct.pack('<Q', 30) + bytes(30)
                       for _ in range(10))
    record = chunk_record(records, len(records), zlib.crc32(records), b'')
    assert mcap_records.decode_chunk(record, 9, len(record)) == records
    assert math.isclose(mcap_records.chunk_bound(10), mcap_records.CHUNK_RATIO_FLOOR)


def test_lz4_chunks_are_decompressed_within_their_declared_size():
    import lz4.frame
    records = b''.join(bytes([mcap_records.MESSAGE]) + struct.pack('<Q', 30) + bytes(30)
                       for _ in range(100))
    frame = lz4.frame.compress(records)
    record = chunk_record(frame, len(records), zlib.crc32(records), b'lz4')
    assert mcap_records.decode_chunk(record, 9, len(record)) == records
    # The same frame under a smaller declared size: refused after at most that many bytes.
    record = chunk_record(frame, len(records) // 2, 0, b'lz4')
    with pytest.raises(mcap_records.DamagedRecord, match='does not end after the 1950 bytes'):
        mcap_records.decode_chunk(record, 9, len(record))
    record = chunk_record(frame[:-4], len(records), 0, b'lz4')
    with pytest.raises(mcap_records.DamagedRecord, match='does not end after the 3900 bytes'):
        mcap_records.decode_chunk(record, 9, len(record))
    record = chunk_record(frame[:12] + b'\xff' * 8 + frame[20:], len(records), 0, b'lz4')
    with pytest.raises(mcap_records.DamagedRecord, match='lz4'):
        mcap_records.decode_chunk(record, 9, len(record))
