"""
A recording: the MCAP files of a bare file or a bag directory, read in one pass each.

Every intact chunk of a (possibly truncated or damaged) file is read through
:func:`io.mcap_reader.iter_messages`; damaged chunks are skipped and listed. The
``damaged`` lists the functions take receive ``(file, offset, reason)`` of every skipped
file, chunk or record (offset None for a count of more places).
"""

import functools
import pathlib
import struct

from .bag_files import bag_files
from .cdr import parse_joint_state
from .mcap_reader import iter_messages, map_file, Salvage
from .mcap_records import message_fields, MESSAGE_HEAD, MESSAGE_HEAD_SIZE
from ..errors import McapFileError
from ..names import JOINT_STATE

# A channel of the wanted type is probed for the crank joint in at most this many messages.
JOINT_PROBE_MESSAGES = 1000


def recording_files(path, damaged=None):
    """
    List the MCAP files of a bare file or a bag directory (in split order).

    Parameters
    ----------
    path : str or os.PathLike
        ``.mcap`` file or bag directory (only its regular files inside it,
        :func:`.bag_files.bag_files`).
    damaged : list, optional
        Receives (entry, None, reason) of every directory entry left out.

    Returns
    -------
    list of pathlib.Path

    """
    path = pathlib.Path(path)
    if path.is_dir():
        skipped = []
        files = bag_files(path, skipped)
        if damaged is not None:
            damaged.extend((str(entry), None, reason) for entry, reason in skipped)
        if not files:
            raise ValueError(f'`input`: no .mcap files in {path}')
        return files
    if not path.exists():
        raise ValueError(f'`input`: no such file or directory: {path}')
    return [path]


def _intact_messages(file, salvage, damaged):
    """
    Yield ``(records, body, stop)`` of every intact message of one file: the one read loop.

    Parameters
    ----------
    file : pathlib.Path
        One MCAP file (a file that is not MCAP is reported and yields nothing).
    salvage : Salvage
        Filled with the file's schemas and channels as reading goes on.
    damaged : list or None
        Receives the skipped places once the file is read.

    """
    try:
        buffer = map_file(file)
    except McapFileError as exc:
        if damaged is not None:
            damaged.append((str(file), 0, str(exc)))
        return
    try:
        yield from iter_messages(buffer, salvage)
    finally:
        buffer.close()
        if damaged is not None:
            damaged.extend((str(file), offset, reason) for offset, reason in salvage.damaged)
            hidden = salvage.damaged_count - len(salvage.damaged)
            if hidden:
                damaged.append((str(file), None, f'{hidden} more damaged places'))


def iter_recording(path, topics=None, damaged=None):
    """
    Messages of a recording, file by file in file order, including truncated files.

    Parameters
    ----------
    path : str or os.PathLike
        ``.mcap`` file or bag directory.
    topics : collection of str or None
        Only these topics (None: all).
    damaged : list, optional
        Receives (file, offset, reason) of every skipped file, chunk or record.

    Yields
    ------
    (topic, type_name, log_time_ns, publish_time_ns, data)

    """
    for file in recording_files(path, damaged):
        salvage = Salvage()
        for records, body, stop in _intact_messages(file, salvage, damaged):
            channel_id, _, log_time, publish_time, data = message_fields(records, body, stop)
            channel = salvage.channels.get(channel_id)
            if channel is None or channel.message_encoding != 'cdr':
                continue
            if topics is not None and channel.topic not in topics:
                continue
            schema = salvage.schemas.get(channel.schema_id)
            yield (channel.topic, schema.name if schema else '', log_time, publish_time, data)


def _file_messages(file, wanted, keep_rest=None, damaged=None):
    """
    Intact messages of one (possibly truncated or damaged) MCAP file, read in one pass.

    Parameters
    ----------
    file : pathlib.Path
        One MCAP file.
    wanted : callable
        ``wanted(topic, type_name)``: keep the payloads of this channel's messages.
    keep_rest : callable, optional
        ``keep_rest(data)``: the message carries what replay looks for. A wanted channel is
        kept from its start once one of its first ``JOINT_PROBE_MESSAGES`` messages does;
        if none does, only those are kept.
    damaged : list, optional
        Receives (file, offset, reason) of every skipped file, chunk or record.

    Returns
    -------
    counts : dict
        Topic -> [type name, message count] of every CDR channel with messages.
    kept : dict
        Topic -> list of (log_time_ns, publish_time_ns, data) of the wanted channels.

    """
    counts, kept, states = {}, {}, {}
    salvage = Salvage()
    for records, body, stop in _intact_messages(file, salvage, damaged):
        channel_id, _, log_time, publish_time = MESSAGE_HEAD.unpack_from(records, body)
        channel = salvage.channels.get(channel_id)
        state = states.get(channel_id)
        if state is None or state[0] is not channel:
            state = states[channel_id] = _channel_state(channel, salvage, wanted,
                                                        keep_rest, counts, kept)
        entry, store = state[1], state[2]
        if entry is None:
            continue
        entry[1] += 1
        if store is None:
            continue
        data = records[body + MESSAGE_HEAD_SIZE:stop]
        store.append((log_time, publish_time, data))
        if state[3] is not None:     # still probing for the joint
            if keep_rest(data):
                state[3] = None
            else:
                state[3] -= 1
                if state[3] == 0:
                    state[2] = None
    return {topic: entry for topic, entry in counts.items() if entry[1]}, kept


def _channel_state(channel, salvage, wanted, keep_rest, counts, kept):
    # [channel, counts entry (None: not CDR), kept list (None: not kept), probes left].
    if channel is None or channel.message_encoding != 'cdr':
        return [channel, None, None, None]
    schema = salvage.schemas.get(channel.schema_id)
    type_name = schema.name if schema else ''
    entry = counts.setdefault(channel.topic, [type_name, 0])
    if not wanted(channel.topic, type_name):
        return [channel, entry, None, None]
    probes = None if keep_rest is None else JOINT_PROBE_MESSAGES
    return [channel, entry, kept.setdefault(channel.topic, []), probes]


def has_joint(data, joint_name):
    """
    Tell whether JointState CDR bytes carry a position for a joint (False if malformed).

    Parameters
    ----------
    data : bytes
        CDR of a ``sensor_msgs/JointState``.
    joint_name : bytes
        UTF-8 name of the joint.

    Returns
    -------
    bool

    """
    try:
        return parse_joint_state(data, joint_name)[1] is not None
    except (struct.error, IndexError, ValueError, OverflowError):
        return False


def scan_recording(path, keep_type=JOINT_STATE, topic=None, joint_name=None, damaged=None):
    """
    Topics and the messages of one type of a recording, in one pass over its files.

    Parameters
    ----------
    path : str or os.PathLike
        ``.mcap`` file or bag directory.
    keep_type : str
        Keep the messages of the topics of this type ...
    topic : str, optional
        ... only of this topic ...
    joint_name : str, optional
        ... or (no ``topic``) only of topics with this joint in one of their first
        ``JOINT_PROBE_MESSAGES`` messages (of the others only those).
    damaged : list, optional
        Receives (file, offset, reason) of every skipped file, chunk or record.

    Returns
    -------
    counts : dict
        Topic -> [type name, message count] (CDR channels with messages).
    kept : dict
        Topic -> list of (log_time_ns, publish_time_ns, data) of the kept topics.

    """
    def wanted(name, type_name):
        return type_name == keep_type and (topic is None or name == topic)

    keep_rest = None
    if topic is None and joint_name is not None:
        keep_rest = functools.partial(has_joint, joint_name=joint_name.encode())
    counts, kept = {}, {}
    for file in recording_files(path, damaged):
        file_counts, file_kept = _file_messages(file, wanted, keep_rest, damaged)
        for topic_name, (type_name, count) in file_counts.items():
            counts.setdefault(topic_name, [type_name, 0])[1] += count
        for topic_name, messages in file_kept.items():
            kept.setdefault(topic_name, []).extend(messages)
    return counts, kept


def choose_input_topic(path, joint_name, topic=None, scan=None):
    """
    Find the JointState topic carrying the crank joint (``topic`` if given, checked).

    Parameters
    ----------
    path : str or os.PathLike
        ``.mcap`` file or bag directory (named in errors; read if ``scan`` is None).
    joint_name : str
        The crank joint.
    topic : str, optional
        The topic the user chose.
    scan : tuple, optional
        :func:`scan_recording` of ``path`` if already done (the file is read once).

    Returns
    -------
    str

    """
    counts, kept = scan_recording(path) if scan is None else scan
    topics = {name: tuple(value) for name, value in counts.items()}
    if topic is not None:
        if topic not in topics:
            raise ValueError(f'`--topic` {topic} is not in the recording (topics: '
                             f'{", ".join(sorted(topics))})')
        if topics[topic][0] != JOINT_STATE:
            raise ValueError(f'`--topic` {topic} is {topics[topic][0]}, not {JOINT_STATE}')
        return topic
    candidates = []
    name_bytes = joint_name.encode()
    for name, (type_name, _) in sorted(topics.items()):
        if type_name != JOINT_STATE or not kept.get(name):
            continue
        # The joint may first appear after other messages (bounded probe, as scan_recording).
        if any(has_joint(data, name_bytes) for _, _, data in kept[name][:JOINT_PROBE_MESSAGES]):
            candidates.append(name)
    if not candidates:
        raise ValueError(f'no {JOINT_STATE} topic with joint {joint_name!r} in {path} '
                         f'(topics: {", ".join(sorted(topics)) or "none"})')
    if len(candidates) > 1:
        raise ValueError(f'several JointState topics carry {joint_name!r} '
                         f'({", ".join(candidates)}): choose one with --topic')
    return candidates[0]


def damage_note(damaged):
    """
    Describe skipped damage for an error message: ' (N damaged places ...)', or ''.

    Parameters
    ----------
    damaged : list of (file, offset, reason)
        What the reader skipped.

    Returns
    -------
    str

    """
    if not damaged:
        return ''
    file, offset, reason = damaged[0]
    where = '' if offset is None else f' at offset {offset}'
    return f' ({len(damaged)} damaged places skipped; first in {file}{where}: {reason})'
