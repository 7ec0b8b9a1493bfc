"""
CDR (XCDR1) bytes: the one alignment rule, the JointState reader and the message walker.

rclpy's Python message classes cost 10-20 us to build and as much to serialise; at 1 kHz with
recording that is a large share of the node's time. :func:`parse_joint_state` reads a
``sensor_msgs/JointState`` directly (the node's outputs are written by :mod:`.output_cdr`).

:func:`walk_message` walks any message object's fields (``SLOT_TYPES``) in CDR order for a
:class:`CdrWriter` (the bytes, zeroed padding: :func:`serialize_message`) or any target with
the same four methods (the tests' sizer counts the exact length and where the padding lies).
Alignment (:func:`align`) counts from the end of the 4-byte encapsulation header.
"""

import struct

from rosidl_parser import definition

from ..errors import MalformedCdr

CDR_LE = b'\x00\x01\x00\x00'  # encapsulation header: plain CDR, little endian
ENCAPSULATION_SIZE = len(CDR_LE)


# Input bounds of a JointState (checked against the declared lengths before anything is
# read or allocated, so crafted counts cannot size an allocation).
MAX_MESSAGE_BYTES = 1 << 20   # 1 MiB: a JointState of MAX_JOINTS joints is under 300 kB
MAX_JOINTS = 1024             # names and each of position, velocity, effort
MAX_NAME_BYTES = 256          # frame_id and each joint name, UTF-8, without the NUL
_ENCAPSULATIONS = {b'\x00\x00': '>', b'\x00\x01': '<'}   # plain CDR big / little endian


def align(offset, size):
    """
    Advance a buffer offset to the next multiple of ``size`` after the encapsulation header.

    Parameters
    ----------
    offset : int
        Offset into the whole buffer, the 4-byte encapsulation header included.
    size : int
        Alignment [bytes] (the size of the value, at most 8).

    Returns
    -------
    int

    """
    return offset + (-(offset - ENCAPSULATION_SIZE)) % size


def _read_count(data, offset, endian, what, limit):
    """Read a uint32 length at ``offset`` (aligned to 4), checked against ``limit``."""
    offset = align(offset, 4)
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
        offset = align(offset, 8)
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
    return _read_joint_state(data, joint_name)[:3]


def _read_joint_state(data, joint_name, with_layout=False):
    """parse_joint_state's three values and (``with_layout``) the :class:`JointLayout` or None."""
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
    positions, position_end = _read_doubles(data, offset, endian, 'position')
    velocities, velocity_end = _read_doubles(data, position_end, endian, 'velocity')
    efforts, effort_end = _read_doubles(data, velocity_end, endian, 'effort')
    stamp_ns = sec * 1_000_000_000 + nanosec
    if index is None or index >= len(positions):
        return stamp_ns, None, None, None
    velocity = velocities[index] if index < len(velocities) else None
    if not with_layout:
        return stamp_ns, positions[index], velocity, None
    starts = [end - 8 * len(values) for end, values in
              ((position_end, positions), (velocity_end, velocities), (effort_end, efforts))]
    layout = JointLayout(data, endian, starts[0] + 8 * index,
                         None if velocity is None else starts[1] + 8 * index,
                         ((12, starts[0]), (position_end, starts[1]), (velocity_end, starts[2])))
    return stamp_ns, positions[index], velocity, layout


_STAMP_AND_VALUE = {endian: (struct.Struct(endian + 'iI'), struct.Struct(endian + 'd'))
                    for endian in _ENCAPSULATIONS.values()}


class JointLayout:
    """
    Where one joint's values lie in a JointState's CDR, and the bytes that put them there.

    Every offset and length of the message follows from its size, byte order, frame id,
    names and the three arrays' length fields (their padding included): a message with the
    same bytes there has the joint's position and velocity at the same offsets and passes
    every bound check this one passed. Those bytes are kept as (start, end, bytes) runs: from
    the frame id to the first position, and each of the velocity's and effort's length fields
    with the padding after it.
    """

    def __init__(self, data, endian, position_at, velocity_at, runs):
        self.size, self.encapsulation = len(data), bytes(data[:2])
        self.stamp, self.value = _STAMP_AND_VALUE[endian]
        self.position_at, self.velocity_at = position_at, velocity_at
        self.runs = tuple((start, end, bytes(data[start:end])) for start, end in runs)

    def read(self, data):
        """
        Stamp, position and velocity of a message with this layout, as parsing gives them.

        None if ``data`` has another layout or an impossible stamp (then parse it).
        """
        if len(data) != self.size or data[:2] != self.encapsulation:
            return None
        (start, end, fixed), (start2, end2, fixed2), (start3, end3, fixed3) = self.runs
        if data[start:end] != fixed or data[start2:end2] != fixed2 \
                or data[start3:end3] != fixed3:
            return None
        sec, nanosec = self.stamp.unpack_from(data, 4)
        if nanosec >= 1_000_000_000:
            return None
        velocity = (None if self.velocity_at is None
                    else self.value.unpack_from(data, self.velocity_at)[0])
        return (sec * 1_000_000_000 + nanosec, self.value.unpack_from(data, self.position_at)[0],
                velocity)


class JointStateReader:
    """
    :func:`parse_joint_state` for a stream of messages: the same results, checked as much.

    A publisher's JointStates keep one layout (frame, names and array lengths); only the
    stamp and the values change. The reader parses a message in full only when its layout
    differs from the last one parsed (compared byte for byte, :class:`JointLayout`): at
    1 kHz that saves most of the parse (about 1 us instead of 5-10 us).

    Parameters
    ----------
    joint_name : bytes
        UTF-8 name of the joint.

    """

    def __init__(self, joint_name):
        self.joint_name = joint_name
        self.full_parses = 0
        self._layout = None

    def __call__(self, data):
        """Return (stamp_ns, position, velocity) as :func:`parse_joint_state` does."""
        if self._layout is not None:
            values = self._layout.read(data)
            if values is not None:
                return values
        self.full_parses += 1
        stamp_ns, position, velocity, self._layout = _read_joint_state(data, self.joint_name,
                                                                       with_layout=True)
        return stamp_ns, position, velocity


# -- any message object, walked field by field ------------------------------------------------

# IDL basic types: XCDR1 size (alignment = size, at most 8) and struct code (None: not written).
_BASIC_TYPES = {
    'boolean': (1, '?'), 'octet': (1, 'B'), 'char': (1, 'B'), 'int8': (1, 'b'),
    'uint8': (1, 'B'), 'int16': (2, 'h'), 'uint16': (2, 'H'), 'wchar': (2, None),
    'int32': (4, 'i'), 'uint32': (4, 'I'), 'float': (4, 'f'), 'int64': (8, 'q'),
    'uint64': (8, 'Q'), 'double': (8, 'd'), 'long double': (16, None),
}


def _basic_type(typename):
    try:
        return _BASIC_TYPES[typename]
    except KeyError:
        raise ValueError(f'CDR of {typename!r} is not supported') from None


def _byte_value(value):
    if isinstance(value, (bytes, bytearray)):
        return value[0]
    return ord(value) if isinstance(value, str) else value


class CdrWriter:
    """Walk target that writes the CDR bytes (little endian, zeroed padding)."""

    def __init__(self):
        self.out = bytearray(CDR_LE)

    def pad(self, size):
        """Write zeros up to the next multiple of ``size``."""
        self.out += bytes(align(len(self.out), size) - len(self.out))

    def count(self, value):
        """Write a uint32 length (of a sequence or string)."""
        self.pad(4)
        self.out += struct.pack('<I', value)

    def string(self, text):
        """Write a string: length with the NUL, UTF-8 bytes, NUL."""
        data = text.encode('utf-8')
        self.count(len(data) + 1)
        self.out += data + b'\x00'

    def basics(self, typename, values):
        """Write values of one basic type, aligned to its size."""
        size, code = _basic_type(typename)
        if code is None:
            raise ValueError(f'CDR of {typename!r} is not supported')
        if typename in ('octet', 'char'):   # rclpy holds bytes of length 1, or str
            values = [_byte_value(v) for v in values]
        self.pad(min(size, 8))
        self.out += struct.pack(f'<{len(values)}{code}', *values)


def walk_message(target, message):
    """
    Walk a message object's fields in CDR order for a :class:`CdrWriter` or a sizer.

    Parameters
    ----------
    target : CdrWriter or an object with its pad, count, string and basics methods
        What each field is given to.
    message : ROS 2 message instance
        Walked through its class's ``__slots__`` and ``SLOT_TYPES``.

    """
    cls = type(message)
    for slot, member_type in zip(cls.__slots__, cls.SLOT_TYPES):
        _walk_value(target, member_type, getattr(message, slot))


def _walk_value(target, member_type, value):
    if isinstance(member_type, definition.BasicType):
        target.basics(member_type.typename, (value,))
    elif isinstance(member_type, definition.AbstractWString):
        raise ValueError('CDR of wstring is not supported')
    elif isinstance(member_type, definition.AbstractString):
        target.string(value)
    elif isinstance(member_type, definition.NamespacedType):
        walk_message(target, value)
    elif isinstance(member_type, definition.AbstractNestedType):
        if isinstance(member_type, definition.AbstractSequence):
            target.count(len(value))
        element = member_type.value_type
        if isinstance(element, definition.BasicType):
            if len(value):
                target.basics(element.typename, value)
        else:
            for item in value:
                _walk_value(target, element, item)
    else:
        raise ValueError(f'CDR of {type(member_type).__name__} is not supported')


def serialize_message(message):
    """
    Return the CDR bytes of a message object, walking its fields in Python (zeroed padding).

    Exactly as long as the DDS payload, without rclpy's serialiser (importing rclpy and the
    type support costs about 0.1 s, more than a replay writes in).

    Parameters
    ----------
    message : ROS 2 message instance
        Of a type without ``wstring`` fields.

    Returns
    -------
    bytes

    """
    writer = CdrWriter()
    walk_message(writer, message)
    return bytes(writer.out)
