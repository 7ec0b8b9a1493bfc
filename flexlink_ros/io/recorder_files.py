"""
The files of a recording: created exclusively, started as rosbag2 starts them, split, finished.

Layout. A recording ``path`` ending in ``.mcap`` is one bare file. Any other ``path`` is a
rosbag2 bag directory holding ``<name>_0.mcap``, ``<name>_1.mcap``, ... (split by size and/or
duration) and a ``metadata.yaml`` (:mod:`flexlink_ros.io.bag_metadata`).

Never overwrite. ``path`` must not exist in any form: an existing file, bare ``.mcap``,
directory or symbolic link (even a dangling one) is refused, saying which. Files are created
exclusively (``O_CREAT | O_EXCL | O_NOFOLLOW``), so a path that appears between the check and
the creation is refused too, never clobbered or followed.
"""

import dataclasses
import os
import pathlib
import stat

import mcap
import numpy as np

from .mcap_writer import COMPRESSIONS, DEFAULT_ZSTD_LEVEL, McapFileWriter
from .msg_schema import message_definition, offered_qos_yaml, type_hash
from .packed_messages import PackedMessages
from .provenance import PROVENANCE_RECORD

# mcap.writer's LIBRARY_IDENTIFIER, without importing mcap.writer (which asks the installed
# packages' metadata for its version: about 40 ms of every replay's start).
LIBRARY = f'flexlink_ros recorder; mcap-python/{mcap.__version__}'
# Smallest split a live recording accepts (0: never split). Each split finishes a file
# (summary, indexes, metadata) and starts the next (header, schemas, channels): far below
# these a recorder fed at 1 kHz would do little but split, and fall behind.
MIN_SPLIT_BYTES = 1 << 20
MIN_SPLIT_DURATION_S = 1.0
# O_NOFOLLOW is POSIX; where it is missing O_EXCL alone still refuses a symlink.
_EXCLUSIVE_FLAGS = (os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, 'O_NOFOLLOW', 0)
                    | getattr(os, 'O_CLOEXEC', 0))


def refuse_existing(path):
    """
    Raise FileExistsError naming what ``path`` is, if anything is there (links not followed).

    Parameters
    ----------
    path : pathlib.Path
        Where a file or directory is to be created.

    """
    try:
        info = os.lstat(path)
    except FileNotFoundError:
        return
    if stat.S_ISLNK(info.st_mode):
        target = os.readlink(path)
        dangling = '' if os.path.exists(path) else ', dangling'
        kind = f'a symbolic link to {target}{dangling}'
    elif stat.S_ISDIR(info.st_mode):
        kind = 'a directory'
    elif stat.S_ISREG(info.st_mode):
        kind = f'a file of {info.st_size} bytes'
    else:
        kind = 'a special file'
    raise FileExistsError(f'{path} exists ({kind}); the recorder never overwrites or follows '
                          'links: choose a new path')


def make_directories(path):
    """
    Create ``path`` and its missing parents; return those created, outermost first.

    Parameters
    ----------
    path : pathlib.Path
        A directory.

    Returns
    -------
    list of pathlib.Path

    """
    missing = []
    while not os.path.lexists(path) and path != path.parent:
        missing.append(path)
        path = path.parent
    created = []
    for directory in reversed(missing):
        try:
            directory.mkdir()
        except FileExistsError:
            continue    # made meanwhile by someone else: not ours to remove
        created.append(directory)
    return created


def remove_directories(created):
    """
    Remove directories :func:`make_directories` created, innermost first, if still empty.

    Parameters
    ----------
    created : list of pathlib.Path
        Outermost first.

    """
    for directory in reversed(created):
        try:
            directory.rmdir()
        except OSError:     # not empty (someone wrote there meanwhile) or gone: left as is
            return


def create_exclusive(path, mode=0o644):
    """
    Open a new file for writing; fail if anything (even a dangling link) is at ``path``.

    Parameters
    ----------
    path : pathlib.Path
        The file to create.
    mode : int
        Its permission bits (less the umask).

    Returns
    -------
    binary file object

    """
    try:
        descriptor = os.open(path, _EXCLUSIVE_FLAGS, mode)
    except FileExistsError:
        refuse_existing(path)   # says what is there
        raise
    return os.fdopen(descriptor, 'wb')


@dataclasses.dataclass
class OpenFile:
    """The file being written: its stream, writer, ids and the log times of its messages."""

    path: pathlib.Path
    stream: object
    writer: McapFileWriter
    channel_ids: dict
    schema_ids: dict = dataclasses.field(default_factory=dict)
    first_log_ns: int = None
    last_log_ns: int = None
    message_count: int = 0
    counts_before: dict = dataclasses.field(default_factory=dict)   # topic counts at open

    def note(self, first_log_ns, last_log_ns, count):
        """Count ``count`` messages written with log times from first to last [ns]."""
        if self.first_log_ns is None:
            self.first_log_ns, self.last_log_ns = first_log_ns, last_log_ns
        else:
            self.first_log_ns = min(self.first_log_ns, first_log_ns)
            self.last_log_ns = max(self.last_log_ns, last_log_ns)
        self.message_count += count

    def entry(self, complete):
        """Describe the file for the bag metadata and status (``complete``: finished)."""
        return {'path': self.path, 'message_count': self.message_count,
                'first_log_ns': self.first_log_ns, 'last_log_ns': self.last_log_ns,
                'complete': complete}


@dataclasses.dataclass
class Topic:
    """A recorded topic: type, offered QoS, messages so far and its last sequence number."""

    name: str
    type_name: str
    qos_profiles: list
    message_count: int = 0
    sequence: int = 0   # of the last message (MCAP: per channel, uint32, rolls over to 0)

    def next_sequences(self, count):
        """Take the sequence numbers of the next ``count`` messages (1, 2, ... per topic)."""
        first, self.sequence = self.sequence + 1, self.sequence + count
        return np.arange(first, self.sequence + 1, dtype=np.uint64) % 2 ** 32


def batch_arguments(topics, messages, log_times_ns, publish_times_ns, known_topics):
    """
    Check write_batch's arguments: (topic names, topic index per message, log, publish).

    Parameters
    ----------
    topics : str or sequence of str
        One topic for every message, or the topic of each (of each column, for a
        :class:`.packed_messages.PackedMessages`).
    messages : sequence of bytes, or PackedMessages
        CDR bytes.
    log_times_ns : array-like of int, shape (n,)
        Log times [ns].
    publish_times_ns : array-like of int, shape (n,), or None
        Publish times [ns] (None: the log times).
    known_topics : container of str
        The declared topics.

    Returns
    -------
    names : list of str
    index : ndarray of intp, shape (n,)
    log, publish : ndarray of int64, shape (n,)

    """
    count = len(messages)
    if isinstance(topics, str):
        names, index = [topics], np.zeros(count, dtype=np.intp)
    elif isinstance(messages, PackedMessages):
        if len(topics) != len(messages.columns):
            raise ValueError(f'`topics` has {len(topics)} entries for '
                             f'{len(messages.columns)} columns')
        names = list(dict.fromkeys(topics))
        index = np.array([names.index(name) for name in topics],
                         dtype=np.intp)[messages.column_of]
    else:
        if len(topics) != count:
            raise ValueError(f'`topics` has {len(topics)} entries for {count} messages')
        names = list(dict.fromkeys(topics))
        lookup = {name: k for k, name in enumerate(names)}
        index = np.fromiter(map(lookup.__getitem__, topics), dtype=np.intp, count=count)
    for name in names:
        if name not in known_topics:
            raise ValueError(f'`topic` {name!r}: declare it with add_topic() before '
                             'writing serialised bytes')
    log = np.asarray(log_times_ns, dtype=np.int64).reshape(-1)
    publish = log if publish_times_ns is None else np.asarray(
        publish_times_ns, dtype=np.int64).reshape(-1)
    if log.size != count or publish.size != count:
        raise ValueError('`log_times_ns` and `publish_times_ns` need one entry per message')
    return names, index, log, publish


def add_batch(current, topics, names, index, messages, log, publish, flush_period_ns,
              last_flush_log_ns):
    """
    Write a checked batch (:func:`batch_arguments`) into the open file in one writer call.

    Takes the batch's sequence numbers from ``topics`` (name -> :class:`Topic`); returns the
    writer's flushes (:meth:`McapFileWriter.add_messages`). Raises OSError as the writer does.
    """
    channel_of = np.array([current.channel_ids[name] for name in names],
                          dtype=np.uint16)[index]
    sequences = np.zeros(len(messages), dtype=np.uint64)
    for k, name in enumerate(names):
        chosen = index == k
        sequences[chosen] = topics[name].next_sequences(int(chosen.sum()))
    return current.writer.add_messages(channel_of, messages, log, publish, flush_period_ns,
                                       last_flush_log_ns, sequences)


def count_appended(topics, current, appended, times):
    """
    Count messages appended to the open file ``current`` in bulk; return how many.

    ``appended``: channel id -> messages (:meth:`McapFileWriter.append_chunks`, which also
    gives their least and greatest log ``times``): each topic's count and last sequence
    number (the messages carry theirs) and the file's span take them in.
    """
    names = {number: name for name, number in current.channel_ids.items()}
    for channel, number in appended.items():
        topics[names[channel]].message_count += number
        topics[names[channel]].sequence += number
    count = sum(appended.values())
    if count:
        current.note(times[0], times[1], count)
    return count


def file_path(path, bare, index):
    """
    Return the path of a recording's file number ``index``.

    Parameters
    ----------
    path : pathlib.Path
        The recording's path.
    bare : bool
        ``path`` is the one bare ``.mcap`` file.
    index : int
        Files before this one.

    Returns
    -------
    pathlib.Path

    """
    if bare:
        return path
    return path / f'{path.name}_{index}.mcap'


def start_file(current, chunk_size, compression, topics, metadata, provenance=None,
               compression_level=DEFAULT_ZSTD_LEVEL):
    """
    Write a new file's header, schemas and channels and flush them; set its writer last.

    Parameters
    ----------
    current : OpenFile
        The file, its stream open and no writer yet (left so if this fails).
    chunk_size : int
        Uncompressed chunk size [bytes].
    compression : {'zstd', 'none'}
        Chunk compression.
    topics : iterable of topic records
        Each with ``name``, ``type_name``, ``qos_profiles``.
    metadata : dict
        The ``rosbag2`` Metadata record written after the header, as rosbag2 does at open.
    provenance : dict, optional
        The ``flexlink_ros`` Metadata record written next (:mod:`.provenance`).
    compression_level : int
        zstd level of the chunks.

    """
    writer = McapFileWriter(current.stream, chunk_size=chunk_size, compression=compression,
                            spill_directory=current.path.parent,
                            compression_level=compression_level)
    writer.start(profile='ros2', library=LIBRARY)
    writer.add_metadata('rosbag2', metadata)
    if provenance:
        writer.add_metadata(PROVENANCE_RECORD, provenance)
    for topic in topics:
        register_topic(writer, current, topic)
    writer.flush()
    current.writer = writer


def register_topic(writer, current, topic):
    """
    Add a topic's schema (once per type) and channel to a file, as rosbag2 writes them.

    Parameters
    ----------
    writer : McapFileWriter
        The file's writer.
    current : OpenFile
        The file (its schema and channel ids are noted).
    topic : topic record
        With ``name``, ``type_name``, ``qos_profiles``.

    """
    schema_id = current.schema_ids.get(topic.type_name)
    if schema_id is None:
        schema_id = writer.register_schema(
            name=topic.type_name, encoding='ros2msg',
            data=message_definition(topic.type_name).encode('utf-8'))
        current.schema_ids[topic.type_name] = schema_id
    current.channel_ids[topic.name] = writer.register_channel(
        topic=topic.name, message_encoding='cdr', schema_id=schema_id,
        metadata={'offered_qos_profiles': offered_qos_yaml(topic.qos_profiles),
                  'topic_type_hash': type_hash(topic.type_name)})


def split_due(current, split_size_bytes, split_duration_ns, log_time_ns):
    """
    Tell whether a message logged at ``log_time_ns`` goes to a new file.

    Parameters
    ----------
    current : OpenFile
        The file being written.
    split_size_bytes : int
        Size that ends a file (0: never).
    split_duration_ns : int
        Span of log time that ends a file (0: never).
    log_time_ns : int
        The next message's log time.

    Returns
    -------
    bool

    """
    if current.message_count == 0:
        return False
    too_big = split_size_bytes and current.stream.tell() >= split_size_bytes
    too_long = (split_duration_ns
                and log_time_ns - current.first_log_ns >= split_duration_ns)
    return bool(too_big or too_long)


def check_settings(path, split_size_bytes, split_duration_s, chunk_size_bytes, flush_period_s,
                   compression):
    """Raise ValueError naming the first of a recorder's settings that cannot be used."""
    if split_size_bytes < 0:
        raise ValueError(f'`split_size_bytes` must be >= 0, got {split_size_bytes}')
    if split_duration_s < 0:
        raise ValueError(f'`split_duration_s` must be >= 0, got {split_duration_s}')
    if path.suffix == '.mcap' and (split_size_bytes or split_duration_s):
        raise ValueError('`split_size_bytes`/`split_duration_s` need a bag directory path, '
                         f'not a single .mcap file ({path})')
    if chunk_size_bytes < 1024:
        raise ValueError(f'`chunk_size_bytes` must be >= 1024, got {chunk_size_bytes}')
    if not flush_period_s > 0:
        raise ValueError(f'`flush_period_s` must be > 0, got {flush_period_s}')
    if compression not in COMPRESSIONS:
        raise ValueError(f'`compression` must be one of {sorted(COMPRESSIONS)}, '
                         f'got {compression!r}')


def split_refusal(name, value, floor, unit):
    """
    Say why a live recording's split setting is refused (None: 0 or at least the floor).

    Parameters
    ----------
    name : str
        The setting, as the user wrote it (parameter or option).
    value : float
        Its value.
    floor : float
        :data:`MIN_SPLIT_BYTES` or :data:`MIN_SPLIT_DURATION_S`, in the setting's unit.
    unit : str
        How to write the floor (e.g. '1 MiB', '1 s').

    Returns
    -------
    str or None

    """
    if value == 0 or value >= floor:
        return None
    return (f'{name} must be 0 (no split) or at least {unit}, got {value:g}: each split '
            'finishes one file and starts another, so smaller splits leave the recorder '
            'splitting instead of writing')


def abandon(current):
    """
    Close a file that failed, as far as the OS lets (its buffered tail may be lost).

    Parameters
    ----------
    current : OpenFile
        The file; its writer's temporary index file is dropped too.

    """
    try:
        current.stream.close()
    except (OSError, ValueError):
        # The buffered tail cannot be written; drop the descriptor regardless.
        try:
            os.close(current.stream.fileno())
        except (OSError, ValueError):
            pass
    if current.writer is not None:
        current.writer.close()
