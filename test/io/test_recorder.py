"""MCAP recorder: rosbag2 layout read back by two readers, crash and full-disk paths."""

import json
import os
import pathlib
import signal
import struct
import subprocess
import sys
import time

from flexlink_ros.cli import main as cli
from flexlink_ros.cli.mcap import mcap_info, recover_mcap, scan_mcap
from flexlink_ros.errors import McapFileError, RecorderError
from flexlink_ros.io.msg_schema import message_definition, serialize_exact, share_directory, \
    type_hash
from flexlink_ros.io.recorder import McapRecorder, RecorderState
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
import numpy as np
import pytest
from recorder_helpers import check_values, record_samples, sample_messages, STEP_NS, T0_NS
from rosbags.highlevel import AnyReader
from sensor_msgs.msg import JointState
import yaml


def read_with_mcap_ros2(path):
    with open(path, 'rb') as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        header, summary = reader.get_header(), reader.get_summary()
        decoded = [(channel.topic, message.log_time, message.publish_time, msg)
                   for _, channel, message, msg
                   in reader.iter_decoded_messages(log_time_order=False)]
    return header, summary, decoded


def test_round_trip_both_readers(tmp_path):
    bag = tmp_path / 'run'
    count = 60
    with McapRecorder(bag) as recorder:
        record_samples(recorder, count)
        # Bytes from a raw subscription are recorded as they are.
        recorder.add_topic('/raw', 'sensor_msgs/msg/JointState')
        recorder.write('/raw', serialize_exact(JointState(name=['x'], position=[1.5])), T0_NS)
    assert recorder.state is RecorderState.CLOSED
    recorder.close()  # idempotent
    files = sorted(bag.glob('*.mcap'))
    assert [f.name for f in files] == ['run_0.mcap']

    header, summary, decoded = read_with_mcap_ros2(files[0])
    assert header.profile == 'ros2'
    assert summary.statistics.message_count == 6 * count + 1
    schemas = {s.name: s for s in summary.schemas.values()}
    assert schemas['sensor_msgs/msg/JointState'].encoding == 'ros2msg'
    for schema in schemas.values():
        assert schema.data.decode() == message_definition(schema.name)
    joint_hash = json.loads(
        (share_directory('sensor_msgs') / 'msg' / 'JointState.json').read_text())
    for channel in summary.channels.values():
        assert channel.message_encoding == 'cdr'
        qos = yaml.safe_load(channel.metadata['offered_qos_profiles'])
        assert qos[0]['reliability'] == 'reliable' and qos[0]['history'] == 'keep_last'
        if channel.topic == '/joint_states':
            assert channel.metadata['topic_type_hash'] == \
                joint_hash['type_hashes'][0]['hash_string'] == \
                type_hash('sensor_msgs/msg/JointState')
        assert channel.metadata['topic_type_hash'].startswith('RIHS01_')
    seen = {}
    for topic, log_time, publish_time, msg in decoded:
        if topic == '/raw':
            assert list(msg.position) == [1.5]
            continue
        k = seen.get(topic, 0)
        seen[topic] = k + 1
        assert publish_time == T0_NS + k * STEP_NS and log_time == publish_time + 20_000
        check_values(topic, k, msg)
    assert seen == {topic: count for topic in sample_messages(0)}

    with AnyReader([bag]) as reader:
        counts = {c.topic: c.msgcount for c in reader.connections}
        assert counts == {**{topic: count for topic in sample_messages(0)}, '/raw': 1}
        seen = {}
        for connection, timestamp, raw in reader.messages():
            msg = reader.deserialize(raw, connection.msgtype)
            # Independent serializer: rosbags re-encodes the decoded message to the same bytes.
            assert reader.typestore.serialize_cdr(msg, connection.msgtype) == raw
            if connection.topic == '/raw':
                continue
            k = seen.get(connection.topic, 0)
            seen[connection.topic] = k + 1
            assert timestamp == T0_NS + k * STEP_NS + 20_000
            check_values(connection.topic, k, msg)
        assert sum(seen.values()) == 6 * count


def test_split_by_size_and_duration(tmp_path):
    by_size = tmp_path / 'sized'
    with McapRecorder(by_size, split_size_bytes=20_000, chunk_size_bytes=4096) as recorder:
        record_samples(recorder, 300)
    files = sorted(by_size.glob('*.mcap'), key=lambda p: int(p.stem.rsplit('_', 1)[1]))
    assert len(files) >= 3
    assert [f.name for f in files] == [f'sized_{i}.mcap' for i in range(len(files))]
    total = 0
    for path in files:
        info = mcap_info(path)
        assert info['complete'] and info['message_count'] > 0
        total += info['message_count']
        # The data section ends at the first chunk boundary past the limit: at most one chunk
        # (schemas included, ~12 kB of .msg text, uncompressed worst case) beyond it.
        footer = path.read_bytes()[-37:]
        (summary_start,) = struct.unpack('<Q', footer[9:17])
        assert summary_start < 20_000 + 4096 + 16_384
    assert total == 6 * 300
    metadata = yaml.safe_load((by_size / 'metadata.yaml').read_text())
    info = metadata['rosbag2_bagfile_information']
    assert info['relative_file_paths'] == [f.name for f in files]
    assert info['message_count'] == 6 * 300
    with AnyReader([by_size]) as reader:
        times = [t for _, t, _ in reader.messages()]
        assert len(times) == 6 * 300 and times == sorted(times)

    by_time = tmp_path / 'timed'
    with McapRecorder(by_time, split_duration_s=0.1) as recorder:
        record_samples(recorder, 250)  # 0.25 s of log time
    infos = [mcap_info(p) for p in sorted(by_time.glob('*.mcap'))]
    assert len(infos) == 3
    assert all(i['duration_s'] < 0.1 for i in infos)
    assert sum(i['message_count'] for i in infos) == 6 * 250


def test_unwritable_and_full_device(tmp_path):
    not_a_dir = tmp_path / 'plain_file'
    not_a_dir.write_text('x')
    recorder = McapRecorder(not_a_dir / 'bag')
    with pytest.raises(RecorderError):
        recorder.open()
    assert recorder.state is RecorderState.FAILED
    recorder.close()  # already reported: no second exception

    full = tmp_path / 'full.mcap'
    full.symlink_to('/dev/full')  # a link is never followed (a full disk: the tmpfs tests)
    recorder = McapRecorder(full)
    with pytest.raises(RecorderError, match='symbolic link to /dev/full'):
        recorder.open()
    assert recorder.state is RecorderState.FAILED
    assert recorder.status()['state'] == 'failed' and 'exists' in recorder.status()['error']
    assert recorder.write('/joint_states', JointState(), T0_NS) is False
    assert recorder.status()['dropped_count'] == 1
    recorder.close()


def test_disk_fills_during_recording(tiny_tmpfs, tmp_path):
    recorder = McapRecorder(tiny_tmpfs / 'bag', chunk_size_bytes=8192, flush_thread=False)
    recorder.open()
    raised, written, k = 0, 0, 0
    while k < 20_000 and recorder.state is RecorderState.RECORDING:
        try:
            for topic, msg in sample_messages(k).items():
                written += recorder.write(topic, msg, T0_NS + k * STEP_NS)
        except RecorderError as exc:
            raised += 1
            assert 'No space left' in str(exc)
        k += 1
    assert recorder.state is RecorderState.FAILED and raised == 1
    for j in range(k, k + 10):  # keeps dropping quietly
        assert recorder.write('/joint_states', sample_messages(j)['/joint_states'],
                              T0_NS + j * STEP_NS) is False
    status = recorder.close()
    assert status['state'] == 'failed' and status['dropped_count'] >= 10
    # What reached the disk is salvageable.
    result = recover_mcap(status['files'][0], tmp_path / 'salvaged.mcap')
    assert 0 < result['message_count'] <= written
    assert mcap_info(tmp_path / 'salvaged.mcap')['complete']


def test_write_after_close_and_bad_arguments(tmp_path):
    recorder = McapRecorder(tmp_path / 'one.mcap')
    with pytest.raises(RecorderError):
        recorder.write('/x', JointState(), T0_NS)  # not opened
    recorder.open()
    with pytest.raises(ValueError, match='add_topic'):
        recorder.write('/bytes', b'\x00\x01\x00\x00', T0_NS)
    recorder.close()
    with pytest.raises(RecorderError):
        recorder.write('/x', JointState(), T0_NS)
    with pytest.raises(ValueError, match='split_size_bytes'):
        McapRecorder(tmp_path / 'two.mcap', split_size_bytes=1000)
    with pytest.raises(RecorderError, match='exists'):
        (tmp_path / 'busy').mkdir()
        (tmp_path / 'busy' / 'other').write_text('x')
        McapRecorder(tmp_path / 'busy').open()


def test_timer_flush_makes_recent_messages_readable(tmp_path):
    path = tmp_path / 'live.mcap'
    recorder = McapRecorder(path, flush_period_s=0.2).open()
    for k in range(5):  # 5 ms of log time: no flush is due from the data alone
        recorder.write('/joint_states', sample_messages(k)['/joint_states'], T0_NS + k * STEP_NS)
    deadline = time.monotonic() + 3.0
    while scan_mcap(path)['message_count'] < 5 and time.monotonic() < deadline:
        time.sleep(0.05)
    scan = scan_mcap(path)  # the file has no summary yet: read as a crash would leave it
    assert scan['message_count'] == 5 and scan['end_reason'].startswith('end of file')
    recorder.close()
    assert mcap_info(path)['complete']


def test_recover_truncated_file_and_cli(tmp_path, capsys):
    path = tmp_path / 'whole.mcap'
    with McapRecorder(path, chunk_size_bytes=4096) as recorder:
        record_samples(recorder, 400)
    data = path.read_bytes()
    _, summary, complete = read_with_mcap_ros2(path)
    for cut in (len(data) // 3, len(data) // 2, len(data) - 100):
        truncated = tmp_path / f'cut_{cut}.mcap'
        truncated.write_bytes(data[:cut])
        assert not mcap_info(truncated)['complete']
        out = tmp_path / f'fixed_{cut}.mcap'
        assert cli.main(['mcap-recover', str(truncated), '--out', str(out), '--json']) == 0
        result = json.loads(capsys.readouterr().out)
        recovered = read_with_mcap_ros2(out)[2]
        assert result['message_count'] == len(recovered) > 0
        # A prefix of the original stream, decoded identically.
        assert [(t, lt) for t, lt, _, _ in recovered] == \
            [(t, lt) for t, lt, _, _ in complete[:len(recovered)]]
        # Exactly the messages of the chunks that lie wholly before the cut survive.
        whole = [c for c in summary.chunk_indexes if c.chunk_start_offset + c.chunk_length <= cut]
        last_kept = max(c.message_end_time for c in whole)
        assert sum(1 for _, lt, _, _ in complete if lt < last_kept) < len(recovered) <= \
            sum(1 for _, lt, _, _ in complete if lt <= last_kept)
        assert recovered[-1][1] == last_kept
        assert mcap_info(out)['complete']
    assert cli.main(['mcap-info', str(path)]) == 0
    text = capsys.readouterr().out
    assert '/joint_states' in text and '400' in text
    assert cli.main(['mcap-recover', str(path), '--out', str(path)]) == 1


def _recorded(path):
    """Tell whether a file being recorded holds a message (False while its header is written)."""
    try:
        return scan_mcap(path)['message_count'] > 0
    except McapFileError:   # created, magic not written yet
        return False


def record_live_stream(tmp_path, stop_signal, record_s=2.5):
    """
    crank_driver (1 kHz) and `flexlink mcap-record` in subprocesses; signal the recorder.

    Returns the output path and the wall time [ns] at which the signal was sent.
    """
    repo = pathlib.Path(__file__).resolve().parents[2]
    out = tmp_path / 'live.mcap'
    driver = subprocess.Popen([sys.executable, '-m', 'flexlink_ros.ros.crank_driver', '--ros-args',
                               '-p', 'duration_s:=30.0'], cwd=repo)
    recorder = subprocess.Popen(
        [sys.executable, '-m', 'flexlink_ros.cli.main', 'mcap-record', str(out),
         '--topic', 'joint_states:sensor_msgs/msg/JointState', '--json'],
        cwd=repo, stdout=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 15.0
        while time.monotonic() < deadline:  # discovery, then the first flushed chunk
            if out.exists() and _recorded(out):
                break
            time.sleep(0.1)
        else:
            pytest.fail('nothing recorded within 15 s')
        time.sleep(record_s)
        sent_ns = time.time_ns()
        recorder.send_signal(stop_signal)
        recorder.wait(timeout=10)
    finally:
        for process in (recorder, driver):
            if process.poll() is None:
                process.terminate()
                try:
                    process.wait(timeout=5)
                except subprocess.TimeoutExpired:
                    process.kill()
                    process.wait()
    return out, sent_ns, recorder


def test_sigterm_closes_the_file_with_summary(tmp_path):
    out, sent_ns, recorder = record_live_stream(tmp_path, signal.SIGTERM)
    assert recorder.returncode == 0
    status = json.loads(recorder.stdout.read())
    info = mcap_info(out)
    assert info['complete'] and status['state'] == 'closed'
    assert info['message_count'] == status['message_count'] > 1000
    _, summary, decoded = read_with_mcap_ros2(out)
    assert summary.statistics.message_count == len(decoded)
    log_times = np.array([log for _, log, _, _ in decoded])
    publish_times = np.array([pub for _, _, pub, _ in decoded])
    assert np.all(log_times >= publish_times)  # receive after send
    assert (log_times - publish_times).max() < 0.5e9
    assert abs(sent_ns - log_times[-1]) < 0.2e9  # recorded up to the signal
    stamps = np.array([m.header.stamp.sec * 10**9 + m.header.stamp.nanosec
                       for _, _, _, m in decoded])
    assert np.all(np.diff(stamps) > 0)


def test_sigkill_leaves_a_salvageable_file(tmp_path):
    out, sent_ns, recorder = record_live_stream(tmp_path, signal.SIGKILL)
    assert recorder.returncode == -signal.SIGKILL
    assert not mcap_info(out)['complete']
    result = recover_mcap(out, tmp_path / 'salvaged.mcap')
    lost_s = (sent_ns - result['end_ns']) / 1e9
    print(f"SIGKILL: {result['message_count']} messages salvaged, last {lost_s:.3f} s lost")
    assert result['message_count'] > 1000
    assert lost_s < 1.0  # one flush period (0.5 s) plus a chunk, at most
    _, summary, decoded = read_with_mcap_ros2(tmp_path / 'salvaged.mcap')
    assert len(decoded) == result['message_count'] == summary.statistics.message_count


@pytest.mark.parametrize('case', ['under_a_file', 'non_empty_bag_directory'])
def test_failed_open_leaves_a_failed_recorder_that_drops_writes(tmp_path, case):
    if case == 'under_a_file':
        (tmp_path / 'file').write_text('x')
        path = tmp_path / 'file' / 'bag'
    else:
        path = tmp_path / 'busy'
        path.mkdir()
        (path / 'other').write_text('x')
    recorder = McapRecorder(path)
    recorder.add_topic('/bytes', 'sensor_msgs/msg/JointState')
    with pytest.raises(RecorderError, match='cannot record'):
        recorder.open()
    assert recorder.status()['state'] == 'failed'
    # The failure was reported by open(): writes are dropped and counted, never raised.
    assert recorder.write('/bytes', b'\x00\x01\x00\x00', T0_NS) is False
    assert recorder.write('/x', JointState(), T0_NS) is False
    assert recorder.status()['dropped_count'] == 2
    recorder.close()


@pytest.mark.parametrize('chunk_size, bag', [(1024, False), (128 * 1024, True), (10**7, False)])
def test_write_batch_writes_the_same_file_as_write(tmp_path, chunk_size, bag):
    """Batches (mixed with single writes) give byte-identical files, metadata and status."""
    rng = np.random.default_rng(chunk_size)
    count = 3000
    topics = np.where(rng.uniform(size=count) < 0.3, '/b', '/a').tolist()
    steps = rng.choice([1_000_000, 2_000_000, 90_000_000, -500_000], size=count)
    log = 10**18 + np.cumsum(steps)
    publish = log - 7
    data = [bytes([n % 256]) * int(rng.integers(1, 400)) for n in range(count)]

    def record(name, batched):
        # Same file names (the rosbag2 metadata records name the files), different folders.
        path = tmp_path / name / ('rec' if bag else 'rec.mcap')
        recorder = McapRecorder(path, chunk_size_bytes=chunk_size, flush_thread=False)
        recorder.open()
        recorder.add_topic('/a', 'sensor_msgs/msg/JointState')
        recorder.add_topic('/b', 'geometry_msgs/msg/Vector3Stamped')
        if batched:
            edges = [0, 1, 5, 900, 901, 2000, 2700, count]
            for n, (first, stop) in enumerate(zip(edges, edges[1:])):
                if n % 3 == 1:      # single writes in between
                    for k in range(first, stop):
                        recorder.write(topics[k], data[k], int(log[k]), int(publish[k]))
                else:
                    assert recorder.write_batch(topics[first:stop], data[first:stop],
                                                log[first:stop], publish[first:stop]) \
                        == stop - first
        else:
            for k in range(count):
                recorder.write(topics[k], data[k], int(log[k]), int(publish[k]))
        status = recorder.close()
        files = [pathlib.Path(f).read_bytes() for f in status['files']]
        metadata = (path / 'metadata.yaml').read_text() if bag else None
        status.pop('path'), status.pop('files')
        return files, metadata, status

    assert record('single', False) == record('batch', True)


@pytest.mark.parametrize('content', [None, b'not an mcap file at all' * 100])
def test_mcap_info_on_a_missing_or_foreign_file_is_a_one_line_error(tmp_path, content):
    import subprocess
    import sys
    path = tmp_path / 'input.mcap'
    if content is not None:
        path.write_bytes(content)
    result = subprocess.run(
        [sys.executable, '-m', 'flexlink_ros.cli.main', 'mcap-info', str(path)],
        capture_output=True, text=True, timeout=60)
    assert result.returncode == 1
    assert result.stderr.startswith('flexlink mcap-info: error:')
    assert len(result.stderr.strip().splitlines()) == 1
    assert ('bad magic' if content else 'No such file') in result.stderr


def test_a_refused_path_leaves_nothing_behind_so_the_next_start_is_not_refused(tmp_path):
    """A 250-character bag name: its file name is too long; no directory is left behind."""
    bag = tmp_path / 'new' / 'parents' / ('x' * 250)
    for _ in range(2):      # the second start is refused for the same reason, not for a leftover
        recorder = McapRecorder(bag)
        with pytest.raises(RecorderError, match='File name too long'):
            recorder.open()
        assert recorder.state is RecorderState.FAILED
        assert not (tmp_path / 'new').exists()


@pytest.mark.parametrize('option, value', [('--split-size-mb', '0.001'),
                                           ('--split-duration-s', '0.001')])
def test_mcap_record_refuses_splits_below_the_floor_before_recording(tmp_path, option, value):
    out = tmp_path / 'tiny'
    done = subprocess.run([sys.executable, '-m', 'flexlink_ros.cli.main', 'mcap-record',
                           str(out), '--topic', 'joint_states:sensor_msgs/msg/JointState',
                           option, value], capture_output=True, text=True, timeout=120)
    assert done.returncode == 1 and f'{option} must be 0 (no split) or at least' in done.stderr
    assert not out.exists()


def test_status_counts_files_and_bytes_and_lists_paths_only_when_asked(tmp_path):
    bag = tmp_path / 'bag'
    with McapRecorder(bag, split_size_bytes=1, flush_thread=False) as recorder:
        recorder.add_topic('/a', 'sensor_msgs/msg/JointState')
        for k in range(5):      # one message per file
            recorder.write('/a', b'\x00\x01\x00\x00' + bytes(40), T0_NS + k)
        light = recorder.status(list_files=False)
        assert 'files' not in light and light['file_count'] == 5
        assert light['message_count'] == 5 and light['dropped_count'] == 0
    status = recorder.status()
    assert status['files'] == [str(bag / f'bag_{n}.mcap') for n in range(5)]
    assert status['bytes_written'] == sum(os.stat(p).st_size for p in status['files'])
    assert status['state'] == 'closed' and status['queued_bytes'] == 0
