"""``flexlink replay --nonlinear`` (cli/replay_nonlinear.py): a real bag, a 2-element model."""

import json
import math
import subprocess
import sys

from flexlink_ros.cli.replay_nonlinear import increasing
from flexlink_ros.core.estimation.nonlinear_stream import estimate_nonlinear
from flexlink_ros.core.reduction.nonlinear_model import nonlinear_model_for
from flexlink_ros.io.provenance import read_provenance
from flexlink_ros.io.recorder import McapRecorder
from flexlink_ros.ros import messages as ros_messages
from mcap.reader import make_reader
import numpy as np
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import JointState

SMALL_MODEL = ['--mechanism', 'cho1992', '--elements-per-link', '2', '--rigid-crank',
               '--bearings', 'flexible', '--stiffness-damping', '1e-4']


def write_bag(path, rpm, seconds=1.5, rate_hz=1000.0):
    """Write a bag of crank JointStates at ``rpm`` (stamps jittered by up to 20 %)."""
    rng = np.random.default_rng(5)
    steps = (1.0 + 0.2 * rng.uniform(-1, 1, int(seconds * rate_hz))) / rate_hz
    times = np.concatenate([[0.0], np.cumsum(steps)])
    stamps = (1_700_000_000_000_000_000 + np.round(times * 1e9)).astype(np.int64)
    speed = rpm * math.pi / 30.0
    with McapRecorder(path) as recorder:
        recorder.add_topic('/joint_states', JointState)
        for stamp, angle in zip(stamps.tolist(), np.mod(speed * times, 2 * math.pi)):
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


def test_replay_nonlinear_on_equals_the_nonlinear_estimate_of_the_same_samples(tmp_path):
    bag, out = tmp_path / 'bag', tmp_path / 'out'
    write_bag(bag, 391.0)
    result = replay(str(bag), '--out', str(out), '--nonlinear', 'on', *SMALL_MODEL,
                    '--cache-dir', str(tmp_path / 'cache'))
    assert result['model_choice'] == {'nonlinear': True, 'why': 'asked for (--nonlinear on)'}
    recorded = read_provenance(out)
    tables, _ = nonlinear_model_for(recorded.mechanism(), recorded.options(), use_cache=False)
    stamps, angles, speeds = read_samples(bag)
    expected = estimate_nonlinear(tables, stamps, angles, speeds)['outputs']
    assert np.isfinite(expected).all()
    span = 1e6 * (expected.max(axis=0) - expected.min(axis=0))
    nonlinear = result['nonlinear']
    assert nonlinear['refused_samples'] == 0 and nonlinear['samples'] == stamps.size
    np.testing.assert_allclose(nonlinear['lever_tip_peak_to_peak_um'], span[0:2], rtol=1e-9)
    np.testing.assert_allclose(nonlinear['coupler_mid_peak_to_peak_um'], span[2:4], rtol=1e-9)
    # the nonlinear estimate is not the linear one at this speed
    assert not np.allclose(nonlinear['coupler_mid_peak_to_peak_um'],
                           result['coupler_mid_peak_to_peak_um'], rtol=1e-3)


def test_replay_auto_picks_the_linear_model_at_low_speed(tmp_path):
    bag = tmp_path / 'bag'
    write_bag(bag, 30.0, seconds=2.5)
    result = replay(str(bag), '--chart', str(tmp_path / 'c.png'), *SMALL_MODEL,
                    '--cache-dir', str(tmp_path / 'cache'))
    assert result['model_choice']['nonlinear'] is False, result['model_choice']
    assert result['model_choice']['why'].startswith('auto: the linear estimate is valid')
    assert result['nonlinear'] is None


def test_only_increasing_stamps_are_stepped():
    assert increasing([1, 2, 2, 5, 3, 6]).tolist() == [True, True, False, True, False, True]
    assert increasing([]).tolist() == []
