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


def _outcome(read, data):
    try:
        return read(data)
    except cdr.MalformedCdr as exc:
        return ('MalformedCdr', str(exc))


def _stream_of_changing_layouts():
    """Return the CDR of a stream of JointStates whose layout repeats, changes and breaks."""
    def message(stamp_ns, names, positions, velocities=()):
        return serialize_message(joint_state(stamp_ns, names, positions, velocities))

    base = message(5 * 10**9 + 1, ['a', 'crank'], [0.1, 0.2], [1.0, 2.0])
    stream = [base, message(5 * 10**9 + 2, ['a', 'crank'], [-3.0, 0.7], [9.0, -4.5])]
    # The same length, another joint name: the crank is gone.
    stream.append(message(5 * 10**9 + 3, ['a', 'cronk'], [0.1, 0.3], [1.0, 2.5]))
    stream.append(message(5 * 10**9 + 4, ['a', 'crank'], [0.1, 0.4], [1.0, 2.5]))
    # The same layout with an impossible stamp, then with a new value in the padding.
    bad_stamp = bytearray(stream[-1])
    struct.pack_into('<I', bad_stamp, 8, 1_000_000_000)
    padded = bytearray(stream[-1])
    padded[len(padded) - 4 - 8 * 2 - 4 - 4] = 0x7f     # the padding before the velocities
    stream += [bytes(bad_stamp), bytes(padded), stream[1]]
    # No velocity for the crank, fewer positions than names, an effort array, truncated.
    stream += [message(5 * 10**9 + 5, ['a', 'crank'], [0.1, 0.5], [1.0]),
               message(5 * 10**9 + 6, ['a', 'crank'], [0.1, 0.6], [1.0]),
               message(5 * 10**9 + 7, ['a', 'crank'], [0.1], [1.0, 2.0]),
               message(5 * 10**9 + 8, ['crank'], [0.9], [3.0]), base[:-12], base]
    with_effort = joint_state(5 * 10**9 + 9, ['crank'], [0.8], [2.0])
    with_effort.effort = [7.0, 8.0]
    stream += [serialize_message(with_effort)] * 2
    return stream


def test_joint_state_reader_matches_parse_on_a_changing_stream():
    stream = _stream_of_changing_layouts()
    reader = cdr.JointStateReader(b'crank')
    outcomes = [_outcome(reader, data) for data in stream]
    assert outcomes == [_outcome(lambda d: cdr.parse_joint_state(d, b'crank'), data)
                        for data in stream]
    assert outcomes[1] == (5 * 10**9 + 2, 0.7, -4.5) and outcomes[2][1] is None
    assert outcomes[4][0] == outcomes[11][0] == 'MalformedCdr' and outcomes[8][2] is None


def test_joint_state_reader_parses_in_full_only_a_new_layout():
    reader = cdr.JointStateReader(b'crank')
    for k in range(5):
        assert reader(serialize_message(joint_state(7 + k, ['crank'], [0.25 * k], [3.0 * k]))) \
            == (7 + k, 0.25 * k, 3.0 * k)
    assert reader.full_parses == 1
    reader(serialize_message(joint_state(20, ['crank', 'b'], [0.5, 1.0], [6.0, 1.0])))
    assert reader.full_parses == 2
