"""`flexlink replay --processes 2`: the second part forked, the messages of one process."""

import subprocess
import sys

from flexlink_ros.core.estimation.follow_spans import WARM_UP_TOLERANCE
from flexlink_ros.io.recorder import McapRecorder
from mcap.reader import make_reader
import numpy as np
import pytest
from rosbags.highlevel import AnyReader
from sensor_msgs.msg import JointState
from test_replay_offline import messages, replay_bench, replay_json, RUN_KEYS

# What differs between one process and two besides the values: timings, output, the split.
SPLIT_RUN_KEYS = RUN_KEYS + ('processes',)


def recording(path, seconds=60.0, gaps=(), outliers=(), other_joint=False):
    """
    Write the benchmark's 1 kHz crank signal; stamps from each gap row on 0.8 s later.

    ``other_joint``: each sample followed by a message of another joint (skipped by a replay).
    """
    module = replay_bench()
    stamps, angles, speeds = module.synthetic_signal(391.0, seconds, 1000.0, jitter=0.3,
                                                     seed=1)
    stamps = stamps + module.START_NS
    for row in gaps:
        stamps[row:] += 800_000_000
    speeds = np.array(speeds, dtype=float)
    speeds[list(outliers)] = 1e6               # implausible speeds: the gate refuses them
    angles = np.mod(angles + np.pi, 2.0 * np.pi) - np.pi
    data = module.crank_messages(stamps, angles, speeds)
    log = stamps + module.LOG_DELAY_NS
    if other_joint:
        wheel = [row.replace(b'crank\x00', b'wheel\x00') for row in data]
        data = [message for pair in zip(data, wheel) for message in pair]
        log = np.repeat(log, 2)
    with McapRecorder(path) as recorder:
        recorder.add_topic('/joint_states', JointState)
        recorder.write_batch('/joint_states', data, log)
    return path


def replay(bag, out, *extra):
    return replay_json(bag, out, '--mechanism', 'cho1992', '--nonlinear', 'off', *extra)


def doubles(data):
    """Read a message's bytes after the CDR encapsulation as little-endian doubles."""
    size = (len(data) - 4) // 8 * 8
    return np.frombuffer(data[4:4 + size], dtype='<f8')


def largest_relative_difference(expected, got):
    """
    Compare two outputs message by message: each topic's largest difference over its range.

    Topic, log and publish time, sequence and length must be equal; where the bytes differ,
    each double that differs is compared with the range of that value over the topic.
    """
    assert len(expected) == len(got)
    ranges = {}
    for topic, *_, data in expected:
        values = doubles(data)
        low, high = ranges.get(topic, (values, values))
        if len(low) == len(values):
            ranges[topic] = (np.minimum(low, values), np.maximum(high, values))
    worst = dict.fromkeys(ranges, 0.0)
    for (topic, *head, data), (other, *other_head, other_data) in zip(expected, got):
        assert (topic, *head, len(data)) == (other, *other_head, len(other_data))
        if data != other_data:
            a, b = doubles(data), doubles(other_data)
            differ = a != b
            span = ranges[topic][1] - ranges[topic][0]
            assert np.all(np.isfinite(b[differ])) and np.all(span[differ] > 0)
            worst[topic] = max(worst[topic],
                               float(np.max(np.abs(a - b)[differ] / span[differ])))
    return worst


# The second part's values against one process's, over each value's range. The deflections
# (and the markers drawn from them) agree to the rounding of the state (measured 1.9e-12);
# the criteria and the quality take the crank filter's acceleration, whose fit amplifies the
# rounding of its moments (measured 6.5e-11 and 1.5e-11 of their ranges).
DEFLECTION_TOLERANCE = 5 * WARM_UP_TOLERANCE
OUTPUT_TOLERANCE = 2e-10


def check_close(worst):
    """Assert each topic of ``largest_relative_difference`` within its tolerance."""
    for topic, value in worst.items():
        bound = OUTPUT_TOLERANCE if topic.endswith(('criteria', 'quality')) else (
            DEFLECTION_TOLERANCE)
        assert value <= bound, (topic, value)


def summary_keys(result):
    return {key: value for key, value in result.items() if key not in SPLIT_RUN_KEYS}


@pytest.fixture(scope='module')
def smooth(tmp_path_factory):
    """Write a 60 s recording and replay it in one process."""
    folder = tmp_path_factory.mktemp('split')
    bag = recording(folder / 'bag.mcap')
    one = replay(bag, folder / 'one.mcap', '--processes', '1')
    return bag, one, messages(folder / 'one.mcap')


def test_a_forked_replay_writes_the_messages_of_one_process(smooth, tmp_path):
    """Every message's topic, times, sequence; the second part's values to 1e-12 of range."""
    bag, one, expected = smooth
    out = tmp_path / 'two.mcap'
    two = replay(bag, out, '--processes', '2')
    assert one['processes'] == {'used': 1}
    assert two['processes']['used'] == 2 and two['processes']['second_part'] == 'forked'
    got = messages(out)
    split = two['processes']['split_row']
    assert 20_000 < split < 40_000
    # The first part and the input are the bytes of one process; the second part's values
    # within the warm-up's tolerance of each value's range.
    first_outputs = [m for m in expected if m[1] < expected[0][1] + split * 900_000]
    assert got[:len(first_outputs)] == first_outputs
    assert [m for m in got if m[0] == '/joint_states'] == [
        m for m in expected if m[0] == '/joint_states']
    worst = largest_relative_difference(expected, got)
    check_close(worst)
    assert worst['/joint_states'] == 0.0 < worst['/flexlink_node/lever_tip/deflection']
    a, b = summary_keys(one), summary_keys(two)
    for key in ('lever_tip_peak_to_peak_um', 'coupler_mid_peak_to_peak_um'):
        assert np.allclose(a.pop(key), b.pop(key), rtol=1e-9, atol=0)
    a['quality'].pop('error_indicator_max'), b['quality'].pop('error_indicator_max')
    a['quality'].pop('nonlinearity_max'), b['quality'].pop('nonlinearity_max')
    assert a == b


def test_the_appended_part_reads_back_as_one_file(smooth, tmp_path):
    """The indexed reader of mcap and rosbags see every message; the statistics count all."""
    bag, _, expected = smooth
    out = tmp_path / 'two.mcap'
    replay(bag, out, '--processes', '2')
    with open(out, 'rb') as stream:
        reader = make_reader(stream)
        summary = reader.get_summary()
        in_order = [(c.topic, m.log_time, m.sequence)
                    for _, c, m in reader.iter_messages(log_time_order=True)]
    assert summary.statistics.message_count == len(expected) == len(in_order)
    assert summary.statistics.chunk_count == len(summary.chunk_indexes) > 2
    counts = {summary.channels[k].topic: n
              for k, n in summary.statistics.channel_message_counts.items()}
    assert counts == {topic: sum(1 for m in expected if m[0] == topic)
                      for topic in counts}
    with AnyReader([out]) as reader:
        read = sum(1 for _ in reader.messages())
        lever = [c for c in reader.connections if c.topic.endswith('lever_tip/deflection')]
        decoded = [reader.deserialize(raw, c.msgtype).vector.x
                   for c, _, raw in reader.messages(connections=lever)]
    assert read == len(expected) and len(decoded) == counts[lever[0].topic]
    assert np.all(np.isfinite(decoded))


@pytest.mark.parametrize('gaps, outliers', [
    ((30_000,), (31_000, 50_000)),          # a gap and a refused sample in the second part
    ((10_000, 45_000), (12_000, 47_000)),   # a gap and refused samples in each part
    ((33_000,), ()),                        # the split inside the gap's warm-up
])
def test_gaps_and_refused_samples_give_the_sequential_messages(tmp_path, gaps, outliers):
    """A restart after the warm-up, or a refused row before the split: the sequential bytes."""
    bag = recording(tmp_path / 'bag.mcap', gaps=gaps, outliers=outliers)
    one = replay(bag, tmp_path / 'one.mcap', '--processes', '1')
    two = replay(bag, tmp_path / 'two.mcap', '--processes', '2')
    assert two['processes']['used'] == 2 and two['processes']['second_part'] == 'sequential'
    worst = largest_relative_difference(messages(tmp_path / 'one.mcap'),
                                        messages(tmp_path / 'two.mcap'))
    # The estimate is the sequential one, byte for byte; a marker drawn by numpy's contraction
    # in another process may round a last bit apart (seen: 1 double of 6 000 markers).
    assert {topic: value for topic, value in worst.items()
            if not topic.endswith('/markers')} == dict.fromkeys(
                [topic for topic in worst if not topic.endswith('/markers')], 0.0)
    assert max(value for topic, value in worst.items() if topic.endswith('/markers')) < 1e-12
    assert summary_keys(two) == summary_keys(one)
    assert one['segments'] == 1 + len(gaps) and one['outliers'] == len(outliers)


def test_refused_samples_after_the_split_stay_in_the_forked_part(tmp_path):
    """The child's gate refuses what one process refuses; no restart: its part is kept."""
    bag = recording(tmp_path / 'bag.mcap', outliers=(40_000, 52_000))
    one = replay(bag, tmp_path / 'one.mcap', '--processes', '1')
    two = replay(bag, tmp_path / 'two.mcap', '--processes', '2')
    assert two['processes']['second_part'] == 'forked'
    assert two['outliers'] == one['outliers'] == 2
    check_close(largest_relative_difference(messages(tmp_path / 'one.mcap'),
                                            messages(tmp_path / 'two.mcap')))


def test_a_short_recording_runs_in_one_process(tmp_path):
    """Too short for a warm-up and a part of its own: one process, whatever is asked."""
    bag = recording(tmp_path / 'bag.mcap', seconds=12.0)
    assert replay(bag, tmp_path / 'out.mcap', '--processes', '2')['processes'] == {'used': 1}


def test_a_split_past_the_last_usable_row_leaves_the_parent_all_rows(tmp_path):
    """As many messages of another joint as samples: the child only counts what it skips."""
    bag = recording(tmp_path / 'bag.mcap', seconds=40.0, other_joint=True)
    one = replay(bag, tmp_path / 'one.mcap', '--processes', '1')
    two = replay(bag, tmp_path / 'two.mcap', '--processes', '2')
    assert two['processes']['second_part'] == 'empty'
    assert two['processes']['split_row'] > one['samples'] == one['skipped'] > 39_000
    assert summary_keys(two) == summary_keys(one)
    assert messages(tmp_path / 'two.mcap') == messages(tmp_path / 'one.mcap')


def test_a_forked_replay_into_a_folder_not_made_yet(smooth, tmp_path):
    """The child's part waits in the nearest folder that exists, and is gone afterwards."""
    bag, _, expected = smooth
    out = tmp_path / 'new' / 'deeper' / 'two.mcap'
    assert replay(bag, out, '--processes', '2')['processes']['second_part'] == 'forked'
    assert len(messages(out)) == len(expected)
    assert sorted(p.name for p in tmp_path.rglob('*')) == ['deeper', 'new', 'two.mcap']


def test_one_process_is_the_default_and_a_bad_count_is_one_line(tmp_path):
    """By default a long recording runs in one process: its bytes are the same on any machine."""
    bag = recording(tmp_path / 'bag.mcap', seconds=30.0)
    assert replay(bag, tmp_path / 'out.mcap')['processes'] == {'used': 1}
    refused = subprocess.run([sys.executable, '-m', 'flexlink_ros.cli', 'replay', str(bag),
                              '--out', str(tmp_path / 'three.mcap'), '--processes', '3'],
                             capture_output=True, text=True, timeout=120)
    assert refused.returncode != 0 and 'Traceback' not in refused.stderr
    assert '`--processes` must be 1 or 2, got 3' in refused.stderr
