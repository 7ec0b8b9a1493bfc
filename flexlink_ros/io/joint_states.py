"""
One joint's stamps, positions and velocities from many JointState CDR payloads, as columns.

Messages of one publisher share a byte layout: the first usable message's layout
(:func:`joint_state_layout`) reads every message like it at once with numpy; the others are
read one by one with :func:`io.cdr.parse_joint_state`, the one scalar reader.
"""

import math
import struct

import numpy as np

from .cdr import align, parse_joint_state
from .recording import choose_input_topic, damage_note, scan_recording
from .recording_stream import iter_topic_messages

# Errors of a payload that is not a readable JointState.
UNREADABLE = (struct.error, IndexError, ValueError, OverflowError)
# Payloads tried for a layout before reading all of them one by one.
LAYOUT_PROBES = 16


def joint_state_layout(data, joint_name):
    """
    Byte layout of a little-endian JointState CDR message, for reading many like it at once.

    Parameters
    ----------
    data : bytes
        CDR of a ``sensor_msgs/JointState``.
    joint_name : bytes
        UTF-8 name of the joint.

    Returns
    -------
    (fixed, position, velocity) or None
        ``fixed``: byte ranges that messages of the same layout share (encapsulation, frame
        id, joint names, array lengths); the rest is the stamp, the values and alignment
        padding, which serialisers need not zero (rclpy's does not). ``position`` /
        ``velocity``: offsets of the joint's values (velocity None if absent). None if the
        message is not little endian or lacks the joint.

    """
    if len(data) < 16 or data[:4] != b'\x00\x01\x00\x00':
        return None
    fixed = [(0, 4)]
    offset = 12
    (length,) = struct.unpack_from('<I', data, offset)
    fixed.append((offset, offset + 4 + length))                 # frame id
    offset = align(offset + 4 + length, 4)
    (count,) = struct.unpack_from('<I', data, offset)
    fixed.append((offset, offset + 4))
    offset += 4
    index = None
    for k in range(count):
        offset = align(offset, 4)
        (length,) = struct.unpack_from('<I', data, offset)
        fixed.append((offset, offset + 4 + length))             # joint name
        if index is None and data[offset + 4:offset + 4 + max(length - 1, 0)] == joint_name:
            index = k
        offset += 4 + length
    starts, sizes = [], []
    for _ in range(3):   # position, velocity, effort
        offset = align(offset, 4)
        (size,) = struct.unpack_from('<I', data, offset)
        fixed.append((offset, offset + 4))
        offset += 4
        if size:
            offset = align(offset, 8)
        starts.append(offset)
        sizes.append(size)
        offset += 8 * size
    # What follows the last array is padding to the serialiser's alignment (at most 8).
    if index is None or index >= sizes[0] or not 0 <= len(data) - offset < 8:
        return None
    velocity = starts[1] + 8 * index if index < sizes[1] else None
    return fixed, starts[0] + 8 * index, velocity


def _first_layout(payloads, joint_name):
    """(layout, its payload) of the first of the leading payloads that has one, or None."""
    for payload in payloads[:LAYOUT_PROBES]:
        try:
            layout = joint_state_layout(payload, joint_name)
        except UNREADABLE:
            layout = None     # not a JointState after all: read one by one
        if layout is not None:
            return layout, payload
    return None


def _column(rows, offset, dtype):
    """Read the value of type ``dtype`` at byte ``offset`` of every row."""
    return rows[:, offset:offset + np.dtype(dtype).itemsize].copy().view(dtype)[:, 0]


def _read_in_bulk(payloads, layout, reference, columns):
    """Fill ``columns`` from the payloads of ``reference``'s layout; their indices."""
    ranges, position, velocity = layout
    size = len(reference)
    count = len(payloads)
    same = np.fromiter((len(p) == size for p in payloads), dtype=bool, count=count)
    chosen = np.flatnonzero(same)
    rows = np.frombuffer(b''.join([payloads[n] for n in chosen]),
                         dtype=np.uint8).reshape(chosen.size, size)
    fixed = np.zeros(size, dtype=bool)
    for first, stop in ranges:
        fixed[first:stop] = True
    expected = np.frombuffer(reference, dtype=np.uint8)[fixed]
    match = np.all(rows[:, fixed] == expected, axis=1)
    chosen, rows = chosen[match], rows[match]
    stamps, angles, speeds, valid, has_speed = columns
    valid[chosen] = True
    sec = _column(rows, 4, '<i4').astype(np.int64)
    nanosec = _column(rows, 8, '<u4').astype(np.int64)
    stamps[chosen] = sec * 1_000_000_000 + nanosec
    angles[chosen] = _column(rows, position, '<f8')
    if velocity is not None:
        speeds[chosen] = _column(rows, velocity, '<f8')
        has_speed[chosen] = True
    return chosen


def _read_one_by_one(payloads, rows, joint_name, columns):
    """Fill ``columns`` at ``rows`` with :func:`io.cdr.parse_joint_state`."""
    stamps, angles, speeds, valid, has_speed = columns
    for n in rows:
        try:
            stamp, angle, speed = parse_joint_state(payloads[n], joint_name)
        except UNREADABLE:
            continue
        if angle is None:
            continue
        valid[n] = True
        stamps[n], angles[n] = stamp, angle
        if speed is not None:
            speeds[n], has_speed[n] = speed, True


def parse_crank_states(payloads, joint_name):
    """
    Stamp [ns], angle and speed (NaN if absent) of the joint in many JointState payloads.

    Messages with the first usable message's byte layout (the usual case: one publisher) are
    read together with numpy; the others one by one (:func:`io.cdr.parse_joint_state`).

    Parameters
    ----------
    payloads : sequence of bytes
        JointState CDR messages.
    joint_name : bytes
        UTF-8 name of the joint.

    Returns
    -------
    stamps (int64), angles, speeds : ndarray, shape (m,)
    valid : ndarray of bool
        The joint has a position (else the values are meaningless).
    has_speed : ndarray of bool
        The message has a velocity for the joint.

    """
    count = len(payloads)
    columns = (np.zeros(count, dtype=np.int64), np.full(count, math.nan),
               np.full(count, math.nan), np.zeros(count, dtype=bool),
               np.zeros(count, dtype=bool))
    fast = np.zeros(count, dtype=bool)
    found = _first_layout(payloads, joint_name)
    if found is not None:
        fast[_read_in_bulk(payloads, *found, columns)] = True
    _read_one_by_one(payloads, np.flatnonzero(~fast).tolist(), joint_name, columns)
    return columns


def read_crank_samples(path, topic, joint_name, scan=None):
    """
    Read the crank samples of one topic.

    Parameters
    ----------
    path : str or os.PathLike
        ``.mcap`` file or bag directory.
    topic : str
        The JointState topic.
    joint_name : str
        The crank joint.
    scan : tuple, optional
        :func:`io.recording.scan_recording` of ``path`` if already done (read once).

    Returns
    -------
    dict
        :func:`crank_samples` of every message of the topic.

    """
    if scan is None:
        scan = scan_recording(path, topic=topic)
    messages = scan[1].get(topic, [])
    if not messages:
        return crank_samples(np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64), [],
                             joint_name)
    log_ns, publish_ns, payloads = zip(*messages)
    return crank_samples(np.array(log_ns, dtype=np.int64), np.array(publish_ns, dtype=np.int64),
                         payloads, joint_name)


def read_input_samples(path, topic, joint_name, damaged):
    """
    Find a recording's input topic and read all its crank samples (in memory).

    Parameters
    ----------
    path : str or os.PathLike
        ``.mcap`` file or bag directory.
    topic : str or None
        The input topic (None: the one carrying the joint).
    joint_name : str
        The crank joint.
    damaged : list
        Receives (file, offset, reason) of what the reader skipped.

    Returns
    -------
    topic : str
    samples : dict
        :func:`read_crank_samples`.
    messages : list of (log_ns, publish_ns, data)
        Every message of the topic, usable or not, in file order.

    Raises
    ------
    ValueError
        No such topic, or no usable sample on it (with the reasons and the damage found).

    """
    scan = scan_recording(path, topic=topic, joint_name=joint_name, damaged=damaged)
    try:
        topic = choose_input_topic(path, joint_name, topic, scan)
        samples = read_crank_samples(path, topic, joint_name, scan)
        if not samples['data']:
            raise ValueError(f'no usable samples of joint {joint_name!r} on {topic}'
                             + ''.join(f'; {n} {why}'
                                       for why, n in samples['skipped_reasons'].items()))
    except ValueError as exc:
        raise ValueError(f'{exc}{damage_note(damaged)}') from None
    return topic, samples, scan[1].get(topic, [])


def iter_crank_samples(path, topic, joint_name, block=65536, damaged=None):
    """
    Read the crank samples of one topic a block of messages at a time (bounded memory).

    Parameters
    ----------
    path : str or os.PathLike
        ``.mcap`` file or bag directory.
    topic : str
        The JointState topic.
    joint_name : str
        The crank joint.
    block : int
        Messages per block.
    damaged : list, optional
        Receives (file, offset, reason) of every skipped file, chunk or record.

    Yields
    ------
    dict
        :func:`crank_samples` of each block of messages.

    """
    for log_ns, publish_ns, payloads in iter_topic_messages(path, topic, block=block,
                                                            damaged=damaged):
        yield crank_samples(log_ns, publish_ns, payloads, joint_name)


def crank_samples(log_ns, publish_ns, payloads, joint_name):
    """
    Return the usable crank samples among JointState messages, and why the others are not.

    Parameters
    ----------
    log_ns, publish_ns : ndarray of int64, shape (m,)
        Log and publish times of the messages [ns].
    payloads : sequence of bytes
        Their CDR.
    joint_name : str
        The crank joint.

    Returns
    -------
    dict
        'data' (list of bytes), 'log_ns', 'publish_ns', 'stamps_ns' (int64), 'angles',
        'speeds' (NaN where missing) of the usable messages, 'skipped' (count) and
        'skipped_reasons' ({reason: count}).

    """
    stamps, angles, speeds, valid, has_speed = parse_crank_states(payloads,
                                                                  joint_name.encode())
    usable = valid & np.isfinite(angles) & (stamps != 0) & (np.isfinite(speeds) | ~has_speed)
    chosen = np.flatnonzero(usable)
    return {'data': [payloads[n] for n in chosen.tolist()],
            'log_ns': np.asarray(log_ns, dtype=np.int64)[chosen],
            'publish_ns': np.asarray(publish_ns, dtype=np.int64)[chosen],
            'stamps_ns': stamps[chosen], 'angles': angles[chosen], 'speeds': speeds[chosen],
            'skipped': len(payloads) - chosen.size,
            'skipped_reasons': skip_reasons(payloads, valid, usable, joint_name.encode())}


def skip_reasons(payloads, valid, usable, joint_name):
    """
    Count why the unusable messages were skipped.

    Parameters
    ----------
    payloads : sequence of bytes
        JointState CDR messages.
    valid : ndarray of bool
        The joint has a position.
    usable : ndarray of bool
        The message is a usable sample.
    joint_name : bytes
        UTF-8 name of the joint.

    Returns
    -------
    dict
        {one-line reason: count}.

    """
    reasons = {}
    for n in np.flatnonzero(~usable).tolist():
        if valid[n]:
            reason = 'zero stamp or non-finite position or velocity'
        else:
            try:
                parse_joint_state(payloads[n], joint_name)
                reason = f'no position for joint {joint_name.decode()!r}'
            except UNREADABLE:
                reason = 'not a readable JointState (cut short or malformed)'
        reasons[reason] = reasons.get(reason, 0) + 1
    return reasons
