"""
The node's recording with a real crank_driver: offered QoS from the graph, ~/quality recorded.

crank_driver offers reliable, keep-last-10; the node subscribes best effort, depth 1000.
rosbag2 stores the publishers' offered QoS of every recorded topic, so the input channel must
say reliable (not the node's best effort), the outputs the node's own publishers' QoS.
"""

import math
import os
import signal
import subprocess
import sys

from flexlink_ros.names import FIRST_INPUT_MESSAGE, QUALITY_NAMES, READY_MESSAGE
import pytest
import test_node
from test_node import DISCOVERY_TIMEOUT_S, NodeProcess, READY_TIMEOUT_S, spin_until
import yaml

processes = test_node.processes   # fixtures of test_node, used here by name
ros = test_node.ros
INPUT = '/joint_states'
QUALITY = '/flexlink_node/quality'
LEVER = '/flexlink_node/lever_tip/deflection'


def _channel_qos(bag_file):
    """Return topic -> (channel id, its offered_qos_profiles parsed) (mcap reader)."""
    from mcap.reader import make_reader
    with open(bag_file, 'rb') as stream:
        summary = make_reader(stream).get_summary()
    return {channel.topic: (channel.id, yaml.safe_load(channel.metadata['offered_qos_profiles']))
            for channel in summary.channels.values()}


def _stamps_and_quality(bag_file):
    """Return topic -> header stamps [ns], and the quality messages (rosbags reader)."""
    from rosbags.highlevel import AnyReader
    stamps, quality = {}, []
    with AnyReader([bag_file.parent]) as reader:
        for connection, _, raw in reader.messages():
            message = reader.deserialize(raw, connection.msgtype)
            if hasattr(message, 'header') and connection.topic != '/diagnostics':
                stamp = message.header.stamp.sec * 10**9 + message.header.stamp.nanosec
                stamps.setdefault(connection.topic, []).append(stamp)
            if connection.topic == QUALITY:
                quality.append(message)
    return stamps, quality


def _start_driver(processes):
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path))
    driver = subprocess.Popen([sys.executable, '-m', 'flexlink_ros.ros.crank_driver',
                               '--ros-args', '-p', 'speed_rpm:=120.0'], env=env,
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    processes.append(driver)
    return driver


@pytest.mark.parametrize('driver_first', [False, True], ids=['node_first', 'driver_first'])
def test_driver_qos_is_recorded_as_offered_and_every_estimate_has_its_quality(
        tmp_path, processes, ros, driver_first):
    """
    Record the driver's offered QoS whichever process starts first.

    Node first: the input is declared at its first message (its channel comes after the
    outputs'); driver first: at the open, once discovery has found the driver by then.
    """
    from rclpy.qos import qos_profile_sensor_data
    from sensor_msgs.msg import JointState
    test_node, executor = ros
    driver = None
    if driver_first:
        driver = _start_driver(processes)
        spin_until(executor, lambda: test_node.count_publishers(INPUT) > 0,
                   DISCOVERY_TIMEOUT_S, 'the driver')
    bag = tmp_path / 'bag'
    node_process = NodeProcess(tmp_path, 'record.enabled:=true', f'record.path:={bag}',
                               'qos.reliability:=best_effort')
    processes.append(node_process)
    node_process.wait_for(READY_MESSAGE, READY_TIMEOUT_S)
    received = []
    test_node.create_subscription(JointState, QUALITY, received.append, qos_profile_sensor_data)
    driver = driver or _start_driver(processes)
    node_process.wait_for(FIRST_INPUT_MESSAGE, DISCOVERY_TIMEOUT_S)
    spin_until(executor, lambda: len(received) >= 200, DISCOVERY_TIMEOUT_S, '~/quality')
    driver.send_signal(signal.SIGINT)
    driver.wait(timeout=20)
    assert node_process.stop(signal.SIGTERM) == 0

    message = received[-1]
    assert list(message.name) == list(QUALITY_NAMES)
    assert message.header.frame_id == 'linkage_ground'
    assert 0.0 <= message.position[0] < 1.0          # error indicator of a converged basis
    assert len(message.position) == 2                 # nonlinearity: NaN until computed

    (bag_file,) = sorted(bag.glob('*.mcap'))
    qos = _channel_qos(bag_file)
    input_channel, (offered,) = qos[INPUT]            # one publisher: the driver
    assert offered['reliability'] == 'reliable'       # the driver's, not the node's
    assert offered['durability'] == 'volatile'
    lever_channel, (own,) = qos[LEVER]
    if not driver_first:
        assert input_channel > lever_channel          # declared at the first message
    assert (own['reliability'], own['depth']) == ('best_effort', 1000)
    metadata = yaml.safe_load((bag / 'metadata.yaml').read_text())
    topics = {entry['topic_metadata']['name']: entry['topic_metadata']
              for entry in metadata['rosbag2_bagfile_information']['topics_with_message_count']}
    assert topics[INPUT]['offered_qos_profiles'][0]['reliability'] == 'reliable'

    # One quality message per estimate, stamped with the input stamps (rosbags).
    stamps, quality = _stamps_and_quality(bag_file)
    assert len(stamps[INPUT]) > 200
    assert stamps[QUALITY] == stamps[LEVER] == stamps[INPUT]
    assert all(list(m.name) == list(QUALITY_NAMES) for m in quality)
    assert all(math.isfinite(m.position[0]) and m.position[0] >= 0.0 for m in quality)
