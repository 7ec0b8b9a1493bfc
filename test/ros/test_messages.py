"""Message translation: input extraction rejects bad messages, outputs carry the stamp."""

import math

from flexlink_ros.io import output_cdr
from flexlink_ros.ros import messages as rm
import numpy as np
import output_messages
import pytest
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import JointState
from visualization_msgs.msg import MarkerArray


def _state(names, position, velocity=(), sec=3, nanosec=5):
    msg = JointState(name=list(names), position=list(position), velocity=list(velocity))
    msg.header.stamp.sec, msg.header.stamp.nanosec = sec, nanosec
    return msg


def test_crank_is_picked_by_name_with_velocity():
    stamp, angle, speed = rm.crank_from_joint_state(
        _state(['other', 'crank'], [9.0, 1.25], [7.0, 40.0]), 'crank')
    assert (stamp, angle, speed) == (3_000_000_005, 1.25, 40.0)


def test_missing_velocity_gives_none():
    assert rm.crank_from_joint_state(_state(['crank'], [0.5]), 'crank')[2] is None


@pytest.mark.parametrize('msg, fragment', [
    (_state([], []), 'empty'),
    (_state(['wheel'], [1.0]), 'not in JointState'),
    (_state(['a', 'crank'], [1.0]), 'no position'),
    (_state(['crank'], [math.nan]), 'non-finite position'),
    (_state(['crank'], [1.0], [math.inf]), 'non-finite velocity'),
])
def test_bad_messages_are_rejected_with_reason(msg, fragment):
    with pytest.raises(rm.InputRejected, match=fragment):
        rm.crank_from_joint_state(msg, 'crank')


def test_stamp_round_trip():
    for ns in (0, 1, 999_999_999, 1_700_000_000_123_456_789):
        assert rm.stamp_to_ns(rm.ns_to_stamp(ns)) == ns


def test_criteria_message_round_trips_through_cdr():
    stamp = rm.ns_to_stamp(12_345)
    msg = output_messages.criteria_message(stamp, 'g', [1.0, 2.0, 3.0, 4.0],
                                           [0.1, 0.2, 0.3, 0.4], [10.0, 20.0, 30.0, 40.0])
    back = deserialize_message(serialize_message(msg), JointState)
    assert list(back.name) == ['O2', 'A', 'B', 'O4']
    assert list(back.position) == [1.0, 2.0, 3.0, 4.0]
    assert list(back.effort) == [10.0, 20.0, 30.0, 40.0]
    assert rm.stamp_to_ns(back.header.stamp) == 12_345


def test_markers_exaggerate_deflection_and_colour_joints():
    points = [np.array([[0.0, 0.0], [0.1, 0.0]])] * 3
    deflection = [np.array([[0.0, 0.0], [0.0, 1e-4]])] * 3
    joints = np.array([[0, 0], [0.1, 0], [0.2, 0.1], [0.24, 0]])
    msg = output_cdr.linkage_markers(rm.ns_to_stamp(1), 'g', points, deflection, 100.0, joints,
                                     [rm.OK, rm.WARN, rm.ERROR, rm.OK])
    back = deserialize_message(serialize_message(msg), MarkerArray)
    deformed = [m for m in back.markers if m.ns.endswith('deformed')]
    assert len(deformed) == 3 and deformed[0].points[1].y == pytest.approx(0.01)
    spheres = [m for m in back.markers if m.ns.endswith('joints')]
    assert [round(m.color.r, 2) for m in spheres] == [0.2, 1.0, 0.9, 0.2]


def test_joint_levels():
    assert rm.joint_level(1.0, False, 10.0, 100.0) == rm.OK
    assert rm.joint_level(50.0, False, 10.0, 100.0) == rm.WARN
    assert rm.joint_level(500.0, False, 10.0, 100.0) == rm.ERROR
    assert rm.joint_level(1.0, True, 10.0, 100.0) == rm.ERROR
    assert rm.joint_level(math.nan, False, 10.0, 100.0) == rm.ERROR
