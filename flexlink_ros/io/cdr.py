"""
CDR (XCDR1) bytes of the few message types the node and replay handle per sample.

rclpy's Python message classes cost 10-20 us to build and as much to serialise; at 1 kHz with
recording that is a large share of the node's time. These functions read a
``sensor_msgs/JointState`` and write ``geometry_msgs/Vector3Stamped`` and the criteria
``sensor_msgs/JointState`` directly, with zeroed alignment padding, byte-identical to
``rosbag_schema.serialize_exact`` of the corresponding ros_messages.py message (tested).
Alignment counts from the end of the 4-byte encapsulation header.
"""

import functools
import struct

from ..errors import MalformedCdr
from ..names import JOINT_NAMES as JOINTS

CDR_LE = b'\x00\x01\x00\x00'  # encapsulation header: plain CDR, little endian


# Input bounds of a JointState (checked against the declared lengths before anything is
# read or allocated, so crafted counts cannot size an allocation).
MAX_MESSAGE_BYTES = 1 << 20   # 1 MiB: a JointState of MAX_JOINTS joints is under 300 kB
MAX_JOINTS = 1024             # names and each of position, velocity, effort
MAX_NAME_BYTES = 256          # frame_id and each joint name, UTF-8, without the NUL
_ENCAPSULATIONS = {b'\x00\x00': '>', b'\x00\x01': '<'}   # plain CDR big / little endian


def _align(offset, size):
    # Alignment counts from the end of the 4-byte encapsulation header.
    return offset + (-(offset - 4)) % size


def _read_count(data, offset, endian, what, limit):
    """A uint32 length at ``offset`` (aligned to 4), checked against ``limit``."""
    offset = _align(offset, 4)
    if offset + 4 > len(data):
        raise MalformedCdr(f'{what}: length field beyond the end of the message')
    (count,) = struct.unpack_from(endian + 'I', data, offset)
    if count > limit:
        raise MalformedCdr(f'{what}: declared length {count} beyond the bound {limit}')
    return count, offset + 4


def _read_string(data, offset, endian, what='string'):
    length, offset = _read_count(data, offset, endian, what, MAX_NAME_BYTES + 1)
    end = offset + length
    if end > len(data):
        raise MalformedCdr(f'{what}: {length} bytes declared, {len(data) - offset} left')
    return bytes(data[offset:offset + max(length - 1, 0)]), end


def _read_doubles(data, offset, endian, what):
    count, offset = _read_count(data, offset, endian, what, MAX_JOINTS)
    if count:
        offset = _align(offset, 8)
    if offset + 8 * count > len(data):
        raise MalformedCdr(f'{what}: {count} values declared, {len(data) - offset} bytes left')
    values = struct.unpack_from(f'{endian}{count}d', data, offset)
    return values, offset + 8 * count


def parse_joint_state(data, joint_name):
    """
    Stamp, position and velocity of one joint from JointState CDR bytes.

    The whole message is checked against the input bounds (:data:`MAX_MESSAGE_BYTES`,
    :data:`MAX_JOINTS`, :data:`MAX_NAME_BYTES`) and every declared length against the bytes
    left, before it is read.

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

    Raises
    ------
    MalformedCdr
        Not a JointState within the bounds (the message names the field).

    """
    if len(data) > MAX_MESSAGE_BYTES:
        raise MalformedCdr(f'{len(data)} bytes, beyond the bound of {MAX_MESSAGE_BYTES}')
    if len(data) < 16:
        raise MalformedCdr(f'{len(data)} bytes, too short for a JointState')
    endian = _ENCAPSULATIONS.get(bytes(data[:2]))
    if endian is None:
        raise MalformedCdr(f'encapsulation {bytes(data[:2]).hex()} is not plain CDR')
    sec, nanosec = struct.unpack_from(endian + 'iI', data, 4)
    if nanosec >= 1_000_000_000:
        raise MalformedCdr(f'stamp nanosec {nanosec} beyond 999999999')
    _, offset = _read_string(data, 12, endian, 'frame_id')
    count, offset = _read_count(data, offset, endian, 'name', MAX_JOINTS)
    if offset + 4 * count > len(data):   # each name takes 4 bytes at least
        raise MalformedCdr(f'name: {count} names declared, {len(data) - offset} bytes left')
    index = None
    for k in range(count):
        name, offset = _read_string(data, offset, endian, 'name')
        if index is None and name == joint_name:
            index = k
    positions, offset = _read_doubles(data, offset, endian, 'position')
    velocities, offset = _read_doubles(data, offset, endian, 'velocity')
    _, offset = _read_doubles(data, offset, endian, 'effort')
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
    if len(ratio) == len(gamma_dot) == len(force) == len(JOINTS):
        # Per-sample path: the layout is fixed by the frame; patch a template (~1 us).
        template, offsets = _criteria_template(frame)
        out = bytearray(template)
        _STAMP.pack_into(out, 4, sec, nanosec)
        _FOUR_DOUBLES.pack_into(out, offsets[0], *ratio)
        _FOUR_DOUBLES.pack_into(out, offsets[1], *gamma_dot)
        _FOUR_DOUBLES.pack_into(out, offsets[2], *force)
        return bytes(out)
    return _criteria_cdr_plain(sec, nanosec, frame, ratio, gamma_dot, force)


@functools.lru_cache(maxsize=16)
def _criteria_template(frame):
    """Serialised criteria message of a frame and the offsets of its three arrays."""
    joints = len(JOINTS)
    sentinels = [[1.0e300 + k * 1e285 + j * 1e284 for j in range(joints)] for k in range(3)]
    template = _criteria_cdr_plain(0, 0, frame, *sentinels)
    offsets = [template.index(struct.pack(f'<{joints}d', *values)) for values in sentinels]
    return template, offsets


_STAMP = struct.Struct('<iI')
_FOUR_DOUBLES = struct.Struct(f'<{len(JOINTS)}d')


def _criteria_cdr_plain(sec, nanosec, frame, ratio, gamma_dot, force):
    out = bytearray(_header_bytes(sec, nanosec, frame))
    out += bytes(_align(len(out), 4) - len(out)) + struct.pack('<I', len(JOINTS))
    for name in JOINTS:
        out += bytes(_align(len(out), 4) - len(out))
        out += struct.pack('<I', len(name) + 1) + name.encode() + b'\x00'
    for values in (ratio, gamma_dot, force):
        out += bytes(_align(len(out), 4) - len(out)) + struct.pack('<I', len(values))
        out += bytes(_align(len(out), 8) - len(out)) + struct.pack(f'<{len(values)}d', *values)
    return bytes(out)


_BASIC_FORMATS = {
    'boolean': '?', 'octet': 'B', 'char': 'B', 'int8': 'b', 'uint8': 'B', 'int16': 'h',
    'uint16': 'H', 'int32': 'i', 'uint32': 'I', 'float': 'f', 'int64': 'q', 'uint64': 'Q',
    'double': 'd',
}


def _serialize_plain(message):
    """
    CDR bytes of a message object by walking its fields in Python (zeroed padding).

    The same bytes as ``rosbag_schema.serialize_exact`` (tested through MarkerEncoder), but
    without rclpy's serialiser: importing rclpy and the type support costs about 0.1 s, more
    than a replay writes in.
    """
    out = bytearray(CDR_LE)
    _write_message(out, message)
    return bytes(out)


def _pad(out, alignment):
    remainder = (len(out) - 4) % alignment
    if remainder:
        out += bytes(alignment - remainder)


def _write_message(out, message):
    cls = type(message)
    for slot, member_type in zip(cls.__slots__, cls.SLOT_TYPES):
        _write_value(out, member_type, getattr(message, slot))


def _write_value(out, member_type, value):
    from rosidl_parser import definition
    if isinstance(member_type, definition.BasicType):
        code = _BASIC_FORMATS[member_type.typename]
        size = struct.calcsize(code)
        _pad(out, min(size, 8))
        out += struct.pack('<' + code, value)
    elif isinstance(member_type, definition.AbstractWString):
        raise ValueError('wstring is not supported')
    elif isinstance(member_type, definition.AbstractString):
        data = value.encode('utf-8')
        _pad(out, 4)
        out += struct.pack('<I', len(data) + 1) + data + b'\x00'
    elif isinstance(member_type, definition.NamespacedType):
        _write_message(out, value)
    elif isinstance(member_type, definition.AbstractNestedType):
        if isinstance(member_type, definition.AbstractSequence):
            _pad(out, 4)
            out += struct.pack('<I', len(value))
        element = member_type.value_type
        if isinstance(element, definition.BasicType):
            code = _BASIC_FORMATS[element.typename]
            if len(value):
                _pad(out, min(struct.calcsize(code), 8))
                out += struct.pack(f'<{len(value)}{code}', *value)
        else:
            for item in value:
                _write_value(out, element, item)
    else:
        raise ValueError(f'CDR of {type(member_type).__name__} is not supported')


class MarkerEncoder:
    """
    CDR of ros_messages.linkage_markers, by patching a serialised template.

    The marker array has a fixed layout for a given frame id and number of points per link,
    so it is serialised once (exactly, zeroed padding) and each call writes only the stamps,
    the points of the rigid and deformed links, the joint positions and the joint colours.
    Offsets are found by serialising sentinel values; the result equals
    ``serialize_exact(linkage_markers(...))`` (tested).

    Parameters
    ----------
    frame_id : str
    points_per_link : int
    links : int
        Number of links (3).

    """

    _SENTINEL_STAMP = (0x5A5A5A5A, 0x1A2B3C4D)
    _COLOUR_AFTER_POSITION = 80   # bytes: position, orientation (7 doubles), scale (3 doubles)

    def __init__(self, frame_id, points_per_link, links=3):
        import numpy as np

        from ..ros import messages as rm
        self.frame_id, self.count, self.links = frame_id, int(points_per_link), links
        self._np, self._rm = np, rm
        index = np.arange(self.count, dtype=float)
        rigid = [np.stack([1e6 + 1e4 * k + index + 0.25, 2e6 + 1e4 * k + index + 0.25], axis=1)
                 for k in range(links)]
        offset = np.array([5e5, 5e5])
        joints = np.array([[7e6 + j + 0.5, 8e6 + j + 0.5] for j in range(4)])
        stamp = rm.Time(sec=self._SENTINEL_STAMP[0], nanosec=self._SENTINEL_STAMP[1])
        template = _serialize_plain(rm.linkage_markers(
            stamp, frame_id, rigid, [np.broadcast_to(offset, p.shape) for p in rigid], 1.0,
            joints, [rm.OK] * 4))
        self.template = template
        self.stamp_offsets = self._find_all(template, struct.pack('<iI', *self._SENTINEL_STAMP))
        self.rigid_offsets = [template.index(struct.pack('<d', p[0, 0])) for p in rigid]
        self.deformed_offsets = [template.index(struct.pack('<d', p[0, 0] + offset[0]))
                                 for p in rigid]
        self.joint_offsets = [template.index(struct.pack('<dd', *q)) for q in joints]
        self.colours = {level: struct.pack('<4f', *rgb, 1.0)
                        for level, rgb in rm.LEVEL_COLOURS.items()}

    @staticmethod
    def _find_all(data, pattern):
        found, start = [], 0
        while (position := data.find(pattern, start)) >= 0:
            found.append(position)
            start = position + 1
        return found

    def encode(self, stamp_ns, link_points, link_deflections, exaggeration, joint_positions,
               joint_levels):
        """
        CDR bytes of the marker array (arguments as ros_messages.linkage_markers).

        Parameters
        ----------
        stamp_ns : int
        link_points, link_deflections : sequence of ndarray, shape (points_per_link, 2)
        exaggeration : float
        joint_positions : ndarray, shape (4, 2)
        joint_levels : sequence of diagnostic levels, length 4

        """
        np = self._np
        out = bytearray(self.template)
        stamp = struct.pack('<iI', *divmod(int(stamp_ns), 1_000_000_000))
        for position in self.stamp_offsets:
            out[position:position + 8] = stamp
        block = np.zeros((self.count, 3))
        size = 24 * self.count
        for k in range(self.links):
            block[:, :2] = link_points[k]
            position = self.rigid_offsets[k]
            out[position:position + size] = block.tobytes()
            block[:, :2] = link_points[k] + exaggeration * np.asarray(link_deflections[k])
            position = self.deformed_offsets[k]
            out[position:position + size] = block.tobytes()
        for position, joint, level in zip(self.joint_offsets, joint_positions, joint_levels):
            out[position:position + 16] = struct.pack('<dd', joint[0], joint[1])
            colour = position + self._COLOUR_AFTER_POSITION
            out[colour:colour + 16] = self.colours[level]
        return bytes(out)

    def encode_rows(self, stamps_ns, link_points, link_deflections, exaggeration,
                    joint_positions, joint_levels):
        """
        CDR of many marker arrays at once (as :meth:`encode`, one row per message).

        Parameters
        ----------
        stamps_ns : ndarray of int, shape (m,)
        link_points, link_deflections : ndarray, shape (m, links, points_per_link, 2)
        exaggeration : float
        joint_positions : ndarray, shape (m, 4, 2)
        joint_levels : sequence of diagnostic levels, length 4 (the same for every message)

        Returns
        -------
        ndarray of uint8, shape (m, length)

        """
        np = self._np
        count = len(stamps_ns)
        rows = _template_rows(self.template, count)
        stamp = _stamp_columns(stamps_ns)
        for position in self.stamp_offsets:
            rows[:, position:position + 8] = stamp
        link_points = np.asarray(link_points, dtype=float)
        shown = link_points + exaggeration * np.asarray(link_deflections, dtype=float)
        block = np.zeros((count, self.count, 3))
        for k in range(self.links):
            block[:, :, :2] = link_points[:, k]
            _put_doubles(rows, self.rigid_offsets[k], block)
            block[:, :, :2] = shown[:, k]
            _put_doubles(rows, self.deformed_offsets[k], block)
        joint_positions = np.asarray(joint_positions, dtype=float)
        for j, (position, level) in enumerate(zip(self.joint_offsets, joint_levels)):
            _put_doubles(rows, position, joint_positions[:, j])
            colour = position + self._COLOUR_AFTER_POSITION
            rows[:, colour:colour + 16] = np.frombuffer(self.colours[level], dtype=np.uint8)
        return rows


# -- many messages at once ---------------------------------------------------------------------
#
# The fixed-layout messages above, for many stamps and values: one template row per message
# (numpy uint8 array of shape (m, length)) with the stamps and values written into their
# columns. Byte-identical to the one-message functions (tested).

def _stamp_columns(stamps_ns):
    import numpy as np
    sec, nanosec = np.divmod(np.asarray(stamps_ns, dtype=np.int64), 1_000_000_000)
    stamp = np.empty(sec.size, dtype=[('sec', '<i4'), ('nanosec', '<u4')])
    stamp['sec'] = sec
    stamp['nanosec'] = nanosec
    return stamp.view(np.uint8).reshape(sec.size, 8)


def _template_rows(template, count):
    import numpy as np
    return np.tile(np.frombuffer(template, dtype=np.uint8), (count, 1))


def _put_doubles(rows, offset, values):
    import numpy as np
    values = np.ascontiguousarray(values, dtype='<f8').reshape(rows.shape[0], -1)
    rows[:, offset:offset + 8 * values.shape[1]] = values.view(np.uint8)


def rows_to_bytes(rows):
    """The rows of a (m, length) uint8 array as a list of m bytes objects."""
    blob = rows.tobytes()
    width = rows.shape[1]
    return [blob[k:k + width] for k in range(0, len(blob), width)]


def vector3_stamped_rows(stamps_ns, frame, values):
    """
    CDR of many ``geometry_msgs/Vector3Stamped`` (as :func:`vector3_stamped_cdr`).

    Parameters
    ----------
    stamps_ns : ndarray of int, shape (m,)
    frame : bytes
    values : ndarray, shape (m, 2) or (m, 3)
        x, y[, z] (z = 0 if absent).

    Returns
    -------
    ndarray of uint8, shape (m, length)

    """
    template = vector3_stamped_cdr(0, 0, frame, 0.0, 0.0, 0.0)
    count = len(stamps_ns)
    rows = _template_rows(template, count)
    rows[:, 4:12] = _stamp_columns(stamps_ns)
    _put_doubles(rows, len(template) - 24, values)
    return rows


def criteria_rows(stamps_ns, frame, ratio, gamma_dot, force):
    """
    CDR of many criteria ``sensor_msgs/JointState`` (as :func:`criteria_cdr`).

    Parameters
    ----------
    stamps_ns : ndarray of int, shape (m,)
    frame : bytes
    ratio, gamma_dot, force : ndarray, shape (m, joints)

    Returns
    -------
    ndarray of uint8, shape (m, length)

    """
    template, offsets = _criteria_template(frame)
    rows = _template_rows(template, len(stamps_ns))
    rows[:, 4:12] = _stamp_columns(stamps_ns)
    for offset, values in zip(offsets, (ratio, gamma_dot, force)):
        _put_doubles(rows, offset, values)
    return rows
