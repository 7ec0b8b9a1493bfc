"""Simulated time without /clock: the warning, /diagnostics and log times (ros/sim_time.py)."""

import signal
import time

from flexlink_ros.names import READY_MESSAGE
from flexlink_ros.ros.sim_time import (cdr_stamp_ns, CLOCK_STARTED, ClockWatch, LogTime,
                                       NO_CLOCK_WARNING)
import test_node
from test_node import DISCOVERY_TIMEOUT_S, joint_state, NodeProcess, READY_TIMEOUT_S, spin_until

ros = test_node.ros


def test_log_time_is_the_clock_else_the_stamp_else_extrapolated():
    log_time = LogTime()
    before = time.time_ns()
    assert log_time(0) >= before                  # no clock, no input yet: the system clock
    assert log_time(123, 456) == 123              # a running clock wins
    assert log_time(0, 5_000_000_000) == 5_000_000_000
    later = log_time(0)                           # no stamp: the last one plus steady time
    assert 5_000_000_000 <= later < 5_000_000_000 + (time.time_ns() - before)
    assert log_time(0, 4_000_000_000) == 4_000_000_000


def test_cdr_stamp_of_a_serialised_message():
    from rclpy.serialization import serialize_message
    data = serialize_message(joint_state(1_700_000_000_123_456_789, ['crank'], [0.1], [1.0]))
    assert cdr_stamp_ns(data) == 1_700_000_000_123_456_789
    assert cdr_stamp_ns(b'\x00\x01\x00\x00') == 0           # too short
    assert cdr_stamp_ns(b'\x00\x00\x00\x00' + bytes(8)) == 0  # big endian: not read


def test_clock_watch_warns_after_the_grace_then_periodically_and_says_when_the_clock_comes():
    said = []
    watch = ClockWatch(lambda text: said.append(('warn', text)),
                       lambda text: said.append(('info', text)), period_s=0.05, grace_s=0.02)
    watch.check(False, 0)            # wall time: nothing to say
    watch.check(True, 0)             # within the grace
    assert said == []
    time.sleep(0.03)
    watch.check(True, 0)
    watch.check(True, 0)             # within the period: once
    assert said == [('warn', NO_CLOCK_WARNING)]
    time.sleep(0.06)
    watch.check(True, 0)
    assert watch.warnings == 2
    watch.check(True, 1)
    assert said[-1] == ('info', CLOCK_STARTED)


def test_node_on_sim_time_without_clock_warns_publishes_diagnostics_and_records_stamps(
        tmp_path, processes, ros):
    """A real node with use_sim_time and no /clock: warned, /diagnostics, no zero log times."""
    from diagnostic_msgs.msg import DiagnosticArray
    from geometry_msgs.msg import Vector3Stamped
    from mcap.reader import make_reader
    from sensor_msgs.msg import JointState

    bag = tmp_path / 'run.mcap'
    node_process = NodeProcess(tmp_path, 'use_sim_time:=true', 'record.enabled:=true',
                               f'record.path:={bag}', 'diagnostics.period_s:=0.2')
    processes.append(node_process)
    node_process.wait_for(READY_MESSAGE, READY_TIMEOUT_S)
    test_node, executor = ros
    publisher = test_node.create_publisher(JointState, 'joint_states', 100)
    diagnostics, outputs = [], []
    test_node.create_subscription(DiagnosticArray, '/diagnostics', diagnostics.append, 10)
    test_node.create_subscription(Vector3Stamped, '/flexlink_node/lever_tip/deflection',
                                  outputs.append, 100)
    spin_until(executor, lambda: publisher.get_subscription_count() > 0 and diagnostics,
               DISCOVERY_TIMEOUT_S, '/diagnostics on simulated time without /clock')
    stamps = [1_000_000_000 * 50 + n * 1_000_000 for n in range(20)]   # 50 s of sim time
    for n, stamp in enumerate(stamps):
        publisher.publish(joint_state(stamp, ['crank'], [0.01 * n], [10.0]))
        time.sleep(0.002)
    spin_until(executor, lambda: len(outputs) >= len(stamps), 20.0, 'the estimates')
    node_process.wait_for('no /clock has been received', 20.0)
    assert all(message.header.stamp.sec > 0 for message in diagnostics)
    assert node_process.stop(signal.SIGTERM) == 0
    assert node_process.log().count('no /clock has been received') == 1   # not per tick

    log_times = {}
    with open(bag, 'rb') as stream:
        for _, channel, message in make_reader(stream).iter_messages():
            log_times.setdefault(channel.topic, []).append(message.log_time)
    assert log_times['/joint_states'] == stamps       # log time = the input's stamp
    assert log_times['/flexlink_node/lever_tip/deflection'] == stamps
    assert min(log_times['/diagnostics']) > 0
