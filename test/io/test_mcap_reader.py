"""Damaged, truncated and crafted MCAP files through mcap-info, mcap-recover and replay."""

import json
import struct
import subprocess
import sys

from flexlink_ros.cli import main as cli
from flexlink_ros.cli.mcap import mcap_info, recover_mcap
from flexlink_ros.io import joint_states, mcap_reader, mcap_records
from flexlink_ros.io import recording as io_recording
from flexlink_ros.io.recorder import McapRecorder
from flexlink_ros.names import JOINT_STATE
from flexlink_ros.ros import messages as ros_messages
from mcap.reader import make_reader
from mcap_helpers import chunk_record, zstd_zeros
import pytest
from rclpy.serialization import serialize_message
from sensor_msgs.msg import JointState

T0_NS = 1_700_000_000_000_000_000
STEP_NS = 1_000_000
SPEED = 40.0    # rad/s


def crank_state(k, names=('crank',)):
    message = JointState(name=list(names), position=[0.04 * k] * len(names),
                         velocity=[SPEED] * len(names))
    message.header.stamp = ros_messages.ns_to_stamp(T0_NS + k * STEP_NS)
    message.header.frame_id = 'ground'
    return bytes(serialize_message(message))


def write_crank_recording(path, count, chunk_size_bytes=16384, payload=crank_state):
    """Record ``count`` JointStates on /joint_states, log time = stamp + 200 us."""
    with McapRecorder(path, chunk_size_bytes=chunk_size_bytes, flush_thread=False) as recorder:
        recorder.add_topic('/joint_states', JointState)
        for k in range(count):
            recorder.write('/joint_states', payload(k), T0_NS + k * STEP_NS + 200_000)
    return path


def chunks_of(path):
    """(offset, length, message count) of every chunk, from mcap's own summary reader."""
    with open(path, 'rb') as stream:
        summary = make_reader(stream).get_summary()
        messages = [m.log_time for _, _, m in make_reader(stream).iter_messages()]
    return [(c.chunk_start_offset, c.chunk_length,
             sum(c.message_start_time <= t <= c.message_end_time for t in messages))
            for c in summary.chunk_indexes]


def read_messages(path):
    """(topic, log time, data) of every message, by mcap's reader (for written outputs)."""
    with open(path, 'rb') as stream:
        return [(channel.topic, message.log_time, message.data)
                for _, channel, message in make_reader(stream).iter_messages(
                    log_time_order=False)]


@pytest.fixture(scope='module')
def recording(tmp_path_factory):
    path = write_crank_recording(tmp_path_factory.mktemp('rec') / 'crank.mcap', 5000)
    return path, chunks_of(path), read_messages(path)


def damaged_copy(path, tmp_path, edit, name='damaged.mcap'):
    data = bytearray(path.read_bytes())
    edit(data)
    out = tmp_path / name
    out.write_bytes(bytes(data))
    return out


def test_a_bad_crc_in_the_first_chunk_loses_only_that_chunk(recording, tmp_path, capsys):
    path, chunks, original = recording
    assert len(chunks) > 5 and len(original) == 5000
    first, _, lost = chunks[0]
    crc_field = first + 9 + 24      # prefix, then start, end, uncompressed size

    def flip_crc(data):
        data[crc_field] ^= 0x01
    bad = damaged_copy(path, tmp_path, flip_crc)

    info = mcap_info(bad)
    assert not info['complete'] and info['status'] == f'damaged: 1 chunks (offsets {first})'
    assert info['damaged'][0]['reason'].startswith('chunk: CRC mismatch')
    assert info['message_count'] == 5000 - lost and info['summary_message_count'] == 5000
    assert mcap_info(path)['status'] == 'complete'

    out = tmp_path / 'recovered.mcap'
    assert cli.main(['mcap-recover', str(bad), '--out', str(out), '--json']) == 0
    result = json.loads(capsys.readouterr().out)
    assert result['message_count'] == 5000 - lost
    assert result['damaged_count'] == 1 and result['damaged'][0]['offset'] == first
    assert read_messages(out) == original[lost:]        # every message of the intact chunks
    assert mcap_info(out)['complete']

    damaged = []
    counts, kept = io_recording.scan_recording(bad, joint_name='crank', damaged=damaged)
    assert counts == {'/joint_states': [JOINT_STATE, 5000 - lost]}
    assert [data for _, _, data in kept['/joint_states']] == [d for _, _, d in original[lost:]]
    assert [(f, o) for f, o, _ in damaged] == [(str(bad), first)]


def test_a_damaged_chunk_length_is_passed_by_finding_the_next_chunk(recording, tmp_path):
    path, chunks, original = recording
    offset, _, lost = chunks[2]

    def break_length(data):
        data[offset + 1:offset + 9] = struct.pack('<Q', 2**62 + 12345)
    bad = damaged_copy(path, tmp_path, break_length)
    result = recover_mcap(bad, tmp_path / 'out.mcap')
    before = sum(c[2] for c in chunks[:2])
    assert result['message_count'] == 5000 - lost
    assert read_messages(tmp_path / 'out.mcap') == original[:before] + original[before + lost:]
    assert result['damaged'][0]['offset'] == offset
    assert 'does not fit' in result['damaged'][0]['reason']


def test_corrupt_zstd_and_a_foreign_payload_do_not_stop_replay(tmp_path):
    """Replay skips a chunk whose zstd is corrupt and a payload that is not a JointState."""
    def payload(k):
        return b'\x00\x01\x00\x00' + b'\xff' * 7 if k == 700 else crank_state(k)
    path = write_crank_recording(tmp_path / 'rec.mcap', 1500, chunk_size_bytes=4096,
                                 payload=payload)
    chunks = chunks_of(path)
    offset, length, lost = chunks[1]

    def garble(data):
        # Overwrite the middle of the chunk's zstd data and fix nothing else.
        middle = offset + length // 2
        data[middle:middle + 16] = bytes(range(16))
    bad = damaged_copy(path, tmp_path, garble)
    out = tmp_path / 'replay.mcap'
    run = subprocess.run([sys.executable, '-m', 'flexlink_ros.cli.main', 'replay', str(bad),
                          '--out', str(out), '--no-geometric-stiffness', '--json',
                          '--markers-every-n', '0', '--mechanism', 'cho1992'],
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    assert 'Traceback' not in run.stderr
    summary = json.loads(run.stdout)
    assert summary['samples'] == 1500 - lost - 1 and summary['skipped'] == 1
    assert summary['skipped_reasons'] == {
        'not a readable JointState (cut short or malformed)': 1}
    assert [d['offset'] for d in summary['damaged']] == [offset]
    text = subprocess.run([sys.executable, '-m', 'flexlink_ros.cli.main', 'replay', str(bad),
                           '--out', str(tmp_path / 'again.mcap'), '--no-geometric-stiffness',
                           '--markers-every-n', '0', '--mechanism', 'cho1992'],
                          capture_output=True, text=True, timeout=300)
    assert text.returncode == 0
    assert f'skipped damaged data in {bad} at offset {offset}: chunk:' in text.stdout
    assert 'skipped 1 messages: not a readable JointState' in text.stdout


def test_replay_with_nothing_usable_is_a_one_line_error(tmp_path):
    path = write_crank_recording(tmp_path / 'rec.mcap', 300, chunk_size_bytes=4096)
    chunks = chunks_of(path)

    def break_every_crc(data):
        for offset, _, _ in chunks:
            data[offset + 9 + 24] ^= 0xff
    bad = damaged_copy(path, tmp_path, break_every_crc)
    run = subprocess.run([sys.executable, '-m', 'flexlink_ros.cli.main', 'replay', str(bad),
                          '--out', str(tmp_path / 'x.mcap'), '--no-geometric-stiffness',
                          '--mechanism', 'cho1992'],
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 1 and len(run.stderr.strip().splitlines()) == 1
    assert f'{len(chunks)} damaged places skipped' in run.stderr
    assert 'CRC mismatch' in run.stderr


def test_joint_detection_looks_past_the_first_messages(tmp_path):
    """The crank joint first appears in the 50th message of its topic: still found."""
    def payload(k):
        return crank_state(k, ('lever',) if k < 49 else ('crank',))
    path = write_crank_recording(tmp_path / 'rec.mcap', 400, payload=payload)
    scan = io_recording.scan_recording(path, joint_name='crank')
    topic = io_recording.choose_input_topic(path, 'crank', scan=scan)
    samples = joint_states.read_crank_samples(path, topic, 'crank', scan)
    assert topic == '/joint_states' and len(samples['data']) == 400 - 49
    assert samples['skipped_reasons'] == {"no position for joint 'crank'": 49}
    # Beyond the probe the topic is not taken (bounded), with the usual one-line refusal.
    late = write_crank_recording(
        tmp_path / 'late.mcap', io_recording.JOINT_PROBE_MESSAGES + 20,
        payload=lambda k: crank_state(k, ('lever',) if k < io_recording.JOINT_PROBE_MESSAGES
                                      else ('crank',)))
    scan = io_recording.scan_recording(late, joint_name='crank')
    assert len(scan[1]['/joint_states']) == io_recording.JOINT_PROBE_MESSAGES
    with pytest.raises(ValueError, match='no sensor_msgs/msg/JointState topic with joint'):
        io_recording.choose_input_topic(late, 'crank', scan=scan)


def bomb_file(tmp_path, name, declared):
    """Write a real 50-message recording with a chunk of ``declared`` zeros after its header."""
    path = write_crank_recording(tmp_path / 'base.mcap', 50)
    data = path.read_bytes()
    (header_length,) = struct.unpack_from('<Q', data, 9)
    cut = 8 + 9 + header_length
    bomb = chunk_record(zstd_zeros(declared), declared)
    out = tmp_path / name
    out.write_bytes(data[:cut] + bomb + data[cut:])
    return out, cut


def peak_rss_of(args):
    """Exit code, stdout, stderr and peak resident size [MiB] of a child process."""
    wrapper = ('import resource, subprocess, sys\n'
               'run = subprocess.run(sys.argv[1:], capture_output=True, text=True)\n'
               'sys.stdout.write(run.stdout); sys.stderr.write(run.stderr)\n'
               'print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss)\n'
               'sys.exit(run.returncode)\n')
    run = subprocess.run([sys.executable, '-c', wrapper, *args], capture_output=True,
                         text=True, timeout=300)
    *lines, peak_kib = run.stdout.strip().splitlines()
    return run.returncode, '\n'.join(lines), run.stderr, int(peak_kib) / 1024


@pytest.mark.parametrize('declared, expected_kb', [(3 * 2**29, 49), (2**28, 8)])
def test_decompression_bombs_are_refused_with_a_bound(tmp_path, declared, expected_kb):
    path, offset = bomb_file(tmp_path, 'bomb.mcap', declared)
    bomb_size = len(zstd_zeros(declared))
    assert abs(bomb_size / 1000 - expected_kb) < 0.3 * expected_kb      # the reported bomb files
    flexlink = [sys.executable, '-m', 'flexlink_ros.cli.main']
    code, out, err, peak = peak_rss_of(flexlink + ['mcap-info', str(path), '--json'])
    assert code == 0 and 'Traceback' not in err, err
    info = json.loads(out)
    assert info['damaged'][0]['offset'] == offset
    assert f'declares {declared} bytes uncompressed' in info['damaged'][0]['reason']
    assert info['message_count'] == 50 and info['status'].startswith('damaged: 1 chunks')
    assert peak < 200, f'mcap-info peaked at {peak:.0f} MiB'

    recovered = tmp_path / 'recovered.mcap'
    code, out, err, peak = peak_rss_of(
        flexlink + ['mcap-recover', str(path), '--out', str(recovered)])
    assert code == 0 and 'declares' in out and peak < 200, (err, peak)
    assert len(read_messages(recovered)) == 50

    reader = ('import sys; from flexlink_ros.io import recording as io_recording; damaged = []\n'
              'counts, kept = io_recording.scan_recording(sys.argv[1], joint_name="crank", '
              'damaged=damaged)\n'
              'print(len(kept["/joint_states"]), damaged[0][1], damaged[0][2])\n')
    code, out, err, peak = peak_rss_of([sys.executable, '-c', reader, str(path)])
    assert code == 0 and out.startswith(f'50 {offset} chunk: declares'), err
    assert peak < 200, f"replay's reader peaked at {peak:.0f} MiB"
    run = subprocess.run(flexlink + ['replay', str(path), '--out', str(tmp_path / 'r.mcap'),
                                     '--no-geometric-stiffness', '--markers-every-n', '0',
                                     '--mechanism', 'cho1992'],
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 0 and 'Traceback' not in run.stderr, run.stderr
    assert run.stdout.startswith(f'{path}: 50 samples on /joint_states')
    assert f'at offset {offset}: chunk: declares {declared} bytes uncompressed' in run.stdout


def test_overlapping_bomb_candidates_share_one_decompression_budget(tmp_path):
    """
    Stop the search for the next chunk at the file's decompression budget.

    Chunk records nested in each other's data, each claiming the rest of the file and 64 MiB
    of zeros, behind a broken record: the search stops at the budget instead of decompressing
    64 MiB per candidate.
    """
    frame = zstd_zeros(mcap_records.MAX_CHUNK_BYTES)
    tail = b''
    for _ in range(100):
        tail = chunk_record(frame + tail, mcap_records.MAX_CHUNK_BYTES, crc=1)
    broken = struct.pack('<BQ', mcap_records.CHUNK, 2**40)
    buffer = mcap_records.MCAP_MAGIC + broken + tail
    budget = mcap_records.decompression_budget(len(buffer))
    # Candidates whose ratio bound lets them decompress 64 MiB: many more than the budget.
    eligible = sum(mcap_records.chunk_bound(len(buffer) - offset) == mcap_records.MAX_CHUNK_BYTES
                   for offset in range(len(buffer)) if buffer[offset] == mcap_records.CHUNK)
    assert eligible * mcap_records.MAX_CHUNK_BYTES > 5 * budget
    salvage = mcap_reader.Salvage()
    assert list(mcap_reader.iter_messages(buffer, salvage)) == []
    assert salvage.end_reason == 'truncated inside a chunk record at offset 8'
    assert 0 <= salvage.budget[0] < mcap_records.MAX_CHUNK_BYTES     # spent, not exceeded


@pytest.mark.parametrize('content', [b'', b'\x89MCAP0\r', b'not an mcap file' * 10,
                                     mcap_records.MCAP_MAGIC + b'\x00' * 100])
def test_unreadable_files_are_refused_in_one_line_without_output(tmp_path, content):
    path = tmp_path / 'in.mcap'
    path.write_bytes(content)
    out = tmp_path / 'out.mcap'
    run = subprocess.run([sys.executable, '-m', 'flexlink_ros.cli.main', 'mcap-recover', str(path),
                          '--out', str(out)], capture_output=True, text=True, timeout=60)
    assert run.returncode == 1 and len(run.stderr.strip().splitlines()) == 1, run.stderr
    expected = 'nothing readable' if content.startswith(mcap_records.MCAP_MAGIC) else 'bad magic'
    assert expected in run.stderr
    assert not out.exists()


def salvaged_messages(path):
    """(channel, log time, data) of every message by the salvaging reader."""
    buffer = mcap_reader.map_file(path)
    try:
        found = [mcap_records.message_fields(records, start, end)
                 for records, start, end in mcap_reader.iter_messages(buffer,
                                                                      mcap_reader.Salvage())]
    finally:
        buffer.close()
    return [(channel, log, data) for channel, _, log, _, data in found]


def mixed_recording(path, count):
    """Crank states with one, then two, joints (two lengths) and a second topic between."""
    with McapRecorder(path, chunk_size_bytes=4096, flush_thread=False) as recorder:
        recorder.add_topic('/joint_states', JointState)
        recorder.add_topic('/other', JointState)
        for k in range(count):
            names = ('crank',) if k < count // 2 else ('crank', 'lever')
            recorder.write('/joint_states', crank_state(k, names), T0_NS + k * STEP_NS)
            if k % 7 == 0:
                recorder.write('/other', crank_state(k), T0_NS + k * STEP_NS + 1)
    return path


@pytest.mark.parametrize('make', [lambda path: write_crank_recording(path, 3000),
                                  lambda path: mixed_recording(path, 3000)],
                         ids=['one length', 'lengths and topics mixed'])
def test_chunks_of_equal_messages_are_read_at_once_as_the_walk_reads_them(tmp_path, make):
    path = make(tmp_path / 'bag.mcap')
    by_mcap = [(topic, log, bytes(data)) for topic, log, data in read_messages(path)]
    topics = {1: '/joint_states', 2: '/other'}
    assert [(topics[c], log, data) for c, log, data in salvaged_messages(path)] == by_mcap


def message_records(lengths):
    """Message records of the given body lengths, back to back."""
    return b''.join(struct.pack('<BQ', mcap_records.MESSAGE, length) + bytes(length)
                    for length in lengths)


def test_a_run_of_equal_messages_is_listed_and_anything_else_is_left_to_the_walk():
    head = mcap_records.MESSAGE_HEAD_SIZE
    records = b'xx' + message_records([head + 10] * 4)
    size = 9 + head + 10        # opcode, length, body
    assert mcap_reader.equal_messages(records, 2, len(records)) == [
        (2 + k * size + 9, 2 + (k + 1) * size) for k in range(4)]
    assert mcap_reader.equal_messages(records, len(records), len(records)) == []
    for other in (message_records([head + 10, head + 11, head + 10]),     # a longer one
                  message_records([head - 1] * 3),                        # too short to be one
                  message_records([head + 10] * 2)[:-1],                  # cut short
                  message_records([head + 10]) + struct.pack('<BQ', mcap_records.CHANNEL,
                                                             head + 10) + bytes(head + 10)):
        assert mcap_reader.equal_messages(other, 0, len(other)) is None
