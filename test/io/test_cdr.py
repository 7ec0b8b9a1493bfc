"""CDR codecs of flexlink_ros.io.cdr against rclpy's serialisation."""

import struct

from flexlink_ros.io import cdr
from flexlink_ros.ros import messages as ros_messages
import pytest
from rclpy.serialization import serialize_message
from sensor_msgs.msg import JointState


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
