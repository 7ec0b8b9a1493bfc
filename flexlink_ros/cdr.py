"""
CDR (XCDR1) bytes of the few message types the node and replay handle per sample.

rclpy's Python message classes cost 10-20 us to build and as much to serialise; at 1 kHz with
recording that is a large share of the node's time. These functions read a
``sensor_msgs/JointState`` and write ``geometry_msgs/Vector3Stamped`` and the criteria
``sensor_msgs/JointState`` directly, with zeroed alignment padding, byte-identical to
``rosbag_schema.serialize_exact`` of the corresponding ros_messages.py message (tested).
Alignment counts from the end of the 4-byte encapsulation header.
"""

import struct

from .core.reduced import JOINTS

CDR_LE = b'\x00\x01\x00\x00'  # encapsulation header: plain CDR, little endian


def _align(offset, size):
    # Alignment counts from the end of the 4-byte encapsulation header.
    return offset + (-(offset - 4)) % size


def _read_string(data, offset, endian):
    offset = _align(offset, 4)
    (length,) = struct.unpack_from(endian + 'I', data, offset)
    offset += 4
    return bytes(data[offset:offset + max(length - 1, 0)]), offset + length


def _read_doubles(data, offset, endian):
    offset = _align(offset, 4)
    (count,) = struct.unpack_from(endian + 'I', data, offset)
    offset += 4
    if count:
        offset = _align(offset, 8)
    values = struct.unpack_from(f'{endian}{count}d', data, offset)
    return values, offset + 8 * count


def parse_joint_state(data, joint_name):
    """
    Stamp, position and velocity of one joint from JointState CDR bytes.

    Parameters
    ----------
    data : bytes
        CDR (XCDR1, either byte order) of a ``sensor_msgs/JointState``.
    joint_name : bytes
        UTF-8 name of the joint.

    Returns
    -------
    stamp_ns : int
    position : float or None
        None if the joint or its position is missing.
    velocity : float or None
        None if the message has no velocity for the joint.

    """
    endian = '<' if data[1] == 1 else '>'
    sec, nanosec = struct.unpack_from(endian + 'iI', data, 4)
    _, offset = _read_string(data, 12, endian)
    offset = _align(offset, 4)
    (count,) = struct.unpack_from(endian + 'I', data, offset)
    offset += 4
    index = None
    for k in range(count):
        name, offset = _read_string(data, offset, endian)
        if index is None and name == joint_name:
            index = k
    positions, offset = _read_doubles(data, offset, endian)
    velocities, offset = _read_doubles(data, offset, endian)
    stamp_ns = sec * 1_000_000_000 + nanosec
    if index is None or index >= len(positions):
        return stamp_ns, None, None
    velocity = velocities[index] if index < len(velocities) else None
    return stamp_ns, positions[index], velocity


def _header_bytes(sec, nanosec, frame):
    return CDR_LE + struct.pack('<iII', sec, nanosec, len(frame) + 1) + frame + b'\x00'


def vector3_stamped_cdr(sec, nanosec, frame, x, y, z=0.0):
    """CDR bytes of a ``geometry_msgs/Vector3Stamped`` (frame as UTF-8 bytes)."""
    head = _header_bytes(sec, nanosec, frame)
    return head + bytes(_align(len(head), 8) - len(head)) + struct.pack('<3d', x, y, z)


def criteria_cdr(sec, nanosec, frame, ratio, gamma_dot, force):
    """CDR bytes of the criteria ``sensor_msgs/JointState`` (ros_messages.criteria_message)."""
    out = bytearray(_header_bytes(sec, nanosec, frame))
    out += bytes(_align(len(out), 4) - len(out)) + struct.pack('<I', len(JOINTS))
    for name in JOINTS:
        out += bytes(_align(len(out), 4) - len(out))
        out += struct.pack('<I', len(name) + 1) + name.encode() + b'\x00'
    for values in (ratio, gamma_dot, force):
        out += bytes(_align(len(out), 4) - len(out)) + struct.pack('<I', len(values))
        out += bytes(_align(len(out), 8) - len(out)) + struct.pack(f'<{len(values)}d', *values)
    return bytes(out)
