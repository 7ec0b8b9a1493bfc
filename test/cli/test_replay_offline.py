"""`flexlink replay` in chunks: the bag of one whole pass, in memory that does not grow."""

import importlib.util
import json
import math
import pathlib
import subprocess
import sys
import threading
import time

from flexlink_ros.cli.replay_offline import ReadAhead
from flexlink_ros.io.recorder import McapRecorder
from flexlink_ros.ros import messages as ros_messages
from mcap.reader import make_reader
import numpy as np
import pytest
from rclpy.serialization import serialize_message
from sensor_msgs.msg import JointState

REPO = pathlib.Path(__file__).resolve().parents[2]
BENCH = REPO / 'benchmarks' / 'replay_bench.py'
SPEED = 391.0 * 2.0 * math.pi / 60.0
# Summary keys that differ between two runs of the same replay (times, paths).
RUN_KEYS = ('read_s', 'write_s', 'estimate_s', 'samples_per_s', 'times_real_time', 'output',
            'output_files')


def crank_state(stamp_ns, angle, speed=SPEED, joint='crank'):
    message = JointState(name=[joint], position=[angle],
                         velocity=[] if speed is None else [speed])
    message.header.stamp = ros_messages.ns_to_stamp(int(stamp_ns))
    message.header.frame_id = 'crank_link'
    return bytes(serialize_message(message))


def awkward_recording(path, count=5000):
    """Repeats, outliers, a gap, a step back, speedless and unusable messages near row 1000s."""
    rng = np.random.default_rng(11)
    stamps = 1_700_000_000_000_000_000 + np.cumsum(
        np.round((1 + 0.3 * rng.uniform(-1, 1, count)) * 1e6)).astype(np.int64)
    stamps[3000:] += 800_000_000                  # a gap: a new segment
    stamps[4000:] -= 2_000_000_000                # back in time: a new segment
    angles = np.mod(SPEED * (stamps - stamps[0]) * 1e-9 + np.pi, 2 * np.pi) - np.pi
    speeds = [SPEED] * count
    for row in (999, 1000, 2048):                 # exact repeats
        stamps[row], angles[row] = stamps[row - 1], angles[row - 1]
    for row in (1001, 2047, 2049, 3001):          # implausible speeds: outliers
        speeds[row] = 1e6
    for row in range(2500, 2520):                 # no measured speed
        speeds[row] = None
    extra = {1998: crank_state(stamps[1998] + 1, math.nan),     # skipped: NaN position
             1999: crank_state(stamps[1999] + 1, 0.0, joint='wheel'),   # skipped: no crank
             2999: crank_state(stamps[2999] + 1, 0.1, math.nan)}        # skipped: NaN speed
    with McapRecorder(path) as recorder:
        recorder.add_topic('/joint_states', JointState)
        for row in range(count):
            log_ns = int(stamps[row]) + 200_000
            recorder.write('/joint_states', crank_state(stamps[row], angles[row], speeds[row]),
                           log_ns, log_ns - 50_000)
            if row in extra:
                recorder.write('/joint_states', extra[row], log_ns + 1)
    return path


def replay_json(bag, out, *args):
    """Run ``flexlink replay BAG --out OUT --json ARGS`` to success; return its summary."""
    result = subprocess.run([sys.executable, '-m', 'flexlink_ros.cli', 'replay', str(bag),
                             '--out', str(out), '--json', *args],
                            capture_output=True, text=True, timeout=600, cwd=REPO)
    assert result.returncode == 0, result.stderr
    return json.loads(result.stdout)


def replay(bag, out, *extra):
    summary = replay_json(bag, out, '--markers-every-n', '7', '--mechanism', 'cho1992', *extra)
    return {key: value for key, value in summary.items() if key not in RUN_KEYS}


def messages(path):
    """(topic, log, publish, sequence, bytes) of every message, by mcap's own reader."""
    with open(path, 'rb') as stream:
        return [(channel.topic, m.log_time, m.publish_time, m.sequence, bytes(m.data))
                for _, channel, m in make_reader(stream).iter_messages(log_time_order=False)]


def test_a_replay_in_chunks_writes_the_bag_of_one_whole_pass(tmp_path):
    """Chunks of 1000 and 333 messages: the messages and summary of one chunk (the old pass)."""
    bag = awkward_recording(tmp_path / 'awkward.mcap')
    whole = replay(bag, tmp_path / 'whole.mcap', '--chunk-samples', '4194304')
    assert whole['skipped'] == 3 and whole['samples'] == 5000
    assert whole['segments'] == 3 and whole['outliers'] == 4
    expected = messages(tmp_path / 'whole.mcap')
    for chunk in (1000, 333):
        out = tmp_path / f'chunks_{chunk}.mcap'
        assert replay(bag, out, '--chunk-samples', str(chunk)) == whole
        assert messages(out) == expected
    markers = sum(1 for topic, *_ in expected if topic.endswith('/markers'))
    assert len(expected) == 5000 + 4 * (5000 - 4) + markers and markers > 600


def replay_bench():
    """Load the benchmark script as a module (its measured runs)."""
    spec = importlib.util.spec_from_file_location('replay_bench', BENCH)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def peak_resident_mb(args):
    """Run ``flexlink ARGS`` from the repository to its end; its own peak resident size [MB]."""
    return replay_bench().run_measured(sys.executable, REPO, args)[2]


def test_the_peak_resident_size_is_the_child_s_own():
    """A parent holding 300 MB does not make a small child look as large (wait4's maxrss did)."""
    held = np.ones(300 * 1024 * 1024 // 8)
    small = peak_resident_mb(['--help'])
    assert held.sum() > 0 and 10.0 < small < 200.0, small


# The nonlinear model steps about 10 times slower than the linear estimate runs ahead of it:
# the queues between them fill to their bound over the first 30-40 s of a recording (measured:
# 210, 221, 230, 232 MB after 20, 40, 120, 240 s), so its pair starts beyond that.
@pytest.mark.parametrize('nonlinear, lengths_s', [('off', (20, 120)), ('on', (60, 180))])
def test_replay_memory_does_not_grow_with_the_recording(tmp_path, nonlinear, lengths_s):
    """Several times the messages, the same peak resident size (it held every sample before)."""
    peaks = []
    for seconds in lengths_s:
        bag = tmp_path / f'bag_{seconds}.mcap'
        subprocess.run([sys.executable, str(BENCH), 'make-bag', str(bag), '--seconds',
                        str(seconds)], check=True, capture_output=True, timeout=300)
        peaks.append(peak_resident_mb(['replay', str(bag), '--out',
                                       str(tmp_path / f'out_{seconds}.mcap'),
                                       '--chunk-samples', '2000', '--mechanism', 'cho1992',
                                       '--nonlinear', nonlinear]))
    # 100 000 or 120 000 samples more: about 90 MB more when every sample was held.
    assert peaks[1] - peaks[0] < 15.0, peaks


# ... and mcap's writer module, which asks the installed packages' metadata for its version
# (importlib.metadata: about 40 ms of a start).
HEAVY_IMPORTS = ("print(sorted(m for m in sys.modules if m.split('.')[0] in "
                 "('rclpy', 'matplotlib') or m in ('scipy.linalg', 'scipy.optimize', "
                 "'scipy.sparse', 'mcap.writer', 'importlib.metadata')))\n")


def test_a_replay_from_the_cache_imports_neither_ros_plotting_nor_scipy_solvers(tmp_path):
    """Their imports alone cost a replay a good part of its time (scipy.linalg 0.2-0.4 s)."""
    bag = tmp_path / 'short.mcap'
    subprocess.run([sys.executable, str(BENCH), 'make-bag', str(bag), '--seconds', '0.3'],
                   check=True, capture_output=True, timeout=300)
    code = ('import sys\nfrom flexlink_ros.cli import main\nmain.main(sys.argv[1:])\n'
            + HEAVY_IMPORTS)
    replay = [sys.executable, '-c', code, 'replay', str(bag), '--mechanism', 'cho1992',
              '--nonlinear', 'off',    # (the nonlinear step solves with scipy)
              '--cache-dir', str(tmp_path / 'cache'), '--out']
    first = subprocess.run(replay + [str(tmp_path / 'first.mcap')], capture_output=True,
                           text=True, timeout=600, cwd=REPO)     # builds the model: needs scipy
    assert first.returncode == 0, first.stderr
    result = subprocess.run(replay + [str(tmp_path / 'out.mcap')], capture_output=True,
                            text=True, timeout=300, cwd=REPO)
    assert result.returncode == 0, result.stderr
    assert 'wrote' in result.stdout and result.stdout.splitlines()[-1] == '[]'


def test_replay_help_imports_neither_ros_plotting_nor_scipy_solvers():
    """`flexlink replay --help` answers without loading ROS, plotting or scipy's solvers."""
    code = ('import sys\nfrom flexlink_ros.cli import main\n'
            'try:\n    main.main(sys.argv[1:])\nexcept SystemExit:\n    pass\n'
            + HEAVY_IMPORTS)
    result = subprocess.run([sys.executable, '-c', code, 'replay', '--help'],
                            capture_output=True, text=True, timeout=300, cwd=REPO)
    assert result.returncode == 0, result.stderr
    assert '--chunk-samples' in result.stdout and result.stdout.splitlines()[-1] == '[]'


def test_a_damaged_chunk_of_a_replayed_bag_is_listed_once(tmp_path):
    """The survey comes from the summary; the reading lists the chunk it skipped, once."""
    bag = tmp_path / 'bag.mcap'
    with McapRecorder(bag, chunk_size_bytes=8192) as recorder:
        recorder.add_topic('/joint_states', JointState)
        for row in range(3000):
            stamp_ns = 1_700_000_000_000_000_000 + row * 1_000_000
            recorder.write('/joint_states', crank_state(stamp_ns, math.remainder(
                SPEED * row * 1e-3, 2 * math.pi)), stamp_ns + 200_000)
    with open(bag, 'rb') as stream:
        offset = make_reader(stream).get_summary().chunk_indexes[-2].chunk_start_offset
    data = bytearray(bag.read_bytes())
    data[offset + 9 + 24] ^= 0xFF       # the chunk's uncompressed CRC
    bad = tmp_path / 'damaged.mcap'
    bad.write_bytes(bytes(data))
    done = subprocess.run([sys.executable, '-m', 'flexlink_ros.cli.main', 'replay', str(bad),
                           '--out', str(tmp_path / 'out.mcap'), '--json', '--nonlinear', 'off',
                           '--mechanism', 'cho1992'], capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0, done.stderr
    result = json.loads(done.stdout)
    assert [d['offset'] for d in result['damaged']] == [offset]
    assert 0 < result['samples'] < 3000


def test_a_replay_reads_only_its_first_chunk_before_the_estimate_starts(tmp_path):
    """The rest is read beside the writing: the first chunk is the only read alone."""
    from flexlink_ros.cli.main import build_parser
    from flexlink_ros.cli.replay_offline import open_input
    bag = tmp_path / 'bag.mcap'
    subprocess.run([sys.executable, str(BENCH), 'make-bag', str(bag), '--seconds', '20'],
                   check=True, capture_output=True, timeout=300)
    argv = ['replay', str(bag), '--out', str(tmp_path / 'out.mcap'), '--joint', 'crank']
    args = build_parser(argv).parse_args(argv)
    topic, rows, messages = open_input(args, [])
    assert topic == '/joint_states' and messages > 19000
    assert 0 < rows.samples <= messages // 2
    # No thread reads ahead yet (a fork for --processes 2 comes after this): the estimate's
    # first chunk starts it, and it reads the rest.
    assert 'replay-read' not in [thread.name for thread in threading.enumerate()]
    chunks = rows.estimate_input()
    first = next(chunks)
    assert 'replay-read' in [thread.name for thread in threading.enumerate()]
    assert len(first[0]) + sum(len(chunk[0]) for chunk in chunks) == rows.samples == messages
    rows.close()
    assert 'replay-read' not in [thread.name for thread in threading.enumerate()]


def test_reading_ahead_gives_the_items_in_order_then_the_error_where_it_happened():
    def items():
        yield from range(5)
        raise ValueError('damaged past item 4')

    ahead = ReadAhead(items(), depth=2)
    assert [next(ahead) for _ in range(5)] == list(range(5))
    with pytest.raises(ValueError, match='damaged past item 4'):
        next(ahead)
    assert list(ahead) == []          # ended: no wait on a reader that is gone
    ahead.close()
    assert list(ReadAhead(iter(range(3)))) == [0, 1, 2]


def counted_items(count, produced):
    """Yield 0 ... count - 1, noting each in ``produced`` as it is made."""
    for n in range(count):
        produced.append(n)
        yield n


def test_closing_stops_a_reader_waiting_on_a_full_queue():
    produced = []
    ahead = ReadAhead(counted_items(1000, produced), depth=2)
    assert next(ahead) == 0
    ahead.close()
    assert not ahead.thread.is_alive() and len(produced) <= 4


def test_reading_ahead_waits_for_its_signal_and_stops_while_it_waits():
    produced = []
    begin = threading.Event()
    ahead = ReadAhead(counted_items(5, produced), depth=2, begin=begin)
    time.sleep(0.3)
    assert produced == []             # the estimate's start has the GIL to itself
    begin.set()
    assert list(ahead) == list(range(5))
    waiting = ReadAhead(counted_items(5, []), begin=threading.Event())
    waiting.close()
    assert not waiting.thread.is_alive()
