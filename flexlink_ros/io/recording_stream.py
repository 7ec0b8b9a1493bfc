"""
A recording read in bounded memory: its topics surveyed, then one topic's messages in blocks.

:func:`survey_recording` counts the messages of every topic and keeps only the first
``JOINT_PROBE_MESSAGES`` of each JointState topic (what :func:`.recording.choose_input_topic`
looks at); :func:`survey_summaries` gives the same from the files' summaries (their statistics'
per-channel counts) and their first chunks alone, where every file has an intact one, so that
a whole recording is read once, not twice; :func:`iter_topic_messages` then yields the
messages of the chosen topic in blocks of at most a given count. They take the messages of a
chunk together (their heads read with numpy), through the same salvaging reader as the rest
(:func:`.mcap_reader.iter_message_units`: damaged chunks are skipped and listed). Memory: one
decompressed chunk (at most ``mcap_records.MAX_CHUNK_BYTES``), one block of messages and
``RELEASE_BYTES`` of the mapped file.
"""

import mmap

import numpy as np

from .mcap_reader import iter_message_units, map_file, read_summary, Salvage
from .mcap_records import MESSAGE_HEAD_SIZE
from .recording import JOINT_PROBE_MESSAGES, recording_files
from ..errors import McapFileError
from ..names import JOINT_STATE

# The pages of the mapped file already read are let go every this many bytes.
RELEASE_BYTES = 8 << 20
# A message record's body starts with these fields (MCAP specification), packed.
_MESSAGE_HEAD = np.dtype([('channel', '<u2'), ('sequence', '<u4'), ('log', '<u8'),
                          ('publish', '<u8')])


def _file_units(file, damaged):
    """Yield ``(salvage, records, messages)`` of each intact unit of one file."""
    try:
        buffer = map_file(file)
    except McapFileError as exc:
        if damaged is not None:
            damaged.append((str(file), 0, str(exc)))
        return
    salvage = Salvage()
    released = 0
    try:
        for records, messages in iter_message_units(buffer, salvage):
            yield salvage, records, messages
            # What lies before this unit is read: let its pages go (the mapping would
            # otherwise hold the whole file resident by the end).
            done = salvage.readable_bytes - salvage.readable_bytes % mmap.PAGESIZE
            if done - released >= RELEASE_BYTES:
                buffer.madvise(mmap.MADV_DONTNEED, released, done - released)
                released = done
    finally:
        buffer.close()
        if damaged is not None:
            damaged.extend((str(file), offset, reason) for offset, reason in salvage.damaged)
            hidden = salvage.damaged_count - len(salvage.damaged)
            if hidden:
                damaged.append((str(file), None, f'{hidden} more damaged places'))


def message_heads(records, messages):
    """Return the heads (channel, sequence, log, publish) of messages in ``records``."""
    starts = np.fromiter((start for start, _ in messages), dtype=np.int64, count=len(messages))
    view = np.frombuffer(records, dtype=np.uint8)
    heads = view[starts[:, None] + np.arange(MESSAGE_HEAD_SIZE)]
    del view      # no view of the file may outlive this call (it is unmapped after reading)
    return heads.view(_MESSAGE_HEAD)[:, 0]


def _topics_of(salvage, channel_ids):
    """{channel id: (topic, type name)} of the CDR channels among ``channel_ids``."""
    found = {}
    for channel_id in channel_ids:
        channel = salvage.channels.get(channel_id)
        if channel is None or channel.message_encoding != 'cdr':
            continue
        schema = salvage.schemas.get(channel.schema_id)
        found[channel_id] = (channel.topic, schema.name if schema else '')
    return found


def survey_recording(path, topic=None, damaged=None):
    """
    Count the messages of every topic; keep the first few of the JointState topics.

    Parameters
    ----------
    path : str or os.PathLike
        ``.mcap`` file or bag directory.
    topic : str, optional
        Keep messages of this topic only (none are needed to check a chosen topic).
    damaged : list, optional
        Receives (file, offset, reason) of every skipped file, chunk or record.

    Returns
    -------
    counts : dict
        Topic -> [type name, message count] (CDR channels with messages).
    kept : dict
        JointState topic -> list of (log_time_ns, publish_time_ns, data) of its first
        ``JOINT_PROBE_MESSAGES`` messages (of ``topic`` only, if given: none).

    """
    counts, kept = {}, {}
    for file in recording_files(path, damaged):
        for salvage, records, messages in _file_units(file, damaged):
            heads = message_heads(records, messages)
            ids, first, numbers = np.unique(heads['channel'], return_index=True,
                                            return_counts=True)
            order = np.argsort(first, kind='stable')      # topics in order of first message
            topics = _topics_of(salvage, ids[order].tolist())
            for channel_id, number in zip(ids[order].tolist(), numbers[order].tolist()):
                if channel_id not in topics:
                    continue
                name, type_name = topics[channel_id]
                counts.setdefault(name, [type_name, 0])[1] += number
                if type_name == JOINT_STATE and topic is None:
                    _probe(kept.setdefault(name, []), heads, records, messages, channel_id)
    return counts, kept


def survey_summaries(path, topic=None):
    """
    :func:`survey_recording` from the files' summaries, reading only the first chunks.

    The topic counts come from each file's summary (its statistics' per-channel message
    counts), the kept messages from the chunks up to the first ``JOINT_PROBE_MESSAGES`` of
    every JointState topic. Nothing damaged is listed: the reading that follows does it.

    Returns
    -------
    (counts, kept) or None
        As :func:`survey_recording`; None when a file has no intact summary with
        per-channel counts (the recording must then be surveyed whole).

    """
    counts, files = {}, recording_files(path)
    for file in files:
        salvage = Salvage()
        try:
            buffer = map_file(file)
        except McapFileError:
            return None
        try:
            read_summary(buffer, salvage)
        finally:
            buffer.close()
        if salvage.channel_counts is None:
            return None
        topics = _topics_of(salvage, sorted(salvage.channel_counts))
        for channel_id, number in salvage.channel_counts.items():
            if channel_id in topics and number:
                name, type_name = topics[channel_id]
                counts.setdefault(name, [type_name, 0])[1] += number
    wanted = {name: min(number, JOINT_PROBE_MESSAGES) for name, (type_name, number)
              in counts.items() if type_name == JOINT_STATE and topic is None}
    return counts, _first_messages(files, wanted)


def _first_messages(files, wanted):
    """{topic: its first messages} of JointState topics, read until each has its count."""
    kept = {}
    for file in files:
        units = _file_units(file, None)
        try:
            for salvage, records, messages in units:
                if all(len(kept.get(name, ())) >= count for name, count in wanted.items()):
                    return kept
                heads = message_heads(records, messages)
                for channel_id, (name, type_name) in _topics_of(
                        salvage, sorted(set(heads['channel'].tolist()))).items():
                    if name in wanted and type_name == JOINT_STATE:
                        _probe(kept.setdefault(name, []), heads, records, messages, channel_id)
        finally:
            units.close()
    return kept


def _probe(store, heads, records, messages, channel_id):
    """Add the channel's messages of a unit to ``store`` up to JOINT_PROBE_MESSAGES."""
    room = JOINT_PROBE_MESSAGES - len(store)
    if room <= 0:
        return
    for n in np.flatnonzero(heads['channel'] == channel_id)[:room].tolist():
        start, end = messages[n]
        store.append((int(heads['log'][n]), int(heads['publish'][n]),
                      bytes(records[start + MESSAGE_HEAD_SIZE:end])))


def iter_topic_messages(path, topic, type_name=JOINT_STATE, block=65536, damaged=None):
    """
    Yield the messages of one topic in file order, in blocks of at most ``block``.

    Parameters
    ----------
    path : str or os.PathLike
        ``.mcap`` file or bag directory.
    topic : str
        The topic (its CDR channels of ``type_name``).
    type_name : str
        The topic's message type.
    block : int
        Messages per block (the last may hold fewer).
    damaged : list, optional
        Receives (file, offset, reason) of every skipped file, chunk or record.

    Yields
    ------
    (log_ns, publish_ns, data) : (ndarray of int64, ndarray of int64, list of bytes)

    """
    pending = ([], [], [])
    held = 0
    for file in recording_files(path, damaged):
        for salvage, records, messages in _file_units(file, damaged):
            heads = message_heads(records, messages)
            wanted = [channel_id for channel_id, found in _topics_of(
                salvage, sorted(set(heads['channel'].tolist()))).items()
                if found == (topic, type_name)]
            rows = np.flatnonzero(np.isin(heads['channel'], wanted))
            for first in range(0, rows.size, block):
                chosen = rows[first:first + block]
                pending[0].append(heads['log'][chosen].astype(np.int64))
                pending[1].append(heads['publish'][chosen].astype(np.int64))
                pending[2].extend(bytes(records[messages[n][0] + MESSAGE_HEAD_SIZE:messages[n][1]])
                                  for n in chosen.tolist())
                held += chosen.size
                while held >= block:
                    yield _take(pending, block)
                    held -= block
    if held:
        yield _take(pending, held)


def _take(pending, count):
    """Remove and return the first ``count`` messages of the pending block parts."""
    log, publish = np.concatenate(pending[0]), np.concatenate(pending[1])
    data = pending[2][:count]
    del pending[2][:count]
    pending[0][:] = [log[count:]]
    pending[1][:] = [publish[count:]]
    return log[:count], publish[:count], data
