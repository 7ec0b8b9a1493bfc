"""Small crank recordings for the fleet tests, written by the project's own recorder."""

import math

from flexlink_ros.io.recorder import McapRecorder
from flexlink_ros.ros import messages as ros_messages
import numpy as np
from rclpy.serialization import serialize_message
from sensor_msgs.msg import JointState

RPM = 2.0 * math.pi / 60.0
T0 = 1_700_000_000_000_000_000
# The model options of these tests' replays (the replay tests' cached model).
MODEL_FLAGS = ('--no-geometric-stiffness',)


def joint_state(stamp_ns, names, positions, velocities=()):
    """Return a JointState message stamped ``stamp_ns``."""
    message = JointState(name=list(names), position=[float(p) for p in positions],
                         velocity=[float(v) for v in velocities])
    message.header.stamp = ros_messages.ns_to_stamp(stamp_ns)
    return message


def crank_stream(seconds, rpm, gap_at=None, start_angle=0.3):
    """Stamps [ns], wrapped angles [rad] and speeds of a crank at ``rpm`` sampled at 1 kHz."""
    times = np.arange(int(round(seconds * 1000))) * 1e-3
    if gap_at is not None:
        times[times >= gap_at] += 0.8             # the estimate restarts after the gap
    speed = rpm * RPM
    angles = np.mod(speed * times + start_angle + math.pi, 2 * math.pi) - math.pi
    stamps = T0 + np.round(times * 1e9).astype(np.int64)
    return stamps, angles, np.full(stamps.size, speed)


def write_bag(path, stamps, angles, speeds, bad=()):
    """Write a bag of crank JointStates (logged 200 us after their stamp) and bad messages."""
    with McapRecorder(path) as recorder:
        recorder.add_topic('/joint_states', JointState)
        for stamp, angle, speed in zip(stamps.tolist(), angles.tolist(), speeds.tolist()):
            data = serialize_message(joint_state(stamp, ['crank'], [angle], [speed]))
            recorder.write('/joint_states', data, stamp + 200_000)
        for log_ns, data in bad:
            recorder.write('/joint_states', data, log_ns)


def bad_messages(stamps, rows):
    """Three kinds of unusable message, logged just after the samples ``rows``."""
    kinds = [lambda s: serialize_message(joint_state(s, ['crank'], [math.nan])),
             lambda s: serialize_message(joint_state(s, ['lever'], [0.0])),
             lambda s: b'\x00\x01\x00\x00\x07']
    return [(int(stamps[row]) + 300_000, kinds[k % 3](int(stamps[row]) + 300_000))
            for k, row in enumerate(rows)]
