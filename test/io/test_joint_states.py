"""The JointState column reader: rclpy's messages read in bulk, the odd ones one by one."""

import math

from flexlink_ros.io import joint_states
from flexlink_ros.ros import messages as ros_messages
import numpy as np
from rclpy.serialization import serialize_message
from sensor_msgs.msg import JointState


def joint_state(stamp_ns, names, positions, velocities=()):
    """Return a JointState with an odd-length frame id."""
    message = JointState(name=list(names), position=[float(p) for p in positions],
                         velocity=[float(v) for v in velocities])
    message.header.stamp = ros_messages.ns_to_stamp(stamp_ns)
    message.header.frame_id = 'odd_length_frame'
    return message


def test_crank_states_of_rclpy_messages_are_read_in_bulk(monkeypatch):
    """Read in bulk although rclpy's CDR leaves alignment padding unzeroed."""
    rng = np.random.default_rng(2)
    payloads = []
    for n in range(500):
        message = joint_state(10**9 + n * 10**6, ['crank', 'other'],
                              rng.normal(size=2), rng.normal(size=2))
        payloads.append(bytes(serialize_message(message)))
    odd = {100: joint_state(5, ['other', 'crank'], [1.0, 2.0], [3.0, 4.0]),
           200: joint_state(6, ['crank'], [1.5]),                      # no velocity
           300: joint_state(7, ['crank', 'other'], [math.nan, 0.0], [0.0, 0.0])}
    odd[300].header.frame_id = 'x'                                      # another length
    # Serialisers need not zero alignment padding (rclpy's Fast DDS does not, depending on
    # the memory it reuses): fill the padding of every message with other bytes.
    fixed, position, velocity = joint_states.joint_state_layout(payloads[0], b'crank')
    meaningful = np.zeros(len(payloads[0]), dtype=bool)
    for first, stop in fixed + [(4, 12), (position, position + 16), (velocity, velocity + 16)]:
        meaningful[first:stop] = True
    padding = np.flatnonzero(~meaningful)
    assert padding.size >= 6        # after the frame id and the names, and at the end
    for n in range(len(payloads)):
        data = np.frombuffer(payloads[n], dtype=np.uint8).copy()
        data[padding] = rng.integers(1, 256, size=padding.size)
        payloads[n] = data.tobytes()
    for n, message in odd.items():
        payloads[n] = bytes(serialize_message(message))
    calls = []
    original = joint_states.parse_joint_state

    def counted(data, name):
        calls.append(data)
        return original(data, name)
    monkeypatch.setattr(joint_states, 'parse_joint_state', counted)
    stamps, angles, speeds, valid, has_speed = joint_states.parse_crank_states(
        payloads, b'crank')
    assert len(calls) <= len(odd)           # only the odd ones one by one
    for n, payload in enumerate(payloads):
        stamp, angle, speed = original(payload, b'crank')
        assert stamps[n] == stamp
        assert (angles[n] == angle) or (math.isnan(angles[n]) and math.isnan(angle))
        assert has_speed[n] == (speed is not None)
        if speed is not None:
            assert speeds[n] == speed
