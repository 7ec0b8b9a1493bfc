"""`flexlink replay`: the offline estimate of a recording against the streaming estimator."""

import json
import math
import pathlib
import subprocess
import sys

from flexlink_ros.core.estimation.streaming import StreamingEstimator
from flexlink_ros.core.mechanism_file import load_mechanism
from flexlink_ros.core.reduction import mechanism_model
from flexlink_ros.io import output_cdr
from flexlink_ros.io.recorder import McapRecorder
from flexlink_ros.io.recording import iter_recording
from flexlink_ros.ros import messages as ros_messages
from flexlink_ros.ros import parameters as node_params
from geometry_msgs.msg import Vector3Stamped
from hostile_bag import ENTRIES, plant_hostile_entries
import numpy as np
import pytest
from rclpy.serialization import deserialize_message, serialize_message
from rosbags.highlevel import AnyReader
from sensor_msgs.msg import JointState

RPM = 2.0 * math.pi / 60.0


@pytest.fixture(scope='module')
def model():
    # The replay's default model (the node's) without geometric stiffness, cached.
    options = node_params.default_model_options(geometric_stiffness=False)
    return mechanism_model.model_for_mechanism(load_mechanism('cho1992'), options)


def joint_state(stamp_ns, names, positions, velocities=()):
    message = JointState(name=list(names), position=[float(p) for p in positions],
                         velocity=[float(v) for v in velocities])
    message.header.stamp = ros_messages.ns_to_stamp(stamp_ns)
    message.header.frame_id = 'odd_length_frame'
    return message


def write_recording(path, stamps_ns, angles, speeds, bad=()):
    """Write a bag of crank JointStates (receive time = stamp + 200 us), with bad messages."""
    with McapRecorder(path) as recorder:
        recorder.add_topic('/joint_states', JointState)
        for stamp, angle, speed in zip(stamps_ns, angles, speeds):
            data = serialize_message(joint_state(stamp, ['crank'], [angle], [speed]))
            recorder.write('/joint_states', data, stamp + 200_000)
        for stamp, message in bad:
            recorder.write('/joint_states', serialize_message(message), stamp)


def test_replay_equals_the_streaming_estimator(tmp_path, model):
    rng = np.random.default_rng(3)
    steps = (1.0 + 0.3 * rng.uniform(-1, 1, 700)) * 1e-3
    times = np.concatenate([[0.0], np.cumsum(steps)])
    times[400:] += 0.8             # a gap: both restart there
    stamps = (1_700_000_000_000_000_000 + np.round(times * 1e9)).astype(np.int64)
    speed = 391.0 * RPM
    angles = np.mod(speed * times + 0.3 + np.pi, 2 * np.pi) - np.pi   # encoder in [-pi, pi)
    bad = [(int(stamps[10]) + 1, joint_state(int(stamps[10]) + 1, ['crank'], [math.nan])),
           (int(stamps[20]) + 1, joint_state(int(stamps[20]) + 1, ['lever'], [0.0]))]
    bag = tmp_path / 'bag'
    write_recording(bag, stamps, angles, np.full(stamps.size, speed), bad)
    out = tmp_path / 'replay.mcap'
    result = subprocess.run([sys.executable, '-m', 'flexlink_ros.cli.main', 'replay', str(bag),
                             '--out', str(out), '--no-geometric-stiffness', '--json',
                             '--mechanism', 'cho1992',   # the bag names no model
                             '--nonlinear', 'off',       # the linear estimator's rows
                             '--markers-every-n', '50'],
                            capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    summary = json.loads(result.stdout)
    assert summary['samples'] == stamps.size and summary['skipped'] == 2
    assert summary['segments'] == 2 and summary['topic'] == '/joint_states'
    assert summary['order'] == model.order == 2       # the default: second-order outputs

    estimator = StreamingEstimator(model)
    expected = {s: estimator.update(s, a, speed) for s, a in zip(stamps.tolist(), angles)}
    counts = {}
    worst = 0.0
    criteria_seen = False
    for topic, type_name, log_ns, _, data in iter_recording(out):
        counts[topic] = counts.get(topic, 0) + 1
        if topic.endswith('/deflection'):
            message = deserialize_message(data, Vector3Stamped)
            stamp = ros_messages.stamp_to_ns(message.header.stamp)
            assert log_ns == stamp + 200_000          # logged at the input's receive time
            sample = expected[stamp]
            reference = sample.lever_tip if 'lever_tip' in topic else sample.coupler_mid
            error = math.hypot(message.vector.x - reference[0], message.vector.y - reference[1])
            worst = max(worst, error / math.hypot(*reference) if any(reference) else error)
            assert message.header.frame_id == 'linkage_ground'
        if topic.endswith('/joint_criteria'):
            message = deserialize_message(data, JointState)
            sample = expected[ros_messages.stamp_to_ns(message.header.stamp)]
            for got, reference in ((message.position, sample.criterion),
                                   (message.velocity, sample.gamma_dot),
                                   (message.effort, sample.reaction_n)):
                assert list(got) == pytest.approx(reference, rel=1e-6, abs=1e-12)
            criteria_seen = criteria_seen or any(sample.criterion)
    assert worst < 1e-6
    assert criteria_seen == bool(np.any(model.force_moments))
    assert counts == {'/joint_states': 701, '/flexlink_node/lever_tip/deflection': 701,
                      '/flexlink_node/coupler_mid/deflection': 701,
                      '/flexlink_node/joint_criteria': 701, '/flexlink_node/quality': 701,
                      '/flexlink_node/markers': 15}
    assert summary['quality']['messages'] == 701
    assert summary['output_topics']['/flexlink_node/quality'] == 701
    check_quality(out, expected)


def check_quality(out, expected):
    """Quality of every estimate, read by rosbags: input stamps, the node's values and bytes."""
    seen = []
    with AnyReader([out]) as reader:
        connections = [c for c in reader.connections if c.topic == '/flexlink_node/quality']
        assert [c.msgtype for c in connections] == ['sensor_msgs/msg/JointState']
        for connection, log_ns, data in reader.messages(connections=connections):
            message = reader.deserialize(data, connection.msgtype)
            stamp = message.header.stamp.sec * 1_000_000_000 + message.header.stamp.nanosec
            assert log_ns == stamp + 200_000 and message.header.frame_id == 'linkage_ground'
            assert list(message.name) == ['error_indicator', 'nonlinearity']
            sample = expected[stamp]
            error, nonlinearity = message.position.tolist()
            assert error == pytest.approx(sample.error_indicator, rel=1e-5, abs=1e-12)
            assert nonlinearity == pytest.approx(sample.nonlinearity, rel=1e-5, abs=1e-12)
            # the bytes the node publishes and records for these values
            assert bytes(data) == output_cdr.quality_cdr(
                message.header.stamp.sec, message.header.stamp.nanosec, b'linkage_ground',
                error, nonlinearity)
            seen.append(stamp)
    assert seen == sorted(expected) and any(expected[s].error_indicator > 0 for s in seen)


def test_replay_refuses_missing_topic_and_existing_output(tmp_path):
    bag = tmp_path / 'bag'
    write_recording(bag, [10**9, 10**9 + 10**6], [0.0, 0.04], [40.0, 40.0])
    run = lambda *extra: subprocess.run(  # noqa: E731
        [sys.executable, '-m', 'flexlink_ros.cli.main', 'replay', str(bag), *extra],
        capture_output=True, text=True, timeout=120)
    result = run('--out', str(tmp_path / 'x.mcap'), '--joint', 'wheel', '--mechanism', 'cho1992')
    assert result.returncode == 1 and "joint 'wheel'" in result.stderr
    result = run('--out', str(bag))
    assert result.returncode == 1 and 'exists' in result.stderr
    result = run()
    assert result.returncode == 1 and '--publish' in result.stderr


def deflections_by_stamp(path):
    """{stamp: (lever_tip x, y, coupler_mid x, y)} of a replay's output MCAP."""
    found = {}
    for topic, _, _, _, data in iter_recording(path):
        if topic.endswith('/deflection'):
            message = deserialize_message(data, Vector3Stamped)
            stamp = ros_messages.stamp_to_ns(message.header.stamp)
            offset = 0 if 'lever_tip' in topic else 2
            found.setdefault(stamp, [math.nan] * 4)[offset:offset + 2] = (
                message.vector.x, message.vector.y)
    return found


def test_replay_skips_poisoned_speeds_and_matches_a_clean_replay(tmp_path):
    """+1.7e308, -1.7e308 and 1e6 rad/s in a recording: counted outliers, nothing else moves."""
    stamps = 1_700_000_000_000_000_000 + np.arange(600, dtype=np.int64) * 1_000_000
    speed = 391.0 * RPM
    angles = speed * (stamps - stamps[0]) * 1e-9
    poison = {300: 1.7e308, 301: -1.7e308, 450: 1e6}
    bad = []
    for n, value in poison.items():
        stamp = int(stamps[n]) + 400_000       # between two samples, at a plausible angle
        bad.append((stamp, joint_state(stamp, ['crank'], [angles[n] + 0.4e-3 * speed],
                                       [value])))
    results = {}
    for name, extra in (('clean', []), ('poisoned', bad)):
        bag = tmp_path / name
        write_recording(bag, stamps, angles, np.full(stamps.size, speed), extra)
        out = tmp_path / f'{name}.mcap'
        result = subprocess.run([sys.executable, '-m', 'flexlink_ros.cli.main', 'replay', str(bag),
                                 '--out', str(out), '--no-geometric-stiffness',
                                 '--markers-every-n', '0', '--mechanism', 'cho1992'],
                                capture_output=True, text=True, timeout=300)
        assert result.returncode == 0, result.stderr
        results[name] = (result.stdout, deflections_by_stamp(out))
    assert '3 outlier(s), 0 out of bound, 1 segment(s)' in results['poisoned'][0]
    assert '0 outlier(s)' in results['clean'][0]
    clean, poisoned = results['clean'][1], results['poisoned'][1]
    # The poison has no outputs; every other sample's output equals the clean replay's.
    assert sorted(poisoned) == sorted(clean) == stamps.tolist()
    for stamp, values in clean.items():
        assert poisoned[stamp] == values


def test_replay_refuses_an_existing_out_path_before_estimating(tmp_path):
    """A dangling link at --out is refused at once with what is there; nothing is created."""
    link = tmp_path / 'out.mcap'
    link.symlink_to(tmp_path / 'target.mcap')
    result = subprocess.run([sys.executable, '-m', 'flexlink_ros.cli.main', 'replay',
                             str(tmp_path / 'no_such_bag'), '--out', str(link)],
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 1
    assert '`--out`' in result.stderr and 'dangling' in result.stderr
    assert 'Traceback' not in result.stderr
    assert not (tmp_path / 'target.mcap').exists() and link.is_symlink()


@pytest.mark.parametrize('names', [('fifo_2.mcap',), ENTRIES], ids=['fifo', 'all'])
def test_replay_of_a_bag_skips_a_fifo_links_out_and_a_device(tmp_path, names):
    """These once hung replay for ever, read a file outside the bag, or failed the bag."""
    stamps = [10**18 + k * 10**6 for k in range(300)]
    angles = [math.remainder(40.0 * k * 1e-3, 2 * math.pi) for k in range(300)]
    write_recording(tmp_path / 'bag', stamps, angles, [40.0] * 300)
    write_recording(tmp_path / 'elsewhere', stamps[:5], angles[:5], [40.0] * 5)
    planted = plant_hostile_entries(tmp_path / 'bag', tmp_path / 'elsewhere' / 'elsewhere_0.mcap',
                                    names)
    done = subprocess.run([sys.executable, '-m', 'flexlink_ros.cli.main', 'replay',
                           str(tmp_path / 'bag'), '--out', str(tmp_path / 'out.mcap'), '--json',
                           '--mechanism', 'cho1992'],   # the bag names no model
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    result = json.loads(done.stdout)
    assert result['samples'] == 300
    assert sorted(pathlib.Path(d['file']).name for d in result['damaged']) == sorted(planted)
    for name in planted:
        assert f"{tmp_path / 'bag' / name} skipped" in done.stderr


def evil_mechanism(tmp_path, name='../../../escape/dir/x'):
    """Write the shipped Cho 1992 file with a name that spells a path."""
    import yaml
    from flexlink_ros.core.mechanism_file import find_config
    data = yaml.safe_load(find_config('cho1992').read_text())
    data['name'] = name
    path = tmp_path / 'evil.yaml'
    path.write_text(yaml.safe_dump(data))
    return path


def test_a_mechanism_name_that_spells_a_path_is_refused_in_one_line(tmp_path):
    bag = tmp_path / 'in.mcap'
    write_recording(bag, [1_700_000_000 * 10**9 + k * 10**6 for k in range(5)],
                    [0.01 * k for k in range(5)], [10.0] * 5)
    cache = tmp_path / 'a' / 'b' / 'c' / 'cache'
    result = subprocess.run([sys.executable, '-m', 'flexlink_ros.cli.main', 'replay', str(bag),
                             '--out', str(tmp_path / 'out'), '--mechanism',
                             str(evil_mechanism(tmp_path)), '--cache-dir', str(cache)],
                            capture_output=True, text=True, timeout=300)
    assert result.returncode != 0 and 'Traceback' not in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1, result.stderr
    assert 'name:' in result.stderr and 'not a plain name' in result.stderr
    assert not (tmp_path / 'a' / 'escape').exists() and not cache.exists()
