"""
Fuzz of the MCAP readers: mutated and truncated copies of a real recording.

Each copy goes through the functions the CLI runs (mcap-info, mcap-recover, replay's reader)
in-process, under tracemalloc; a few go through the real ``flexlink`` script.
"""

import random
import re
import struct
import subprocess
import sys
import tracemalloc
import zlib

from flexlink_ros.cli.mcap import mcap_info, recover_mcap
from flexlink_ros.errors import FlexlinkError
from flexlink_ros.io import joint_states, mcap_records
from flexlink_ros.io import recording as io_recording
import pytest
from test_mcap_reader import chunks_of, read_messages, write_crank_recording
import zstandard

MESSAGES = 1000
PEAK_BOUND = 16 * 2**20  # bytes traced per file: far below any declared size fuzzed


def record_boundaries(data):
    """Offsets of the top-level records of an intact MCAP file (and its end)."""
    offsets, offset = [], 8
    while offset + 9 <= len(data):
        offsets.append(offset)
        offset += 9 + struct.unpack_from('<Q', data, offset + 1)[0]
    return offsets + [len(data)]


def inner_record_edit(data, chunk_offset, opcode, field, value):
    """
    Copy a file, its first chunk re-encoded (valid CRC) with one field edited.

    One field of the chunk's first ``opcode`` record is set to ``value``: the bounds inside a
    chunk, behind a valid CRC.
    """
    payload = mcap_records.decode_chunk(data, chunk_offset + 9,
                                        chunk_offset + 9 + struct.unpack_from(
                                            '<Q', data, chunk_offset + 1)[0])
    payload = bytearray(payload)
    position = 0
    while payload[position] != opcode:
        position += 9 + struct.unpack_from('<Q', payload, position + 1)[0]
    body = position + 9
    if field == 'length':
        struct.pack_into('<Q', payload, position + 1, value)
    elif field == 'first string':     # topic (channel) or name (schema)
        struct.pack_into('<I', payload, body + (4 if opcode == 4 else 2), value)
    elif field == 'last length':      # metadata map (channel) or data (schema)
        offset = body + (4 if opcode == 4 else 2)
        for _ in range(2):
            offset += 4 + struct.unpack_from('<I', payload, offset)[0]
        struct.pack_into('<I', payload, offset, value)
    payload = bytes(payload)
    compressed = zstandard.ZstdCompressor().compress(payload)
    start, end = struct.unpack_from('<QQ', data, chunk_offset + 9)
    chunk = struct.pack('<QQQII', start, end, len(payload), zlib.crc32(payload),
                        4) + b'zstd' + struct.pack('<Q', len(compressed)) + compressed
    old_end = chunk_offset + 9 + struct.unpack_from('<Q', data, chunk_offset + 1)[0]
    return data[:chunk_offset] + struct.pack('<BQ', 6, len(chunk)) + chunk + data[old_end:]


def mutations(data, chunks, rng):
    """(kind, bytes, cut) of about 300 damaged copies; cut is the length of a truncation."""
    boundaries = record_boundaries(data)
    for cut in boundaries[:-1]:
        yield 'truncated at a record boundary', data[:cut], cut
    for cut in sorted(rng.sample(range(8, len(data)), 40)):
        yield 'truncated at a random offset', data[:cut], cut

    def edited(edit):
        copy = bytearray(data)
        edit(copy)
        return bytes(copy)
    for _ in range(60):
        flips = [(rng.randrange(len(data)), 1 << rng.randrange(8))
                 for _ in range(rng.randint(1, 4))]
        yield 'bit flips', edited(lambda d: [d.__setitem__(i, d[i] ^ b) for i, b in flips]), None
    for _ in range(50):
        at, run = rng.randrange(len(data)), rng.randint(1, 64)
        yield 'overwritten bytes', edited(
            lambda d: d.__setitem__(slice(at, at + run), rng.randbytes(run)[:len(d) - at])), None
    for _ in range(40):
        at, run = rng.randrange(len(data)), rng.randint(1, 512)
        yield 'zeroed range', edited(
            lambda d: d.__setitem__(slice(at, at + run), bytes(len(d[at:at + run])))), None
    for _ in range(30):
        at = rng.randrange(8, len(data))
        yield 'inserted bytes', data[:at] + rng.randbytes(rng.randint(1, 64)) + data[at:], None
    for value in (2**63 - 1, 2**40, 2**32 + 7, len(data)):
        for offset in rng.sample(boundaries[:-1], 4):
            yield 'huge record length', edited(
                lambda d: struct.pack_into('<Q', d, offset + 1, value)), None
    for value in (2**40, 2**31, 3 * 2**29, 2**28, 65 * 2**20):
        offset = rng.choice(chunks)[0]
        yield 'huge chunk size', edited(
            lambda d: struct.pack_into('<Q', d, offset + 9 + 16, value)), None
    first = chunks[0][0]
    for opcode, field, value in ((4, 'first string', 0xFFFFFFF0), (4, 'last length', 2**31),
                                 (3, 'first string', 2**32 - 1), (3, 'last length', 2**30),
                                 (5, 'length', 2**62), (4, 'length', 3)):
        yield 'huge length in a chunk', inner_record_edit(data, first, opcode, field, value), None


def read_everything(path, out):
    """Run the three readers; (info, recovered count, replay count) or the refusal."""
    try:
        info = mcap_info(path)
        recovered = recover_mcap(path, out)
        damaged = []
        scan = io_recording.scan_recording(path, topic='/joint_states', damaged=damaged)
        samples = joint_states.read_crank_samples(path, '/joint_states', 'crank', scan)
        try:
            io_recording.choose_input_topic(path, 'crank', scan=scan)
        except ValueError as exc:      # the CLI's one-line refusal: nothing usable
            assert '\n' not in str(exc)
        return info, recovered, len(samples['data']) + samples['skipped']
    except FlexlinkError as exc:     # refused as a whole (not MCAP, nothing readable)
        assert '\n' not in str(exc)
        return exc


def test_mutated_and_truncated_recordings(tmp_path):
    original_path = write_crank_recording(tmp_path / 'original.mcap', MESSAGES,
                                          chunk_size_bytes=4096)
    data = original_path.read_bytes()
    chunks = chunks_of(original_path)
    original = read_messages(original_path)
    rng = random.Random(12)
    tally = {'files': 0, 'refused': 0, 'salvaged': 0, 'complete': 0, 'messages kept': 0,
             'damaged places': 0}
    reasons = {}
    for n, (kind, mutated, cut) in enumerate(mutations(data, chunks, rng)):
        path, out = tmp_path / f'm{n}.mcap', tmp_path / f'r{n}.mcap'
        path.write_bytes(mutated)
        tracemalloc.start()
        result = read_everything(path, out)
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        assert peak < PEAK_BOUND, f'{kind} (file {n}): {peak} bytes traced'
        tally['files'] += 1
        if isinstance(result, FlexlinkError):
            tally['refused'] += 1
            continue
        info, recovered, replayed = result
        kept = read_messages(out)
        # The three readers agree, and nothing is invented: kept messages are the original's,
        # in order.
        assert info['message_count'] == recovered['message_count'] == replayed == len(kept)
        position = iter(original)
        assert all(message in position for message in kept), f'{kind} (file {n})'
        if cut is not None:
            whole = sum(count for offset, length, count in chunks if offset + length <= cut)
            assert kept == original[:whole], f'{kind} at {cut}'
        tally['salvaged'] += bool(kept)
        tally['complete'] += info['complete']
        tally['messages kept'] += len(kept)
        tally['damaged places'] += info['damaged_count']
        for damage in info['damaged']:
            reason = re.sub(r'\d+', 'N', damage['reason'].split(';')[0])[:40]
            reasons[reason] = reasons.get(reason, 0) + 1
        path.unlink()
        out.unlink()
    print('\nMCAP fuzz:', tally, '\nreasons:', sorted(reasons.items(), key=lambda r: -r[1]))
    assert tally['files'] >= 300 and tally['salvaged'] > tally['files'] // 2


@pytest.mark.parametrize('kind', ['bit flips', 'huge record length', 'huge chunk size',
                                  'truncated at a random offset', 'zeroed range'])
def test_mutated_files_through_the_flexlink_script(tmp_path, kind):
    original_path = write_crank_recording(tmp_path / 'original.mcap', 300,
                                          chunk_size_bytes=4096)
    data = original_path.read_bytes()
    rng = random.Random(kind)
    mutated = next(m for k, m, _ in mutations(data, chunks_of(original_path), rng) if k == kind)
    path = tmp_path / 'mutated.mcap'
    path.write_bytes(mutated)
    flexlink = [sys.executable, '-m', 'flexlink_ros.cli.main']
    for args in (['mcap-info', str(path)], ['mcap-recover', str(path), '--out',
                                            str(tmp_path / 'out.mcap')],
                 ['replay', str(path), '--out', str(tmp_path / 'replay.mcap'),
                  '--no-geometric-stiffness', '--markers-every-n', '0', '--mechanism',
                  'cho1992']):
        run = subprocess.run(flexlink + args, capture_output=True, text=True, timeout=300)
        assert 'Traceback' not in run.stderr, run.stderr
        assert run.returncode in (0, 1)
        if run.returncode == 1:
            assert run.stderr.startswith(f'flexlink {args[0]}: error:')
            assert len(run.stderr.strip().splitlines()) == 1
