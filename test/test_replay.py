"""`flexlink replay`: the offline estimate of a recording against the streaming estimator."""

import json
import math
import subprocess
import sys

import numpy as np
import pytest
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import JointState

from flexlink_ros.cli import replay as cli_replay
from flexlink_ros.ros import parameters as node_params, messages as ros_messages
from flexlink_ros.core.reduction import model as reduced
from flexlink_ros.core.estimation.streaming import StreamingEstimator
from flexlink_ros.core.mechanism import load_mechanism
from flexlink_ros.io.recorder import McapRecorder

RPM = 2.0 * math.pi / 60.0


@pytest.fixture(scope='module')
def model():
    # The replay's default model (the node's) without geometric stiffness, cached.
    options = node_params.default_model_options(geometric_stiffness=False)
    return reduced.model_for_mechanism(load_mechanism('cho1992'), options)


def joint_state(stamp_ns, names, positions, velocities=()):
    message = JointState(name=list(names), position=[float(p) for p in positions],
                         velocity=[float(v) for v in velocities])
    message.header.stamp = ros_messages.ns_to_stamp(stamp_ns)
    message.header.frame_id = 'odd_length_frame'
    return message


def test_segments_follow_the_streaming_resets():
    stamps = np.array([0, 1, 2, 2, 3, 10**9, 10**9 + 1, 5, 6]) * 1_000_000
    angles = np.array([0.0, 0.1, 0.2, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7])
    starts, repeated = cli_replay.segments(stamps, angles)
    # 3 -> 1000 ms is a 0.997 s gap (> 0.5 s), 1000 -> 5 ms goes back.
    assert starts == [0, 5, 7]
    assert repeated.tolist() == [False, False, False, True] + [False] * 5


def write_recording(path, stamps_ns, angles, speeds, bad=()):
    """A bag of crank JointStates (receive time = stamp + 200 us), with bad messages."""
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
                             '--markers-every-n', '50'],
                            capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    summary = json.loads(result.stdout)
    assert summary['samples'] == stamps.size and summary['skipped'] == 2
    assert summary['segments'] == 2 and summary['topic'] == '/joint_states'

    estimator = StreamingEstimator(model)
    expected = {s: estimator.update(s, a, speed) for s, a in zip(stamps.tolist(), angles)}
    counts = {}
    worst = 0.0
    criteria_seen = False
    for topic, type_name, log_ns, _, data in cli_replay.iter_recording(out):
        counts[topic] = counts.get(topic, 0) + 1
        if topic.endswith('/deflection'):
            from geometry_msgs.msg import Vector3Stamped
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
                      '/flexlink_node/joint_criteria': 701, '/flexlink_node/markers': 15}


def test_replay_refuses_missing_topic_and_existing_output(tmp_path):
    bag = tmp_path / 'bag'
    write_recording(bag, [10**9, 10**9 + 10**6], [0.0, 0.04], [40.0, 40.0])
    run = lambda *extra: subprocess.run(  # noqa: E731
        [sys.executable, '-m', 'flexlink_ros.cli.main', 'replay', str(bag), *extra],
        capture_output=True, text=True, timeout=120)
    result = run('--out', str(tmp_path / 'x.mcap'), '--joint', 'wheel')
    assert result.returncode == 1 and "joint 'wheel'" in result.stderr
    result = run('--out', str(bag))
    assert result.returncode == 1 and 'exists' in result.stderr
    result = run()
    assert result.returncode == 1 and '--publish' in result.stderr


def test_crank_states_of_rclpy_messages_are_read_in_bulk(monkeypatch):
    """rclpy's CDR leaves alignment padding unzeroed: the bulk reader must not need it."""
    rng = np.random.default_rng(2)
    payloads = []
    for n in range(500):
        message = joint_state(10**9 + n * 10**6, ['crank', 'other'],
                              rng.normal(size=2), rng.normal(size=2))
        payloads.append(bytes(serialize_message(message)))
    odd = {100: joint_state(5, ['other', 'crank'], [1.0, 2.0], [3.0, 4.0]),
           200: joint_state(6, ['crank'], [1.5]),                      # no velocity
           300: joint_state(7, ['crank', 'other'], [math.nan, 0.0], [0.0, 0.0])}
    odd[300].header.frame_id = 'x'                                      # another length
    # Serialisers need not zero alignment padding (rclpy's Fast DDS does not, depending on
    # the memory it reuses): fill the padding of every message with other bytes.
    fixed, position, velocity = cli_replay._joint_state_layout(payloads[0], b'crank')
    meaningful = np.zeros(len(payloads[0]), dtype=bool)
    for first, stop in fixed + [(4, 12), (position, position + 16), (velocity, velocity + 16)]:
        meaningful[first:stop] = True
    padding = np.flatnonzero(~meaningful)
    assert padding.size >= 6        # after the frame id and the names, and at the end
    for n in range(len(payloads)):
        data = np.frombuffer(payloads[n], dtype=np.uint8).copy()
        data[padding] = rng.integers(1, 256, size=padding.size)
        payloads[n] = data.tobytes()
    for n, message in odd.items():
        payloads[n] = bytes(serialize_message(message))
    calls = []
    original = cli_replay.parse_joint_state

    def counted(data, name):
        calls.append(data)
        return original(data, name)
    monkeypatch.setattr(cli_replay, 'parse_joint_state', counted)
    stamps, angles, speeds, valid, has_speed = cli_replay._parse_crank_states(payloads, b'crank')
    assert len(calls) <= len(odd)           # only the odd ones one by one
    for n, payload in enumerate(payloads):
        stamp, angle, speed = original(payload, b'crank')
        assert stamps[n] == stamp
        assert (angles[n] == angle) or (math.isnan(angles[n]) and math.isnan(angle))
        assert has_speed[n] == (speed is not None)
        if speed is not None:
            assert speeds[n] == speed


def test_estimate_reports_only_final_samples_to_the_writer(model, monkeypatch):
    """progress(n) comes only once the first n samples are final, through gaps and repeats."""
    from flexlink_ros.core.estimation import streaming as core_estimator
    monkeypatch.setattr(core_estimator, 'REPLAY_CHUNK', 64)     # many chunks per segment
    stamps = np.arange(700) * 1_000_000
    stamps[400:] += 800_000_000                                 # a gap: two segments
    stamps[200] = stamps[199]                                   # a repeated sample
    angles = 391 * RPM * stamps * 1e-9
    angles[200] = angles[199]
    speeds = np.full(stamps.size, 391 * RPM)
    speeds[300:310] = np.nan                                    # no speed in a stretch
    snapshots = []
    result = cli_replay.allocate_estimate(model, stamps.size)

    def progress(count):
        snapshots.append((count, {key: result[key][:count].copy()
                                  for key in ('lever_tip', 'criterion', 'modal')}))
    cli_replay.estimate_offline(model, stamps, angles, speeds, result=result, progress=progress)
    counts = [count for count, _ in snapshots]
    assert counts == sorted(counts) and counts[-1] == stamps.size and len(counts) > 10
    for count, early in snapshots:
        for key, values in early.items():
            np.testing.assert_array_equal(values, result[key][:count])
    assert result['segments'] == 2
    np.testing.assert_array_equal(result['lever_tip'][200], result['lever_tip'][199])


def test_replay_writer_gets_the_estimate_error():
    def failing(result, progress):
        progress(10)
        raise ValueError('estimate failed')
    background = cli_replay._Background(failing, {})
    with pytest.raises(ValueError, match='estimate failed'):
        background.wait_for(11)
    with pytest.raises(ValueError, match='estimate failed'):
        background.join()


def test_segments_share_one_set_of_step_tables(model, monkeypatch):
    """A recording with many gaps builds the step tables once, not per segment."""
    from flexlink_ros.core.estimation import streaming as core_estimator
    built = []
    original = core_estimator._StepTables.__init__

    def counted(self, *args, **kwargs):
        built.append(1)
        original(self, *args, **kwargs)
    monkeypatch.setattr(core_estimator._StepTables, '__init__', counted)
    stamps = np.arange(60) * 1_000_000 + np.repeat(np.arange(6), 10) * 700_000_000
    angles = 391 * RPM * stamps * 1e-9
    speeds = np.full(stamps.size, 391 * RPM)
    result = cli_replay.estimate_offline(model, stamps, angles, speeds)
    assert result['segments'] == 6 and len(built) == 1
    with pytest.raises(ValueError, match='do not match the model'):
        small = reduced.model_for_mechanism(load_mechanism('cho1992'), reduced.ModelOptions(
            rigid_crank=True, bearings='rigid', geometric_stiffness=False))
        StreamingEstimator(model, step_tables=core_estimator.step_tables(small))


def deflections_by_stamp(path):
    """{stamp: (lever_tip x, y, coupler_mid x, y)} of a replay's output MCAP."""
    from geometry_msgs.msg import Vector3Stamped
    found = {}
    for topic, _, _, _, data in cli_replay.iter_recording(path):
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
                                 '--markers-every-n', '0'],
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


@pytest.mark.parametrize('window', [cli_replay.PLAN_WINDOW, 7])
def test_offline_estimate_equals_streaming_through_outliers_and_out_of_bound(
        model, monkeypatch, window):
    """Outliers, a jump and out-of-bound resets: replay's rows are the node's samples."""
    monkeypatch.setattr(cli_replay, 'PLAN_WINDOW', window)     # planned in windows or not
    from flexlink_ros.core.estimation import streaming as core_estimator
    from flexlink_ros.errors import OutlierSample
    from flexlink_ros.core.estimation.streaming import SampleFlag
    stamps = 10**9 + np.arange(1500, dtype=np.int64) * 1_000_000
    speed = np.full(stamps.size, 391.0 * RPM)
    speed[1000:] = -100.0            # a jump: outliers until it is plausible over their dt
    angles = np.cumsum(speed) * 1e-3
    speed[[200, 201, 600]] = (1.7e308, -1.7e308, 1e6)
    stamps[800], angles[800] = stamps[799], angles[799]       # an exact repeat
    reference = StreamingEstimator(model)
    normal = max(max(map(abs, reference.update(int(s), a, w).lever_tip))
                 for s, a, w in zip(stamps[:400].tolist(), angles[:400], speed[:400])
                 if abs(w) < 1e3)
    # A bound below the normal peak: the peaks go out of bound and restart the estimate.
    monkeypatch.setattr(core_estimator, 'DEFLECTION_SAFETY_FACTOR',
                        core_estimator.DEFLECTION_SAFETY_FACTOR * 0.9 * normal
                        / reference.deflection_bound_m)
    estimator = StreamingEstimator(model)
    streamed = []
    for stamp, angle, value in zip(stamps.tolist(), angles.tolist(), speed.tolist()):
        try:
            streamed.append(estimator.update(stamp, angle, value))
        except OutlierSample:
            streamed.append(None)
    result = cli_replay.estimate_offline(model, stamps, angles, speed)
    flags = result['flags']
    refused = [n for n, s in enumerate(streamed) if s is None]
    assert refused == np.flatnonzero(flags & SampleFlag.OUTLIER).tolist()
    assert refused[:4] == [200, 201, 600, 1000]
    out = [n for n, s in enumerate(streamed)
           if s is not None and s.flags & SampleFlag.OUT_OF_BOUND]
    assert len(out) > 5 and out == np.flatnonzero(flags & SampleFlag.OUT_OF_BOUND).tolist()
    assert result['outliers'] == len(refused) and result['out_of_bound'] == len(out)
    for n, sample in enumerate(streamed):
        if sample is None or sample.flags & SampleFlag.OUT_OF_BOUND:
            assert np.all(np.isnan(result['lever_tip'][n]))
            continue
        assert bool(flags[n] & SampleFlag.REPEATED) == bool(sample.flags & SampleFlag.REPEATED)
        if not sample.flags & SampleFlag.REPEATED:
            assert bool(flags[n] & SampleFlag.RESET) == bool(sample.flags & SampleFlag.RESET)
        np.testing.assert_allclose(result['lever_tip'][n], sample.lever_tip, rtol=1e-7,
                                   atol=1e-12)
        np.testing.assert_allclose(result['coupler_mid'][n], sample.coupler_mid, rtol=1e-7,
                                   atol=1e-12)


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
