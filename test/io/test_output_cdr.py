"""output_cdr: the node's outputs, one message or many rows, against rclpy's serialisation."""

import math

from cdr_helpers import rclpy_exact
from flexlink_ros.io import output_cdr
from flexlink_ros.io.cdr import serialize_message as exact_cdr
from flexlink_ros.ros import messages as ros_messages
import numpy as np
import output_messages
import pytest
from rclpy.serialization import deserialize_message
from rosbags.typesys import get_typestore, Stores
from sensor_msgs.msg import JointState


@pytest.mark.parametrize('frame, count', [('linkage_ground', 9), ('m', 2), ('odd_frame', 17)])
def test_marker_encoder_equals_the_exact_serialisation(frame, count):
    rng = np.random.default_rng(count)
    encoder = output_cdr.MarkerEncoder(frame, count)
    assert len(encoder.stamp_offsets) == 10      # 6 link strips + 4 joint spheres
    levels = [ros_messages.OK, ros_messages.WARN, ros_messages.ERROR, ros_messages.STALE]
    for _ in range(3):
        points = [rng.normal(size=(count, 2)) for _ in range(3)]
        deflections = [1e-3 * rng.normal(size=(count, 2)) for _ in range(3)]
        joints = rng.normal(size=(4, 2))
        stamp_ns = int(rng.integers(0, 2**31 - 1)) * 10**9 + int(rng.integers(0, 10**9))
        rng.shuffle(levels)
        expected = rclpy_exact(output_cdr.linkage_markers(
            ros_messages.ns_to_stamp(stamp_ns), frame, points, deflections, 37.0, joints,
            levels))
        assert encoder.encode(stamp_ns, points, deflections, 37.0, joints, levels) == expected


@pytest.mark.parametrize('frame', ['linkage_ground', 'm', 'odd_frame'])
def test_row_encoders_equal_the_one_message_encoders(frame):
    rng = np.random.default_rng(len(frame))
    count = 7
    stamps = rng.integers(0, 2**31 - 1, count) * 10**9 + rng.integers(0, 10**9, count)
    values = rng.normal(size=(count, 2))
    ratio, rate, force = (rng.normal(size=(count, 4)) for _ in range(3))
    encoded = frame.encode()
    vectors = output_cdr.rows_to_bytes(output_cdr.vector3_stamped_rows(stamps, encoded, values))
    criteria = output_cdr.rows_to_bytes(output_cdr.criteria_rows(stamps, encoded, ratio, rate,
                                                                 force))
    encoder = output_cdr.MarkerEncoder(frame, 5)
    points = rng.normal(size=(count, 3, 5, 2))
    deflections = 1e-3 * rng.normal(size=(count, 3, 5, 2))
    joints = rng.normal(size=(count, 4, 2))
    levels = [ros_messages.OK, ros_messages.WARN, ros_messages.ERROR, ros_messages.OK]
    marker_rows = output_cdr.rows_to_bytes(encoder.encode_rows(stamps, points, deflections,
                                                               11.0, joints, levels))
    for n, stamp in enumerate(stamps.tolist()):
        sec, nanosec = divmod(stamp, 10**9)
        assert vectors[n] == output_cdr.vector3_stamped_cdr(sec, nanosec, encoded, *values[n])
        assert criteria[n] == output_cdr.criteria_cdr(sec, nanosec, encoded, ratio[n],
                                                      rate[n], force[n])
        assert marker_rows[n] == encoder.encode(stamp, list(points[n]), list(deflections[n]),
                                                11.0, joints[n], levels)


def test_row_encoders_take_no_rows():
    # A replay block may hold no sample of an output (markers every n-th sample).
    stamps, encoded = np.zeros(0, dtype=np.int64), b'linkage_ground'
    assert output_cdr.vector3_stamped_rows(stamps, encoded, np.zeros((0, 2))).shape[0] == 0
    assert output_cdr.criteria_rows(stamps, encoded, *(np.zeros((0, 4)),) * 3).shape[0] == 0
    assert output_cdr.quality_rows(stamps, encoded, np.zeros(0), np.zeros(0)).shape[0] == 0
    encoder = output_cdr.MarkerEncoder('linkage_ground', 5)
    rows = encoder.encode_rows(stamps, np.zeros((0, 3, 5, 2)), np.zeros((0, 3, 5, 2)), 1.0,
                               np.zeros((0, 4, 2)), [ros_messages.OK] * 4)
    assert output_cdr.rows_to_bytes(rows) == []


def test_output_cdr_decodes_with_rclpy_and_equals_the_node_messages():
    stamp = ros_messages.ns_to_stamp(1_234_567_890_123)
    vector = output_cdr.vector3_stamped_cdr(stamp.sec, stamp.nanosec, b'linkage_ground',
                                            1.5e-3, -2e-4)
    node_vector = output_messages.deflection_message(stamp, 'linkage_ground', 1.5e-3, -2e-4)
    assert vector == rclpy_exact(node_vector)   # rclpy leaves padding uninitialised
    criteria = output_cdr.criteria_cdr(stamp.sec, stamp.nanosec, b'g', [1.0, 2.0, 3.0, 4.0],
                                       [0.1, 0.2, 0.3, 0.4], [10.0, 20.0, 30.0, 40.0])
    node_criteria = output_messages.criteria_message(stamp, 'g', [1.0, 2.0, 3.0, 4.0],
                                                     [0.1, 0.2, 0.3, 0.4],
                                                     [10.0, 20.0, 30.0, 40.0])
    assert criteria == rclpy_exact(node_criteria)
    decoded = deserialize_message(criteria, JointState)
    assert list(decoded.name) == ['O2', 'A', 'B', 'O4'] and decoded.effort[3] == 40.0


@pytest.mark.parametrize('frame', ['', 'g', 'ab', 'abc', 'abcd', 'abcde', 'abcdef', 'abcdefg',
                                   'linkage_ground', 'machine_base_frame'])
def test_vector3_stamped_equals_rclpy_for_any_frame_length(frame):
    """The one-struct encoder against rclpy, frames of every padding class (and none)."""
    for stamp_ns in (1, 1_700_000_000_987_654_321):
        stamp = ros_messages.ns_to_stamp(stamp_ns)
        got = output_cdr.vector3_stamped_cdr(stamp.sec, stamp.nanosec, frame.encode(),
                                             -3.25e-4, 1.5e-3)
        expected = output_messages.deflection_message(stamp, frame, -3.25e-4, 1.5e-3)
        assert got == rclpy_exact(expected)


@pytest.mark.parametrize('frame', ['g', 'linkage_ground', 'abc', 'machine_base_frame'])
def test_criteria_template_path_equals_rclpy_for_any_frame_length(frame):
    """The per-sample template encoder against rclpy, frames of every padding class."""
    rng = np.random.default_rng(len(frame))
    values = [rng.normal(size=4).tolist() for _ in range(3)]
    for stamp_ns in (1, 1_700_000_000_987_654_321):
        stamp = ros_messages.ns_to_stamp(stamp_ns)
        got = output_cdr.criteria_cdr(stamp.sec, stamp.nanosec, frame.encode(), *values)
        assert got == rclpy_exact(output_messages.criteria_message(stamp, frame, *values))


def test_quality_rows_are_the_bytes_the_node_publishes():
    stamps = np.array([1_700_000_000_000_000_000, 1_700_000_000_999_999_999, 5])
    error = np.array([0.031, 0.0, 2.5])
    nonlinearity = np.array([np.nan, 0.25, 1e-3])
    for frame in (b'linkage_ground', b'odd'):    # the frame's length moves the values
        rows = output_cdr.quality_rows(stamps, frame, error, nonlinearity)
        for row, stamp, e, n in zip(rows, stamps.tolist(), error, nonlinearity):
            sec, nanosec = divmod(stamp, 1_000_000_000)
            assert row.tobytes() == output_cdr.quality_cdr(sec, nanosec, frame, e, n)


def test_quality_cdr_is_the_quality_message_read_back_by_rclpy_and_rosbags():
    stamp = ros_messages.ns_to_stamp(1_700_000_000_123_456_789)
    data = output_cdr.quality_cdr(stamp.sec, stamp.nanosec, b'linkage_ground', 0.031, math.nan)
    assert data == exact_cdr(output_messages.quality_message(stamp, 'linkage_ground', 0.031,
                                                             math.nan))
    message = deserialize_message(data, JointState)
    assert list(message.name) == ['error_indicator', 'nonlinearity']
    assert message.position[0] == 0.031 and math.isnan(message.position[1])
    assert (message.header.stamp, message.header.frame_id) == (stamp, 'linkage_ground')
    assert len(message.velocity) == len(message.effort) == 0
    # rosbags refuses CDR of any other length than the message's (exact bytes).
    decoded = get_typestore(Stores.ROS2_HUMBLE).deserialize_cdr(data,
                                                                'sensor_msgs/msg/JointState')
    assert decoded.position[0] == 0.031 and decoded.header.stamp.nanosec == 123_456_789
    other = output_cdr.quality_cdr(1, 2, b'frame_b', 0.5, 0.25)   # another frame, template
    assert deserialize_message(other, JointState).position.tolist() == [0.5, 0.25]


@pytest.mark.parametrize('frame', ['g', 'ab', 'abc', 'linkage_ground', 'machine_base_frame'])
def test_every_row_encoder_equals_rclpy_for_each_output(frame):
    """Rows of each of the four outputs against rclpy's serialisation of the node's message."""
    rng = np.random.default_rng(len(frame) + 7)
    count = 5
    stamps = np.array([0, 1, 1_700_000_000_987_654_321, 2**31 * 10**9 - 1, 123_456_789_012])
    deflections = rng.normal(size=(count, 2)) * 1e-3
    deflections[1, 0] = math.nan
    ratio, rate, force = (rng.normal(size=(count, 4)) for _ in range(3))
    error, nonlinearity = rng.uniform(size=count), rng.uniform(size=count)
    nonlinearity[2] = math.nan
    encoded = frame.encode()
    vectors = output_cdr.vector3_stamped_rows(stamps, encoded, deflections)
    criteria = output_cdr.criteria_rows(stamps, encoded, ratio, rate, force)
    quality = output_cdr.quality_rows(stamps, encoded, error, nonlinearity)
    encoder = output_cdr.MarkerEncoder(frame, 4)
    points, bent = rng.normal(size=(count, 3, 4, 2)), 1e-3 * rng.normal(size=(count, 3, 4, 2))
    joints = rng.normal(size=(count, 4, 2))
    levels = [ros_messages.WARN, ros_messages.OK, ros_messages.STALE, ros_messages.ERROR]
    marker_rows = encoder.encode_rows(stamps, points, bent, 25.0, joints, levels)
    for n, stamp_ns in enumerate(stamps.tolist()):
        stamp = ros_messages.ns_to_stamp(stamp_ns)
        assert vectors[n].tobytes() == rclpy_exact(
            output_messages.deflection_message(stamp, frame, *deflections[n]))
        assert criteria[n].tobytes() == rclpy_exact(
            output_messages.criteria_message(stamp, frame, ratio[n], rate[n], force[n]))
        assert quality[n].tobytes() == rclpy_exact(
            output_messages.quality_message(stamp, frame, error[n], nonlinearity[n]))
        assert marker_rows[n].tobytes() == rclpy_exact(output_cdr.linkage_markers(
            stamp, frame, list(points[n]), list(bent[n]), 25.0, joints[n], levels))
