"""``flexlink replay --nonlinear`` (cli/replay_nonlinear.py): a real bag, a 2-element model."""

import ctypes
import json
import math
import os
import subprocess
import sys
import warnings

from flexlink_ros.cli.replay_nonlinear import NonlinearRows
from flexlink_ros.core.estimation.nonlinear_stream import estimate_nonlinear
from flexlink_ros.core.reduction.nonlinear_model import nonlinear_model_for
from flexlink_ros.io.provenance import read_provenance
from flexlink_ros.io.recorder import McapRecorder
from flexlink_ros.names import NODE_NAME, output_topics
from flexlink_ros.ros import messages as ros_messages
from geometry_msgs.msg import Vector3Stamped
from mcap.reader import make_reader
import numpy as np
import pytest
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import JointState
from small_nonlinear import small_nonlinear_tables

SMALL_MODEL = ['--mechanism', 'cho1992', '--elements-per-link', '2', '--rigid-crank',
               '--bearings', 'flexible', '--stiffness-damping', '1e-4']


def write_bag(path, rpm, seconds=1.5, rate_hz=1000.0, edit=None):
    """
    Write a bag of crank JointStates at ``rpm`` (stamps jittered by up to 20 %).

    ``edit(times, angles)`` may alter the sample times and angles before they are written.
    """
    rng = np.random.default_rng(5)
    steps = (1.0 + 0.2 * rng.uniform(-1, 1, int(seconds * rate_hz))) / rate_hz
    times = np.concatenate([[0.0], np.cumsum(steps)])
    speed = rpm * math.pi / 30.0
    angles = np.mod(speed * times, 2 * math.pi)
    if edit is not None:
        edit(times, angles)
    stamps = (1_700_000_000_000_000_000 + np.round(times * 1e9)).astype(np.int64)
    with McapRecorder(path) as recorder:
        recorder.add_topic('/joint_states', JointState)
        for stamp, angle in zip(stamps.tolist(), angles):
            message = JointState(name=['crank'], position=[float(angle)], velocity=[speed])
            message.header.stamp = ros_messages.ns_to_stamp(stamp)
            recorder.write('/joint_states', serialize_message(message), stamp + 100_000)


def replay(*flags):
    done = subprocess.run([sys.executable, '-m', 'flexlink_ros.cli.main', 'replay', *flags,
                           '--json'], capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout)


def read_samples(path):
    """Stamps, angles and speeds read back by the mcap library (an independent reader)."""
    rows = []
    for file in sorted(path.glob('*.mcap')):
        with open(file, 'rb') as stream:
            records = list(make_reader(stream).iter_messages())
        for _, _, record in records:
            message = deserialize_message(record.data, JointState)
            stamp = message.header.stamp.sec * 10**9 + message.header.stamp.nanosec
            rows.append((stamp, message.position[0], message.velocity[0]))
    stamps, angles, speeds = zip(*rows)
    return np.array(stamps, dtype=np.int64), np.array(angles), np.array(speeds)


def written_rows(path, topic):
    """{stamp: (x, y)} of a Vector3Stamped topic, read back by the mcap library."""
    rows = {}
    for file in sorted(path.glob('*.mcap')):
        with open(file, 'rb') as stream:
            for _, channel, record in make_reader(stream).iter_messages(topics=[topic]):
                message = deserialize_message(record.data, Vector3Stamped)
                stamp = message.header.stamp.sec * 10**9 + message.header.stamp.nanosec
                rows[stamp] = (message.vector.x, message.vector.y)
    return rows


def test_replay_nonlinear_on_writes_the_nonlinear_deflections(tmp_path):
    bag, out, linear = tmp_path / 'bag', tmp_path / 'out', tmp_path / 'linear'
    write_bag(bag, 391.0)
    cache = ['--cache-dir', str(tmp_path / 'cache')]
    result = replay(str(bag), '--out', str(out), '--nonlinear', 'on', *SMALL_MODEL, *cache)
    assert result['model_choice'] == {'nonlinear': True, 'why': 'asked for (--nonlinear on)',
                                      'asked': 'on'}
    replay(str(bag), '--out', str(linear), '--nonlinear', 'off', *SMALL_MODEL, *cache)
    recorded = read_provenance(out)
    assert recorded.nonlinear == 'on' and read_provenance(linear).nonlinear == 'off'
    tables, _ = nonlinear_model_for(recorded.mechanism(), recorded.options(), use_cache=False)
    stamps, angles, speeds = read_samples(bag)
    expected = estimate_nonlinear(tables, stamps, angles, speeds)['outputs']
    topics = output_topics(NODE_NAME)
    for key, columns in (('lever_tip', slice(0, 2)), ('coupler_mid', slice(2, 4))):
        written = written_rows(out, topics[key])
        assert len(written) == stamps.size
        rows = np.array([written[stamp] for stamp in stamps.tolist()])
        # The replay steps on its crank filter's angle and speed, the estimate on the raw
        # samples: equal here but for the filter's start.
        span = expected[:, columns].max(axis=0) - expected[:, columns].min(axis=0)
        assert np.all(np.abs(rows - expected[:, columns]) <= 0.01 * span), key
        linear_written = written_rows(linear, topics[key])
        linear_rows = np.array([linear_written[stamp] for stamp in stamps.tolist()])
        assert np.max(np.abs(rows - linear_rows)) > 0.05 * span.max(), key
    nonlinear = result['nonlinear']
    assert nonlinear['refused_samples'] == 0 and nonlinear['samples'] == stamps.size
    lever = written_rows(out, topics['lever_tip'])
    written = np.array([lever[stamp] for stamp in stamps.tolist()])
    np.testing.assert_allclose(nonlinear['lever_tip_peak_to_peak_um'],
                               1e6 * (written.max(axis=0) - written.min(axis=0)), rtol=1e-12)
    assert result['lever_tip_peak_to_peak_um'] == nonlinear['lever_tip_peak_to_peak_um']


def test_a_nonlinear_replay_replayed_with_no_flags_reproduces_itself(tmp_path):
    bag, first, second = tmp_path / 'bag', tmp_path / 'first', tmp_path / 'second'
    write_bag(bag, 391.0, seconds=0.6)
    cache = ['--cache-dir', str(tmp_path / 'cache')]
    replay(str(bag), '--out', str(first), '--nonlinear', 'on', *SMALL_MODEL, *cache)
    again = replay(str(first), '--out', str(second), *cache)     # the recording's own model
    assert again['model_choice']['asked'] == 'on' and again['model_choice']['nonlinear']
    assert again['model_choice']['why'] == \
        "the recording's model (its provenance says nonlinear: on)"
    topic = output_topics(NODE_NAME)['coupler_mid']
    assert written_rows(second, topic) == written_rows(first, topic)


def test_bad_samples_and_a_gap_are_skipped_and_counted_not_stepped(tmp_path):
    """Bad angles (NaN, absurd) are refused before the model steps; a 2 s gap restarts it."""
    def edit(times, angles):
        angles[200:205] = np.nan
        angles[300] = 1e12
        times[700:] += 2.0

    bag, out = tmp_path / 'bag', tmp_path / 'out'
    write_bag(bag, 391.0, edit=edit)
    result = replay(str(bag), '--out', str(out), '--nonlinear', 'on', *SMALL_MODEL,
                    '--cache-dir', str(tmp_path / 'cache'))
    nonlinear = result['nonlinear']
    assert nonlinear['restarts'] == 1 and nonlinear['refused_samples'] == 0
    # The five NaN are skipped on reading, the absurd angle refused by the estimate; the
    # model steps exactly the samples the linear estimate published.
    assert result['skipped'] == 5, result['skipped_reasons']
    assert nonlinear['samples'] == result['quality']['messages'] <= result['samples'] - 1, (
        result['samples'], result['quality'], nonlinear)
    lever = written_rows(out, output_topics(NODE_NAME)['lever_tip'])
    assert lever and np.isfinite(np.array(list(lever.values()))).all()
    assert all(np.isfinite(result['lever_tip_peak_to_peak_um']))


def test_replay_auto_picks_the_linear_model_at_low_speed(tmp_path):
    bag = tmp_path / 'bag'
    write_bag(bag, 30.0, seconds=2.5)
    result = replay(str(bag), '--chart', str(tmp_path / 'c.png'), *SMALL_MODEL,
                    '--cache-dir', str(tmp_path / 'cache'))
    assert result['model_choice']['nonlinear'] is False, result['model_choice']
    assert result['model_choice']['why'].startswith('auto: the linear estimate is valid')
    assert result['nonlinear'] is None


# inotify: the file was opened, or closed unwritten (alternate events: identical ones in a
# row would be merged into one).
IN_OPEN, IN_CLOSE_NOWRITE = 0x20, 0x10


class OpenCounter:
    """Opens of one file by any process, counted by the kernel (inotify)."""

    def __init__(self, path):
        libc = ctypes.CDLL(None, use_errno=True)
        self.descriptor = libc.inotify_init1(os.O_NONBLOCK)
        assert self.descriptor >= 0 and libc.inotify_add_watch(
            self.descriptor, str(path).encode(), IN_OPEN | IN_CLOSE_NOWRITE) >= 0

    def take(self):
        """Return the opens since the last call."""
        opens = 0
        while True:
            try:
                data = os.read(self.descriptor, 4096)
            except BlockingIOError:
                return opens
            # struct inotify_event: wd, mask, cookie, len (no name for a watched file).
            events = np.frombuffer(data, dtype=[('wd', '<i4'), ('mask', '<u4'),
                                                ('cookie', '<u4'), ('len', '<u4')])
            assert not events['len'].any()
            opens += int(np.count_nonzero(events['mask'] & IN_OPEN))

    def close(self):
        os.close(self.descriptor)


def all_messages(path):
    """(topic, log, publish, sequence, bytes) of every message of an MCAP file."""
    with open(path, 'rb') as stream:
        return [(channel.topic, m.log_time, m.publish_time, m.sequence, bytes(m.data))
                for _, channel, m in make_reader(stream).iter_messages(log_time_order=False)]


@pytest.mark.parametrize('rpm, kept', [(30.0, 'off'), (391.0, 'on')])
def test_replay_auto_reads_a_recording_it_keeps_linear_once(tmp_path, rpm, kept):
    """Valid: the linear pass's output stays (read once); not valid: the nonlinear one's."""
    bag = tmp_path / 'bag'
    write_bag(bag, rpm, seconds=2.5)
    counter = OpenCounter(next(bag.glob('*.mcap')))
    flags = [*SMALL_MODEL, '--cache-dir', str(tmp_path / 'cache')]
    try:
        fixed = replay(str(bag), '--out', str(tmp_path / 'fixed.mcap'), '--nonlinear', kept,
                       *flags)
        fixed_opens = counter.take()
        auto = replay(str(bag), '--out', str(tmp_path / 'auto.mcap'), *flags)
        auto_opens = counter.take()
    finally:
        counter.close()
    assert auto['model_choice']['nonlinear'] is (kept == 'on')
    assert auto['model_choice']['why'].startswith('auto: the linear estimate is '
                                                  + ('valid' if kept == 'off' else 'not'))
    assert all_messages(tmp_path / 'auto.mcap') == all_messages(tmp_path / 'fixed.mcap')
    assert auto['lever_tip_peak_to_peak_um'] == fixed['lever_tip_peak_to_peak_um']
    if kept == 'off':
        assert auto_opens == fixed_opens > 0
    else:
        assert auto_opens > fixed_opens > 0
    assert read_provenance(tmp_path / 'auto.mcap').nonlinear == kept


@pytest.fixture(scope='module')
def damped_tables():
    """Return a small nonlinear model damped to fade a start in 0.25 s (a test's spans)."""
    return small_nonlinear_tables(5e-3)


def _linear_blocks(count, block_rows, gaps=(), outliers=(), faster_after=None):
    """Blocks of (first, samples, estimate) as the linear replay hands them on (1 kHz)."""
    rng = np.random.default_rng(7)
    steps = 1e-3 * (1.0 + 0.3 * rng.uniform(-1, 1, count - 1))
    if faster_after is not None:
        steps[faster_after:] *= 0.025       # then 40 kHz: a span shorter than a warm-up
    time_s = np.concatenate([[0.0], np.cumsum(steps)])
    speeds = 41.0 * (1.0 + 0.05 * np.sin(3.0 * time_s))
    stamps = np.round(time_s * 1e9).astype(np.int64)
    for row in gaps:
        stamps[row:] += 1_000_000_000
    angles = np.mod(41.0 * time_s, 2.0 * math.pi)
    lever = np.zeros((count, 2))
    lever[list(outliers)] = np.nan
    for first in range(0, count, block_rows):
        rows = slice(first, first + block_rows)
        yield first, {'stamps_ns': stamps[rows]}, {
            'lever_tip': lever[rows], 'coupler_mid': lever[rows].copy(),
            'crank_angle': angles[rows], 'crank_speed': speeds[rows],
            'criterion': np.full((len(angles[rows]), 4), 0.5)}


def test_spans_followed_in_threads_give_the_block_by_block_follower(damped_tables):
    """Three spans (two threads) with outliers, a gap in a warm-up and one in a span."""
    count, gaps, outliers = 12_000, (3_900, 9_000), (5, 4_100, 4_101, 11_999)
    reference = NonlinearRows(damped_tables, 0.1, speed_max=60.0)
    expected = [(first, reference(samples, estimate)) for first, samples, estimate
                in _linear_blocks(count, 1000, gaps, outliers)]
    spans = NonlinearRows(damped_tables, 0.1, speed_max=60.0, threads=2)
    got = list(spans.blocks(_linear_blocks(count, 1000, gaps, outliers), count,
                            max_span_rows=4096))
    assert [first for first, _, _ in got] == [first for first, _ in expected]
    for (_, _, mine), (_, theirs) in zip(got, expected):
        assert np.array_equal(mine['criterion'], theirs['criterion'])     # passed through
        for key in ('lever_tip', 'coupler_mid'):
            assert np.array_equal(np.isnan(mine[key]), np.isnan(theirs[key]))
    outputs = {key: np.concatenate([block[key] for _, _, block in got])
               for key in ('lever_tip', 'coupler_mid')}
    for key, values in outputs.items():
        reference_values = np.concatenate([block[key] for _, block in expected])
        span = np.nanmax(reference_values, axis=0) - np.nanmin(reference_values, axis=0)
        assert np.nanmax(np.abs(values - reference_values) / span) <= 1e-11, key
    mine, theirs = spans.summary(), reference.summary()
    assert {k: mine[k] for k in ('samples', 'refused_samples', 'restarts')} == \
        {k: theirs[k] for k in ('samples', 'refused_samples', 'restarts')} == \
        {'samples': count - len(outliers), 'refused_samples': 0, 'restarts': 2}
    np.testing.assert_allclose(mine['lever_tip_peak_to_peak_um'],
                               theirs['lever_tip_peak_to_peak_um'], rtol=1e-9)
    assert mine['link_slope_max_rad'] == pytest.approx(theirs['link_slope_max_rad'], rel=1e-9)


def test_a_warm_up_reaches_back_over_spans_shorter_than_it(damped_tables):
    """The rate rises 40-fold after the first spans: a span lasts 0.1 s, a warm-up 0.25 s."""
    count, args = 20_000, (1000, (), (), 9_000)
    reference = NonlinearRows(damped_tables, 0.1, speed_max=60.0)
    expected = np.concatenate([reference(samples, estimate)['lever_tip'] for _, samples, estimate
                               in _linear_blocks(count, *args)])
    spans = NonlinearRows(damped_tables, 0.1, speed_max=60.0, threads=2)
    got = np.concatenate([block['lever_tip'] for _, _, block in spans.blocks(
        _linear_blocks(count, *args), count, max_span_rows=4096)])
    span = np.ptp(expected, axis=0)
    assert np.max(np.abs(got - expected) / span) <= 1e-11


def test_a_recording_too_short_for_two_spans_is_followed_block_by_block(damped_tables):
    blocks = list(_linear_blocks(1500, 500))
    reference = NonlinearRows(damped_tables, 0.1, speed_max=60.0)
    expected = [reference(samples, estimate)['lever_tip'] for _, samples, estimate in blocks]
    got = NonlinearRows(damped_tables, 0.1, speed_max=60.0, threads=2).blocks(iter(blocks), 1500)
    assert all(np.array_equal(mine['lever_tip'], theirs)
               for (_, _, mine), theirs in zip(got, expected))


def test_a_first_block_of_one_repeated_stamp_is_followed_block_by_block(damped_tables):
    """No rate to size the spans by (and no division by zero said on stderr)."""
    blocks = list(_linear_blocks(12_000, 1000))
    blocks[0][1]['stamps_ns'][:] = blocks[0][1]['stamps_ns'][0]
    expected = [NonlinearRows(damped_tables, 0.1, speed_max=60.0)(blocks[0][1], blocks[0][2])]
    with warnings.catch_warnings():
        warnings.simplefilter('error')
        got = next(NonlinearRows(damped_tables, 0.1, speed_max=60.0, threads=2).blocks(
            iter(blocks), 12_000, max_span_rows=4096))
    assert np.array_equal(got[2]['lever_tip'], expected[0]['lever_tip'], equal_nan=True)


def test_threads_is_taken_and_bounded(tmp_path):
    """`--threads 2` on a recording too short for spans writes what one thread writes."""
    bag = tmp_path / 'bag'
    write_bag(bag, 391.0, seconds=0.6)
    cache = ['--cache-dir', str(tmp_path / 'cache')]
    one = replay(str(bag), '--out', str(tmp_path / 'one'), '--nonlinear', 'on', *SMALL_MODEL,
                 *cache)
    two = replay(str(bag), '--out', str(tmp_path / 'two'), '--nonlinear', 'on', '--threads',
                 '2', *SMALL_MODEL, *cache)
    assert two['nonlinear'] == one['nonlinear']
    topic = output_topics(NODE_NAME)['lever_tip']
    assert written_rows(tmp_path / 'two', topic) == written_rows(tmp_path / 'one', topic)
    refused = subprocess.run([sys.executable, '-m', 'flexlink_ros.cli.main', 'replay', str(bag),
                              '--out', str(tmp_path / 'none'), '--threads', '0', *SMALL_MODEL],
                             capture_output=True, text=True, timeout=600)
    assert refused.returncode == 1 and '`--threads` must be in 1..16, got 0' in refused.stderr
    assert not (tmp_path / 'none').exists()
