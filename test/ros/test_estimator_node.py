"""The node's per-sample outputs as another process receives them and as the node records them."""

import math
import signal

from flexlink_ros.io import cdr
from flexlink_ros.names import READY_MESSAGE, TOPICS
from flexlink_ros.ros.estimator_node import linear_resampling, OUTPUT_TYPES, PER_SAMPLE_OUTPUTS
import numpy as np
import pytest
from test_node import (DISCOVERY_TIMEOUT_S, joint_state, node_model, NodeProcess,  # noqa: F401
                       READY_TIMEOUT_S, ros, spin_until)

FRAME = 'linkage_ground'


def recorded_messages(bag):
    """Topic -> list of message bytes in the recording, read by the mcap package's reader."""
    from mcap.reader import make_reader
    found = {}
    for path in sorted(bag.glob('*.mcap')):
        with open(path, 'rb') as stream:
            for _, channel, message in make_reader(stream).iter_messages(log_time_order=False):
                found.setdefault(channel.topic, []).append(bytes(message.data))
    return found


def test_published_outputs_are_the_estimate_and_the_recorded_bytes(
        tmp_path, processes, ros):  # noqa: F811 (test_node's fixtures)
    """Raw bytes received in this process: rclpy's CDR of the estimate, and what was recorded."""
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from rclpy.serialization import deserialize_message, serialize_message
    from sensor_msgs.msg import JointState

    bag = tmp_path / 'bag'
    node_process = NodeProcess(tmp_path, 'record.enabled:=true', f'record.path:={bag}',
                               'model.nonlinear:=off')     # the linear estimate's numbers
    processes.append(node_process)
    model = node_model()
    node_process.wait_for(READY_MESSAGE, READY_TIMEOUT_S)
    test_node, executor = ros
    qos = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
    publisher = test_node.create_publisher(JointState, 'joint_states', qos)
    received = {key: [] for key in PER_SAMPLE_OUTPUTS}
    topics = {key: '/flexlink_node/' + TOPICS[key].lstrip('~/') for key in PER_SAMPLE_OUTPUTS}
    for key in PER_SAMPLE_OUTPUTS:
        test_node.create_subscription(OUTPUT_TYPES[key], topics[key], received[key].append,
                                      qos, raw=True)
    spin_until(executor, lambda: publisher.get_subscription_count() > 0 and all(
        test_node.count_publishers(topics[key]) > 0 for key in PER_SAMPLE_OUTPUTS),
        DISCOVERY_TIMEOUT_S, 'discovery')

    speed = 391.0 * 2.0 * math.pi / 60.0
    stamps = [1_800_000_000 * 10**9 + k * 1_000_000 for k in range(200)]
    angles = [math.remainder(speed * k * 1e-3, 2.0 * math.pi) for k in range(200)]
    for n, (stamp, angle) in enumerate(zip(stamps, angles)):
        publisher.publish(joint_state(stamp, ['crank'], [angle], [speed]))
        spin_until(executor, lambda: len(received['quality']) > n, 20.0, f'output {n}',
                   lambda: '\n' + node_process.log())
    spin_until(executor, lambda: all(len(v) == len(stamps) for v in received.values()), 10.0,
               'every output')
    assert node_process.stop(signal.SIGINT) == 0

    from flexlink_ros.core.estimation.streaming import StreamingEstimator
    estimator = StreamingEstimator(model)
    reference = [estimator.update(s, a, speed) for s, a in zip(stamps, angles)]
    for key in PER_SAMPLE_OUTPUTS:
        messages = [deserialize_message(data, OUTPUT_TYPES[key]) for data in received[key]]
        # The bytes are the CDR of the message they carry, with zero padding: rclpy's own
        # serialiser leaves stray bytes in the padding, the only bytes allowed to differ.
        assert [cdr.serialize_message(m) for m in messages] == received[key], key
        assert [deserialize_message(serialize_message(m), OUTPUT_TYPES[key])
                for m in messages] == messages, key
        for message, stamp in zip(messages, stamps):
            assert (message.header.frame_id, message.header.stamp.sec,
                    message.header.stamp.nanosec) == (FRAME, *divmod(stamp, 10**9))
        received[key] = messages
    # Field by field, exactly the estimator's numbers.
    for key in ('lever_tip', 'coupler_mid'):
        assert [(m.vector.x, m.vector.y, m.vector.z) for m in received[key]] == [
            (*getattr(s, key), 0.0) for s in reference], key
    assert [list(m.name) for m in received['criteria']] == [['O2', 'A', 'B', 'O4']] * 200
    assert [(tuple(m.position), tuple(m.velocity), tuple(m.effort))
            for m in received['criteria']] == [
        (tuple(s.criterion), tuple(s.gamma_dot), tuple(s.reaction_n)) for s in reference]
    got = np.array([m.position for m in received['quality']])
    expected = np.array([(s.error_indicator, s.nonlinearity) for s in reference])
    assert np.array_equal(got, expected, equal_nan=True)

    # The recording holds the very bytes published, in order.
    recorded = recorded_messages(bag)
    for key in PER_SAMPLE_OUTPUTS:
        assert recorded[topics[key]] == [cdr.serialize_message(m) for m in received[key]], key
    assert len(recorded['/joint_states']) == len(stamps)


@pytest.mark.parametrize('points, count', [(13, 9), (5, 12), (2, 2)])
def test_linear_resampling_is_np_interp_of_each_coordinate(points, count):
    values = np.random.default_rng(points).normal(size=(3, points, 2))
    resampled = linear_resampling(points, count) @ values
    target, source = np.linspace(0.0, 1.0, count), np.linspace(0.0, 1.0, points)
    for link in range(3):
        for axis in range(2):
            np.testing.assert_allclose(
                resampled[link, :, axis], np.interp(target, source, values[link, :, axis]),
                rtol=1e-13, atol=1e-15)


def test_a_publish_after_shutdown_is_said_and_not_raised():
    """Markers still waiting at SIGTERM are delivered after rclpy shut the context down."""
    import types

    import rclpy
    from rclpy.context import Context
    from std_msgs.msg import String

    from flexlink_ros.ros.estimator_node import EstimatorNode

    context = Context()
    rclpy.init(context=context)
    node = rclpy.create_node('flexlink_shutdown_publish', context=context)
    try:
        publisher = node.create_publisher(String, 'flexlink_shutdown_markers', 10)
        owner = types.SimpleNamespace(publishers_={'markers': publisher}, context=context)
        data = cdr.serialize_message(String(data='m'))
        assert EstimatorNode._publish(owner, [('markers', data)])
        context.try_shutdown()
        assert EstimatorNode._publish(owner, [('markers', data)]) is False
    finally:
        node.destroy_node()
        context.try_shutdown()
