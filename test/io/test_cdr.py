"""CDR codecs of flexlink_ros.io.cdr and .markers against rclpy's serialisation."""

import struct

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from flexlink_ros.io import cdr
from flexlink_ros.io import markers
from flexlink_ros.io.msg_schema import cdr_layout, serialize_exact
from flexlink_ros.ros import messages as ros_messages
import numpy as np
import pytest
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import JointState
from visualization_msgs.msg import Marker


def rclpy_exact(message):
    """Serialise with rclpy, zero the padding and cut the buffer at the exact CDR length."""
    data = bytearray(serialize_message(message))
    length, padding = cdr_layout(message)
    assert length <= len(data)
    for start, stop in padding:
        data[start:stop] = bytes(stop - start)
    return bytes(data[:length])


def joint_state(stamp_ns, names, positions, velocities=()):
    message = JointState(name=list(names), position=[float(p) for p in positions],
                         velocity=[float(v) for v in velocities])
    message.header.stamp = ros_messages.ns_to_stamp(stamp_ns)
    message.header.frame_id = 'odd_length_frame'
    return message


@pytest.mark.parametrize('names, positions, velocities, expected', [
    (['crank'], [1.25], [40.0], (1.25, 40.0)),
    (['base', 'crank', 'z'], [0.1, -2.5, 3.0], [1.0, 2.0, 3.0], (-2.5, 2.0)),
    (['crank'], [0.3], [], (0.3, None)),
    (['other'], [0.3], [1.0], (None, None)),
    (['a', 'crank'], [0.3], [], (None, None)),
])
def test_parse_joint_state_matches_rclpy(names, positions, velocities, expected):
    data = serialize_message(joint_state(1_700_000_000_123_456_789, names, positions,
                                         velocities))
    stamp, position, velocity = cdr.parse_joint_state(data, b'crank')
    assert stamp == 1_700_000_000_123_456_789
    assert (position, velocity) == expected


def test_output_cdr_decodes_with_rclpy_and_equals_the_node_messages():
    stamp = ros_messages.ns_to_stamp(1_234_567_890_123)
    vector = cdr.vector3_stamped_cdr(stamp.sec, stamp.nanosec, b'linkage_ground',
                                     1.5e-3, -2e-4)
    node_vector = ros_messages.deflection_message(stamp, 'linkage_ground', 1.5e-3, -2e-4)
    assert vector == rclpy_exact(node_vector)   # rclpy leaves padding uninitialised
    criteria = cdr.criteria_cdr(stamp.sec, stamp.nanosec, b'g', [1.0, 2.0, 3.0, 4.0],
                                [0.1, 0.2, 0.3, 0.4], [10.0, 20.0, 30.0, 40.0])
    node_criteria = ros_messages.criteria_message(stamp, 'g', [1.0, 2.0, 3.0, 4.0],
                                                  [0.1, 0.2, 0.3, 0.4],
                                                  [10.0, 20.0, 30.0, 40.0])
    assert criteria == rclpy_exact(node_criteria)
    decoded = deserialize_message(criteria, JointState)
    assert list(decoded.name) == ['O2', 'A', 'B', 'O4'] and decoded.effort[3] == 40.0


def test_big_endian_joint_state_is_read():
    little = serialize_message(joint_state(5 * 10**9 + 7, ['crank'], [0.5], [2.0]))
    # Re-encode by hand in big endian: header, then each field swapped.
    big = b'\x00\x00\x00\x00' + struct.pack('>iII', 5, 7, 17) + b'odd_length_frame\x00'
    big += bytes((-(len(big) - 4)) % 4) + struct.pack('>I', 1)
    big += struct.pack('>I', 6) + b'crank\x00'
    big += bytes((-(len(big) - 4)) % 4) + struct.pack('>I', 1)
    big += bytes((-(len(big) - 4)) % 8) + struct.pack('>d', 0.5)
    big += struct.pack('>I', 1) + bytes((-(len(big) + 4 - 4)) % 8) + struct.pack('>d', 2.0)
    big += struct.pack('>I', 0)
    assert cdr.parse_joint_state(big, b'crank') == cdr.parse_joint_state(little, b'crank') \
        == (5 * 10**9 + 7, 0.5, 2.0)


@pytest.mark.parametrize('frame, count', [('linkage_ground', 9), ('m', 2), ('odd_frame', 17)])
def test_marker_encoder_equals_the_exact_serialisation(frame, count):
    rng = np.random.default_rng(count)
    encoder = markers.MarkerEncoder(frame, count)
    assert len(encoder.stamp_offsets) == 10      # 6 link strips + 4 joint spheres
    levels = [ros_messages.OK, ros_messages.WARN, ros_messages.ERROR, ros_messages.STALE]
    for _ in range(3):
        points = [rng.normal(size=(count, 2)) for _ in range(3)]
        deflections = [1e-3 * rng.normal(size=(count, 2)) for _ in range(3)]
        joints = rng.normal(size=(4, 2))
        stamp_ns = int(rng.integers(0, 2**31 - 1)) * 10**9 + int(rng.integers(0, 10**9))
        rng.shuffle(levels)
        expected = rclpy_exact(markers.linkage_markers(
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
    vectors = markers.rows_to_bytes(markers.vector3_stamped_rows(stamps, encoded, values))
    criteria = markers.rows_to_bytes(markers.criteria_rows(stamps, encoded, ratio, rate, force))
    encoder = markers.MarkerEncoder(frame, 5)
    points = rng.normal(size=(count, 3, 5, 2))
    deflections = 1e-3 * rng.normal(size=(count, 3, 5, 2))
    joints = rng.normal(size=(count, 4, 2))
    levels = [ros_messages.OK, ros_messages.WARN, ros_messages.ERROR, ros_messages.OK]
    marker_rows = markers.rows_to_bytes(encoder.encode_rows(stamps, points, deflections, 11.0,
                                                            joints, levels))
    for n, stamp in enumerate(stamps.tolist()):
        sec, nanosec = divmod(stamp, 10**9)
        assert vectors[n] == cdr.vector3_stamped_cdr(sec, nanosec, encoded, *values[n])
        assert criteria[n] == cdr.criteria_cdr(sec, nanosec, encoded, ratio[n], rate[n],
                                               force[n])
        assert marker_rows[n] == encoder.encode(stamp, list(points[n]), list(deflections[n]),
                                                11.0, joints[n], levels)


@pytest.mark.parametrize('frame', ['g', 'linkage_ground', 'abc', 'machine_base_frame'])
def test_criteria_template_path_equals_rclpy_for_any_frame_length(frame):
    """The per-sample template encoder against rclpy, frames of every padding class."""
    rng = np.random.default_rng(len(frame))
    values = [rng.normal(size=4).tolist() for _ in range(3)]
    for stamp_ns in (1, 1_700_000_000_987_654_321):
        stamp = ros_messages.ns_to_stamp(stamp_ns)
        got = cdr.criteria_cdr(stamp.sec, stamp.nanosec, frame.encode(), *values)
        assert got == rclpy_exact(ros_messages.criteria_message(stamp, frame, *values))


def diagnostics():
    status = DiagnosticStatus(level=DiagnosticStatus.WARN, name='jöint', message='',
                              values=[KeyValue(key='k', value='v' * 5)])
    return DiagnosticArray(status=[status, DiagnosticStatus()])


@pytest.mark.parametrize('message', [
    JointState(), JointState(name=['a', 'bb'], position=[1.0, 2.0], velocity=[], effort=[3.0]),
    Marker(), Marker(points=[], text='é', frame_locked=True),
    ros_messages.deflection_message(ros_messages.ns_to_stamp(7), 'ground', 1.0, 2.0),
    diagnostics(),
], ids=['empty', 'joints', 'marker', 'marker-text', 'vector', 'diagnostics'])
def test_serialize_exact_equals_rclpy_trimmed_with_zeroed_padding(message):
    data = serialize_exact(message)
    assert data == rclpy_exact(message)
    assert cdr_layout(message)[0] == len(data)
    assert deserialize_message(data, type(message)) == message
