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
import time

from flexlink_ros.names import FIRST_INPUT_MESSAGE, QUALITY_NAMES, READY_MESSAGE
import pytest
import test_node
from test_node import (DISCOVERY_TIMEOUT_S, NodeProcess, read_with_mcap_ros2, read_with_rosbags,
                       READY_TIMEOUT_S, spin_until)
import yaml

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


def test_split_settings_below_the_floor_stop_the_node_at_start_up(tmp_path, processes):
    """record.max_bytes:=1 once lost the recording and hung the node: now refused, nothing made."""
    bag = tmp_path / 'tiny'
    node_process = NodeProcess(tmp_path, 'record.enabled:=true', f'record.path:={bag}',
                               'record.max_bytes:=1', 'record.max_duration_s:=0.001')
    processes.append(node_process)
    assert node_process.process.wait(timeout=READY_TIMEOUT_S) == 1
    log = node_process.log()
    assert 'record.max_bytes must be 0 (no split) or at least 1048576 (1 MiB), got 1' in log
    assert 'record.max_duration_s must be 0 (no split) or at least 1 s, got 0.001' in log
    assert READY_MESSAGE not in log and not bag.exists()


def _publish_crank(publisher, executor, count, rate_hz=1000.0):
    """Publish ``count`` JointState messages of a crank at 391 rpm, paced at ``rate_hz``."""
    from test_node import joint_state
    speed = 391.0 * 2.0 * math.pi / 60.0
    start = time.monotonic()
    for n in range(count):
        t = n / rate_hz
        angle = math.remainder(speed * t, 2.0 * math.pi)
        publisher.publish(joint_state(1_800_000_000 * 10**9 + round(t * 1e9), ['crank'],
                                      [angle], [speed]))
        delay = start + (n + 1) / rate_hz - time.monotonic()
        if delay > 0:
            time.sleep(delay)
        if n % 100 == 0:
            executor.spin_once(timeout_sec=0.0)


def _settled_count(executor, reports, key='received', unchanged_reports=10):
    """
    Spin until the node's input count on /diagnostics is the same in ``unchanged_reports``.

    Counted in the node's own reports, not in seconds: a node stalled on a loaded machine
    publishes no report, so a backlog it has yet to take cannot pass for a settled count.
    """
    def counts():
        return [int(kv.value) for report in reports for status in report.status
                if status.name.endswith('input') for kv in status.values if kv.key == key]

    deadline = time.monotonic() + 3 * DISCOVERY_TIMEOUT_S
    while True:
        seen = counts()
        if len(seen) >= unchanged_reports and len(set(seen[-unchanged_reports:])) == 1:
            return seen[-1]
        assert time.monotonic() < deadline, f'the input count did not settle: {seen[-20:]}'
        executor.spin_once(timeout_sec=0.05)


def _log_time_spans_s(files):
    """Seconds between the first and last message log time of each MCAP file of ``files``."""
    from mcap.reader import make_reader
    spans = []
    for path in files:
        with open(path, 'rb') as stream:
            times = [message.log_time for _, _, message in make_reader(stream).iter_messages()]
        spans.append((max(times) - min(times)) * 1e-9 if times else 0.0)
    return spans


@pytest.mark.parametrize('sig', [signal.SIGINT, signal.SIGTERM], ids=['SIGINT', 'SIGTERM'])
def test_a_signal_ends_a_split_recording_at_the_floor_within_five_seconds_complete(
        tmp_path, processes, ros, sig):
    """Splits at the smallest accepted settings, 1 kHz input: closed bag, every input kept."""
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import JointState
    test_node, executor = ros
    bag = tmp_path / 'floor'
    node_process = NodeProcess(tmp_path, 'record.enabled:=true', f'record.path:={bag}',
                               'record.max_bytes:=1048576', 'record.max_duration_s:=1.0',
                               'diagnostics.period_s:=0.2')
    processes.append(node_process)
    node_process.wait_for(READY_MESSAGE, READY_TIMEOUT_S)
    from diagnostic_msgs.msg import DiagnosticArray
    reports = []
    test_node.create_subscription(DiagnosticArray, '/diagnostics', reports.append, 10)
    publisher = test_node.create_publisher(
        JointState, INPUT, QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE))
    spin_until(executor, lambda: publisher.get_subscription_count() > 0, DISCOVERY_TIMEOUT_S,
               'the node subscribing')
    if sig == signal.SIGINT:     # nor can a running node be set below the floor
        from rclpy.parameter import Parameter
        from rclpy.parameter_client import AsyncParameterClient
        client = AsyncParameterClient(test_node, 'flexlink_node')
        spin_until(executor, client.services_are_ready, DISCOVERY_TIMEOUT_S, 'parameters')
        future = client.set_parameters([Parameter('record.max_bytes', value=1),
                                        Parameter('record.max_duration_s', value=0.001)])
        spin_until(executor, future.done, 10.0, 'set_parameters')
        assert [r.successful for r in future.result().results] == [False, False]
    sent = 4000
    _publish_crank(publisher, executor, sent)
    node_process.wait_for(FIRST_INPUT_MESSAGE, DISCOVERY_TIMEOUT_S)
    # what reached the node: a loaded machine loses inputs between the processes (a quarter
    # reached it at a load of 21 on 2 cores); what reached it must all be on disk
    received = _settled_count(executor, reports)
    assert received >= sent // 10, received
    start = time.monotonic()
    node_process.process.send_signal(sig)
    code = node_process.process.wait(timeout=60)
    ended_s = time.monotonic() - start
    node_process.log_file.close()
    assert code == 0 and ended_s < 5.0, (ended_s, node_process.log())

    files = sorted(bag.glob('*.mcap'))
    # split every second of log time (4 s of input and the diagnostics until the signal):
    # several files, none spanning more than a second however the load spread the messages
    spans = _log_time_spans_s(files)
    assert len(files) >= 2 and max(spans) <= 1.0, spans
    metadata = yaml.safe_load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    assert metadata['relative_file_paths'] == [f'floor_{n}.mcap' for n in range(len(files))]
    counts, _ = read_with_rosbags(bag)
    assert counts[INPUT] == received        # every input the node received is on disk
    assert sum(counts.values()) == metadata['message_count']
    assert read_with_mcap_ros2(bag) == counts


def test_a_refused_record_path_is_said_in_the_ready_line_and_leaves_nothing(tmp_path, processes):
    """A 250-character record.path: refused, the ready line says so, no directory left."""
    bag = tmp_path / ('x' * 250)
    node_process = NodeProcess(tmp_path, 'record.enabled:=true', f'record.path:={bag}')
    processes.append(node_process)
    node_process.wait_for(READY_MESSAGE, READY_TIMEOUT_S)
    assert node_process.stop(signal.SIGTERM) == 0
    ready = [line for line in node_process.log().splitlines() if READY_MESSAGE in line]
    assert len(ready) == 1 and 'recording to' not in ready[0], ready
    assert 'not recording (cannot record to' in ready[0] and 'File name too long' in ready[0]
    assert not bag.exists() and sorted(p.name for p in tmp_path.iterdir()
                                       if not p.name.endswith('.log')) == []
