"""`flexlink reindex`: metadata.yaml of a killed recording rebuilt; rosbags then opens the bag."""

import json
import pathlib
import signal
import subprocess
import sys
import time

from flexlink_ros.cli import main as cli
from flexlink_ros.cli.mcap import scan_mcap
from flexlink_ros.errors import McapFileError
from flexlink_ros.io.provenance import provenance_entries, read_provenance
from flexlink_ros.io.recorder import McapRecorder
from flexlink_ros.ros.parameters import default_model_options
from geometry_msgs.msg import Vector3Stamped
from mcap.reader import make_reader
import pytest
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rosbags.rosbag2 import Reader
from rosbags.typesys import get_typestore, Stores
from sensor_msgs.msg import JointState
import yaml

REPO = pathlib.Path(__file__).resolve().parents[2]
T0_NS = 1_700_000_000_000_000_000
TYPESTORE = get_typestore(Stores.ROS2_JAZZY)


def rosbags_messages(bag):
    """Every message of a bag directory through rosbags: (topic, log time, decoded)."""
    with Reader(bag) as reader:
        return [(connection.topic, log_ns, TYPESTORE.deserialize_cdr(data, connection.msgtype))
                for connection, log_ns, data in reader.messages()]


def _recorded(path):
    """Count the readable messages of a file being recorded (0 while its header is written)."""
    try:
        return scan_mcap(path)['message_count']
    except McapFileError:   # created, magic not written yet
        return 0


def _wait_for_recording(bag, files, messages, timeout_s):
    """Wait until ``bag`` holds ``files`` split files and ``messages`` readable messages."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:  # discovery, then flushed chunks in a split file
        paths = sorted(bag.glob('*.mcap'))
        if len(paths) >= files and _recorded(paths[-1]) and sum(
                _recorded(path) for path in paths) >= messages:
            return
        time.sleep(0.1)
    pytest.fail(f'not {files} files and {messages} messages recorded within {timeout_s} s: '
                f'{sorted(bag.glob("*.mcap"))}')


def record_then_kill(bag, files=2, messages=1200):
    """
    Record crank_driver's 1 kHz /joint_states into a split bag directory; SIGKILL it.

    The kill waits for ``files`` split files and ``messages`` readable messages, however
    loaded the machine (no fixed recording time).
    """
    driver = subprocess.Popen([sys.executable, '-m', 'flexlink_ros.ros.crank_driver', '--ros-args',
                               '-p', 'duration_s:=120.0'], cwd=REPO)
    recorder = subprocess.Popen(
        [sys.executable, '-m', 'flexlink_ros.cli.main', 'mcap-record', str(bag),
         '--topic', 'joint_states:sensor_msgs/msg/JointState', '--split-duration-s', '1.0'],
        cwd=REPO, stdout=subprocess.DEVNULL)
    try:
        _wait_for_recording(bag, files, messages, 90.0)
        recorder.send_signal(signal.SIGKILL)
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
    return recorder.returncode


def test_reindex_after_a_real_sigkill_lets_rosbags_open_the_bag(tmp_path, capsys):
    bag = tmp_path / 'killed'
    assert record_then_kill(bag) == -signal.SIGKILL
    files = sorted(bag.glob('*.mcap'))
    assert len(files) >= 2 and not (bag / 'metadata.yaml').exists()
    with pytest.raises(Exception):
        rosbags_messages(bag)          # what a ROS user met: rosbags refuses the folder
    readable = sum(scan_mcap(path)['message_count'] for path in files)
    last = files[-1].read_bytes()

    assert cli.main(['reindex', str(bag), '--json']) == 0
    result = json.loads(capsys.readouterr().out)
    messages = rosbags_messages(bag)
    cut = [pathlib.Path(f['path']).name for f in result['files'] if f['salvaged_from']]
    with capsys.disabled():
        print(f"\nreindex after SIGKILL: {len(result['files'])} files, {len(messages)} "
              f'messages read by rosbags, cut short and rewritten: {cut}')
    assert len(messages) == result['message_count'] == readable > 1000
    assert result['topics'] == {'/joint_states': readable}
    assert {topic for topic, _, _ in messages} == {'/joint_states'}
    stamps = [m.header.stamp.sec * 10**9 + m.header.stamp.nanosec for _, _, m in messages]
    assert stamps == sorted(stamps) and len(set(stamps)) == len(stamps)
    # The cut-short last file was rewritten complete; the original is kept, untouched.
    salvaged = [f for f in result['files'] if f['salvaged_from']]
    assert [f['path'] for f in salvaged] == [str(files[-1])]
    assert pathlib.Path(salvaged[0]['salvaged_from']).read_bytes() == last
    metadata = yaml.safe_load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    assert metadata['version'] == 9 and metadata['storage_identifier'] == 'mcap'
    assert metadata['relative_file_paths'] == [f.name for f in files]
    (topic,) = metadata['topics_with_message_count']
    assert topic['topic_metadata']['type'] == 'sensor_msgs/msg/JointState'
    assert topic['topic_metadata']['offered_qos_profiles'][0]['reliability'] == 'reliable'
    assert topic['topic_metadata']['type_description_hash'].startswith('RIHS01_')
    # A second run finds metadata.yaml and refuses, unless told to rebuild it.
    before = (bag / 'metadata.yaml').read_bytes()
    assert cli.main(['reindex', str(bag)]) == 1
    assert 'exists' in capsys.readouterr().err
    assert cli.main(['reindex', str(bag), '--force']) == 0
    assert (bag / 'metadata.yaml').read_bytes() == before


def record_bag(bag, count=3000, provenance=None):
    """Record two topics into a bag split by log time; return the closed recorder's status."""
    with McapRecorder(bag, split_duration_s=1.0, chunk_size_bytes=4096,
                      provenance=provenance) as recorder:
        offered = QoSProfile(depth=100, reliability=ReliabilityPolicy.BEST_EFFORT)
        recorder.add_topic('/joint_states', JointState, qos_profiles=[offered])
        for k in range(count):
            t = T0_NS + k * 1_000_000
            joint = JointState(name=['crank'], position=[0.001 * k])
            joint.header.stamp.sec, joint.header.stamp.nanosec = divmod(t, 10**9)
            recorder.write('/joint_states', joint, t + 5_000, publish_time_ns=t)
            if k % 10 == 0:
                recorder.write('/deflection', Vector3Stamped(), t + 6_000)
        return recorder.status()


def test_reindex_rebuilds_the_recorders_metadata_exactly_and_salvages_a_cut_file(tmp_path):
    bag = tmp_path / 'run'
    status = record_bag(bag)
    files = [pathlib.Path(f) for f in status['files']]
    assert len(files) == 3
    written = (bag / 'metadata.yaml').read_text()
    (bag / 'metadata.yaml').unlink()
    assert cli.main(['reindex', str(bag)]) == 0
    assert (bag / 'metadata.yaml').read_text() == written   # what close() wrote, byte for byte

    data = files[-1].read_bytes()
    earlier = status['message_count'] - scan_mcap(files[-1])['message_count']
    files[-1].write_bytes(data[:len(data) * 2 // 3])   # the last file cut short
    kept = scan_mcap(files[-1])['message_count']
    assert cli.main(['reindex', str(bag), '--force']) == 0
    messages = rosbags_messages(bag)
    assert 0 < kept < 1100 and len(messages) == earlier + kept < status['message_count']
    with open(files[-1], 'rb') as stream:       # the rewritten file has its summary again
        reader = make_reader(stream)
        assert reader.get_summary().statistics.message_count == kept
        records = [yaml.safe_load(m.metadata['serialized_metadata'])
                   for m in reader.iter_metadata() if m.name == 'rosbag2']
        sequences = [m.sequence for _, c, m in reader.iter_messages(log_time_order=False)
                     if c.topic == '/deflection']
    assert len(records) == 2 and records[0]['files'][-1]['message_count'] == 0
    assert sequences == list(range(sequences[0], sequences[0] + len(sequences)))
    assert sequences[0] > 1     # numbering carried on from the earlier files, and kept
    counts = {}
    for topic, _, _ in messages:
        counts[topic] = counts.get(topic, 0) + 1
    metadata = yaml.safe_load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    assert {t['topic_metadata']['name']: t['message_count']
            for t in metadata['topics_with_message_count']} == counts
    assert metadata['message_count'] == len(messages)
    # The closing record describes the rewritten file alone, as the recorder writes it.
    assert records[1]['relative_file_paths'] == [files[-1].name]
    assert records[1]['message_count'] == kept
    assert records[1]['topics_with_message_count'][0]['topic_metadata'] == metadata[
        'topics_with_message_count'][0]['topic_metadata']
    (qos,) = metadata['topics_with_message_count'][0]['topic_metadata']['offered_qos_profiles']
    assert (qos['reliability'], qos['depth']) == ('best_effort', 100)


def test_reindex_keeps_what_made_the_bag_in_custom_data(tmp_path):
    """A rebuilt metadata.yaml carries the recording's provenance, as close() wrote it."""
    bag = tmp_path / 'run'
    record_bag(bag, count=1500, provenance=provenance_entries('flexlink mcap-record'))
    written = (bag / 'metadata.yaml').read_text()
    assert 'flexlink_ros.producer: flexlink mcap-record' in written
    (bag / 'metadata.yaml').unlink()
    assert cli.main(['reindex', str(bag)]) == 0
    assert (bag / 'metadata.yaml').read_text() == written


def test_a_salvaged_first_file_still_says_what_made_the_bag(tmp_path):
    """The recorder killed in its first file: the rewritten file keeps the provenance record."""
    bag = tmp_path / 'run'
    status = record_bag(bag, count=800, provenance=provenance_entries(
        'flexlink_node', 'kang1990', default_model_options()))
    (first,) = [pathlib.Path(f) for f in status['files']]
    data = first.read_bytes()
    first.write_bytes(data[:len(data) * 2 // 3])     # cut short, as a SIGKILL does
    (bag / 'metadata.yaml').unlink()
    assert cli.main(['reindex', str(bag)]) == 0
    recorded = read_provenance(bag)
    assert recorded is not None and recorded.mechanism().name == 'kang1990'
    metadata = yaml.safe_load((bag / 'metadata.yaml').read_text())
    assert metadata['rosbag2_bagfile_information']['custom_data'][
        'flexlink_ros.producer'] == 'flexlink_node'


def test_reindex_refuses_what_is_not_a_crashed_bag(tmp_path, capsys):
    (tmp_path / 'file.mcap').write_bytes(b'x')
    (tmp_path / 'empty').mkdir()
    (tmp_path / 'other').mkdir()
    (tmp_path / 'other' / 'notes.txt').write_text('x')
    (tmp_path / 'stray').mkdir()      # a folder that merely holds some MCAP file
    with McapRecorder(tmp_path / 'stray' / 'rr.mcap') as recorder:
        recorder.write('/a', JointState(), T0_NS)
    for path, reason in ((tmp_path / 'file.mcap', 'not a directory'),
                         (tmp_path / 'stray', 'not a bag directory'),
                         (tmp_path / 'missing', 'not a directory'),
                         (tmp_path / 'empty', 'not a bag directory'),
                         (tmp_path / 'other', 'not a bag directory')):
        assert cli.main(['reindex', str(path)]) == 1
        assert reason in capsys.readouterr().err
        assert not (path / 'metadata.yaml').exists()
    bag = tmp_path / 'closed'
    record_bag(bag, count=200)
    before = (bag / 'metadata.yaml').read_bytes()
    assert cli.main(['reindex', str(bag)]) == 1
    assert '--force' in capsys.readouterr().err
    assert (bag / 'metadata.yaml').read_bytes() == before
    (bag / 'metadata.yaml').unlink()
    (bag / 'closed_0.mcap').write_bytes(b'not an MCAP file')
    assert cli.main(['reindex', str(bag)]) == 1      # one file is not MCAP at all: said so
    assert 'not an MCAP file' in capsys.readouterr().err
    assert not (bag / 'metadata.yaml').exists()


RECORDING_SCRIPT = """
import signal, sys, time
from flexlink_ros.io.recorder import McapRecorder
from sensor_msgs.msg import JointState
stop = []
signal.signal(signal.SIGTERM, lambda *_: stop.append(1))
recorder = McapRecorder(sys.argv[1]).open()
k = 0
while not stop:
    recorder.enqueue('/a', JointState(name=['crank'], position=[1e-3 * k]),
                     1_700_000_000_000_000_000 + k * 1_000_000)
    k += 1
    time.sleep(0.001)
status = recorder.close()
print(k, status['message_count'])
"""


def test_reindex_refuses_a_bag_being_recorded_and_force_does_not_override(tmp_path):
    """The recorder holds a lock on its bag for the recording's life: reindex exits 2, one line."""
    bag = tmp_path / 'live'
    recording = subprocess.Popen([sys.executable, '-c', RECORDING_SCRIPT, str(bag)], cwd=REPO,
                                 stdout=subprocess.PIPE, text=True)
    try:
        first = bag / 'live_0.mcap'
        deadline = time.monotonic() + 20.0
        while not (first.exists() and _recorded(first)):
            assert time.monotonic() < deadline, 'nothing recorded within 20 s'
            time.sleep(0.05)
        before = sorted(p.name for p in bag.iterdir())
        for extra in ([], ['--force']):
            done = subprocess.run([sys.executable, '-m', 'flexlink_ros.cli.main', 'reindex',
                                   str(bag), *extra], cwd=REPO, capture_output=True, text=True,
                                  timeout=60)
            assert done.returncode == 2, done.stderr
            assert len(done.stderr.splitlines()) == 1 and 'being recorded' in done.stderr
            assert sorted(p.name for p in bag.iterdir()) == before     # nothing rewritten
    finally:
        recording.send_signal(signal.SIGTERM)
        out, _ = recording.communicate(timeout=30)
    sent, recorded = map(int, out.split())
    assert recording.returncode == 0 and sent == recorded
    assert len(rosbags_messages(bag)) == recorded       # the bag is whole: one file, all of it


def _kill_at_a_split(tmp_path, name, last):
    """Make a closed two-file bag, drop its metadata.yaml and make its last file ``last``."""
    bag = tmp_path / name
    status = record_bag(bag, count=1500)
    (bag / 'metadata.yaml').unlink()
    files = [pathlib.Path(p) for p in status['files']]
    assert len(files) == 2
    header = files[1].read_bytes()[:8 + 200]
    files[1].write_bytes({'empty': b'', 'magic': header[:8], 'header': header}[last])
    return bag, files


@pytest.mark.parametrize('last', ['empty', 'magic', 'header'])
def test_a_last_file_cut_at_a_split_is_skipped_with_a_note(tmp_path, capsys, last):
    bag, files = _kill_at_a_split(tmp_path, f'cut_{last}', last)
    assert cli.main(['reindex', str(bag)]) == 0
    out = capsys.readouterr().out
    assert f'skipped {files[1]}' in out and 'no message' in out
    metadata = yaml.safe_load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    assert metadata['relative_file_paths'] == [files[0].name]
    assert len(rosbags_messages(bag)) == metadata['message_count'] == 1100


def test_stale_salvage_files_are_removed_and_the_rewrite_keeps_the_mode(tmp_path, capsys):
    bag = tmp_path / 'stale'
    record_bag(bag, count=1500)
    (bag / 'metadata.yaml').unlink()
    cut = bag / 'stale_1.mcap'
    data = cut.read_bytes()
    cut.write_bytes(data[:len(data) // 2])      # killed mid-recording, before its summary
    cut.chmod(0o600)
    gone = subprocess.run([sys.executable, '-c', 'import os; print(os.getpid())'],
                          capture_output=True, text=True, check=True)
    dead_pid = int(gone.stdout)
    stale = bag / f'.stale_1.mcap.{dead_pid}.salvage'          # a reindex killed mid-rewrite
    alive = bag / f'.stale_1.mcap.{1}.salvage'                  # pid 1 is alive: not ours
    other = bag / f'.stale_1.mcap.{dead_pid}.salvage.keep'      # not the pattern: not ours
    for path in (stale, alive, other):
        path.write_bytes(bytes(1000))
    assert cli.main(['reindex', str(bag)]) == 0
    assert 'removed' in capsys.readouterr().out
    assert not stale.exists() and alive.exists() and other.exists()
    assert cut.stat().st_mode & 0o777 == 0o600          # the rewritten file keeps the mode
    assert len(rosbags_messages(bag)) > 1100
