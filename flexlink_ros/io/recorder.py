"""
MCAP recorder that writes what rosbag2 writes, built to lose at most about a second on a crash.

Files are what ``ros2 bag record -s mcap`` produces: header profile ``ros2``; one schema per type
(``pkg/msg/Type``, encoding ``ros2msg``, the concatenated .msg definition); one channel per
topic with ``message_encoding='cdr'`` and metadata ``offered_qos_profiles`` and
``topic_type_hash``; message ``log_time`` = receive time, ``publish_time`` = send time (integer
ns); a summary with Statistics, so ``ros2 bag play FILE.mcap`` opens a bare file.

Layout. A ``path`` ending in ``.mcap`` is one bare file. Any other ``path`` is a rosbag2 bag
directory (created) holding ``<name>_0.mcap``, ``<name>_1.mcap``, ...
(split by size and/or duration) and a ``metadata.yaml`` (rosbag2 version 9) written on close,
which ``ros2 bag play DIR``, ``ros2 bag info DIR`` and ``rosbags`` need.

Never overwrite. ``path`` must not exist in any form: an existing file, bare ``.mcap``,
directory or symbolic link (even a dangling one) is refused with a :class:`RecorderError` saying
which, and nothing is written. Files and the bag directory are created exclusively
(``O_CREAT | O_EXCL | O_NOFOLLOW``, ``mkdir``), so a path that appears between the check and
the creation is refused too, never clobbered or followed.

Crash safety. Chunks are small (128 KiB before compression) and the open chunk is written and
flushed to the OS whenever a flush period (0.5 s) of data has accumulated, and also by a
background timer when no message comes (which also writes what :meth:`McapRecorder.enqueue`
queued, every 20 ms). A SIGKILL therefore loses at most one flush period plus what was in the
chunk; the file lacks its summary but every complete chunk is readable by
a streaming reader (``flexlink mcap-recover`` rewrites it with a summary). Data are not
fsync'ed: a killed process loses nothing the kernel already has; power loss is out of scope.

Memory. Files are written by :class:`~flexlink_ros.io.mcap_writer.McapFileWriter`, composed over
the mcap library's public record classes. Where mcap's ``Writer`` keeps one ``ChunkIndex``
object per chunk for the summary (about 740 B each; at the node's 4-5 topics at 1 kHz that is
about 6 chunks a second, 16 MB an hour), it keeps them as their encoded summary records
(about 130 B each), at most :data:`~flexlink_ros.io.chunk_index.INDEX_SPILL_BYTES` in memory and
the rest in an unnamed temporary file in the recording's directory, so memory stays flat however
long a file grows; only ``close`` reads them back to write the summary.

Errors. An unwritable path or a full disk raises :class:`RecorderError` once (from ``open``,
``write`` or ``close``); afterwards the recorder is in state ``FAILED``, drops messages and
counts them, so the caller can report it (a diagnostic) and carry on.
"""

import collections
import dataclasses
import enum
import logging
import os
import pathlib
import stat
import threading
import time

import numpy as np
import yaml
from mcap.writer import LIBRARY_IDENTIFIER

from ..errors import RecorderError
from .mcap_writer import COMPRESSIONS, McapFileWriter
from .msg_schema import (
    message_definition, message_type_name, offered_qos_yaml, qos_profile_dict, serialize_exact,
    type_hash,
)

LOGGER = logging.getLogger(__name__)

DEFAULT_CHUNK_SIZE = 128 * 1024  # bytes before compression; one chunk is the unit of loss
DEFAULT_FLUSH_PERIOD_S = 0.5  # at most this much data (log time, or wall time) sits in memory
QUEUE_PERIOD_S = 0.02  # the background thread writes enqueued messages this often
ROSBAG2_METADATA_VERSION = 9  # rosbag2 metadata.yaml version written (QoS policies as names)
ROS_DISTRO = 'kilted'
LIBRARY = f'flexlink_ros recorder; {LIBRARY_IDENTIFIER}'
DEFAULT_QOS = {
    'history': 'keep_last', 'depth': 10, 'reliability': 'reliable', 'durability': 'volatile',
    'deadline': {'sec': 9223372036, 'nsec': 854775807},
    'lifespan': {'sec': 9223372036, 'nsec': 854775807},
    'liveliness': 'automatic',
    'liveliness_lease_duration': {'sec': 9223372036, 'nsec': 854775807},
    'avoid_ros_namespace_conventions': False,
}


@enum.unique
class RecorderState(enum.Enum):
    """Life cycle of a :class:`McapRecorder`."""

    NEW = 'new'
    RECORDING = 'recording'
    FAILED = 'failed'
    CLOSED = 'closed'


@dataclasses.dataclass
class _Topic:
    name: str
    type_name: str
    qos_profiles: list
    message_count: int = 0


@dataclasses.dataclass
class _OpenFile:
    path: pathlib.Path
    stream: object
    writer: McapFileWriter
    channel_ids: dict
    schema_ids: dict = dataclasses.field(default_factory=dict)
    first_log_ns: int = None
    last_log_ns: int = None
    message_count: int = 0


class McapRecorder:
    """
    Record ROS 2 messages into rosbag2-compatible MCAP.

    Parameters
    ----------
    path : str or os.PathLike
        ``*.mcap`` for one bare file, anything else for a bag directory (see module docstring).
    split_size_bytes : int
        Start a new file once the current one reaches this size (0: never). The split happens at
        the next chunk boundary, so a file can exceed it by one compressed chunk.
    split_duration_s : float
        Start a new file once its messages span this much log time (0: never).
    chunk_size_bytes : int
        Uncompressed chunk size.
    flush_period_s : float
        Longest span of log time (and of wall time, via a background thread) kept unwritten.
    compression : {'zstd', 'none'}
    flush_thread : bool
        Run the background flusher; without it only writes trigger flushes.

    """

    def __init__(self, path, *, split_size_bytes=0, split_duration_s=0.0,
                 chunk_size_bytes=DEFAULT_CHUNK_SIZE, flush_period_s=DEFAULT_FLUSH_PERIOD_S,
                 compression='zstd', flush_thread=True):
        self.path = pathlib.Path(path)
        self.bare = self.path.suffix == '.mcap'
        if split_size_bytes < 0:
            raise ValueError(f'`split_size_bytes` must be >= 0, got {split_size_bytes}')
        if split_duration_s < 0:
            raise ValueError(f'`split_duration_s` must be >= 0, got {split_duration_s}')
        if self.bare and (split_size_bytes or split_duration_s):
            raise ValueError('`split_size_bytes`/`split_duration_s` need a bag directory path, '
                             f'not a single .mcap file ({self.path})')
        if chunk_size_bytes < 1024:
            raise ValueError(f'`chunk_size_bytes` must be >= 1024, got {chunk_size_bytes}')
        if not flush_period_s > 0:
            raise ValueError(f'`flush_period_s` must be > 0, got {flush_period_s}')
        if compression not in COMPRESSIONS:
            raise ValueError(f'`compression` must be one of {sorted(COMPRESSIONS)}, '
                             f'got {compression!r}')
        self.split_size_bytes = int(split_size_bytes)
        self.split_duration_ns = int(round(split_duration_s * 1e9))
        self.chunk_size_bytes = int(chunk_size_bytes)
        self.flush_period_ns = int(round(flush_period_s * 1e9))
        self.compression = compression
        self._use_flush_thread = flush_thread
        self._lock = threading.RLock()
        self._topics = {}
        self._file = None
        self._closed_files = []  # dicts: path, message_count, first/last log time
        self._state = RecorderState.NEW
        self._error = None
        self._error_reported = False
        self._dropped = 0
        self._message_count = 0
        self._unflushed = 0
        self._last_flush_log_ns = None
        self._last_flush_wall = time.monotonic()
        self._stop_flusher = threading.Event()
        self._flusher = None
        self._queue = collections.deque()   # (topic, bytes, log_ns) from enqueue()

    # -- life cycle -------------------------------------------------------------------------

    def open(self):
        """
        Create the output and write the first file's header.

        Raises
        ------
        RecorderError
            The path cannot be created or written (the recorder is then ``FAILED``).

        """
        with self._lock:
            if self._state is not RecorderState.NEW:
                raise RecorderError(f'recorder for {self.path} already opened')
            try:
                refuse_existing(self.path)
                self.path.parent.mkdir(parents=True, exist_ok=True)
                if not self.bare:
                    self.path.mkdir()   # not exist_ok: a directory made meanwhile is refused
                self._state = RecorderState.RECORDING
                self._open_file()
            except OSError as exc:
                # FAILED (not NEW): later writes are dropped quietly, not refused one by one.
                self._fail(exc)
                self._error_reported = True
                where = '' if isinstance(exc, FileExistsError) else f' to {self.path}'
                raise RecorderError(f'cannot record{where}: {exc}') from exc
        if self._use_flush_thread:
            self._flusher = threading.Thread(target=self._flush_loop, name='mcap-flush',
                                             daemon=True)
            self._flusher.start()
        return self

    def close(self):
        """
        Finish the current file with its summary and write ``metadata.yaml``; idempotent.

        Returns
        -------
        dict
            :meth:`status` after closing.

        Raises
        ------
        RecorderError
            Finishing failed (full disk) and no error had been raised before.

        """
        self._stop_flusher.set()
        if self._flusher is not None and self._flusher is not threading.current_thread():
            self._flusher.join()
        self._write_queue()
        with self._lock:
            if self._state is RecorderState.RECORDING:
                try:
                    self._finish_file()
                    self._state = RecorderState.CLOSED
                    if not self.bare:
                        write_bag_metadata(self.path, self._closed_files, self._topics)
                except OSError as exc:
                    self._fail(exc)
            elif self._state is RecorderState.NEW:
                self._state = RecorderState.CLOSED
            if self._state is RecorderState.FAILED and not self._error_reported:
                self._error_reported = True
                raise RecorderError(f'recording to {self.path} failed: {self._error}')
            return self.status()

    def __enter__(self):
        """Open on entering the context."""
        return self.open()

    def __exit__(self, exc_type, exc_value, traceback):
        """Close on leaving the context, even on an exception."""
        self.close()
        return False

    # -- recording --------------------------------------------------------------------------

    def add_topic(self, topic, type_name, qos_profiles=None):
        """
        Declare a topic (needed before writing serialised bytes to it).

        Parameters
        ----------
        topic : str
        type_name : str or message class
            ``pkg/msg/Type`` or the message class.
        qos_profiles : sequence of rclpy.qos.QoSProfile or dict, optional
            Offered QoS of the topic's publishers (``node.get_publishers_info_by_topic``, or a
            publisher's ``qos_profile``); default reliable, volatile, keep last 10.

        """
        if not isinstance(type_name, str):
            type_name = message_type_name(type_name)
        profiles = [p if isinstance(p, dict) else qos_profile_dict(p)
                    for p in (qos_profiles or [DEFAULT_QOS])]
        message_definition(type_name)  # fail now, naming the type, if it is not installed
        with self._lock:
            known = self._topics.get(topic)
            if known is not None:
                if known.type_name != type_name:
                    raise ValueError(f'`topic` {topic!r} already recorded as {known.type_name}, '
                                     f'not {type_name}')
                return
            self._topics[topic] = _Topic(topic, type_name, profiles)
            if self._state is RecorderState.RECORDING and self._file is not None:
                try:
                    self._register(self._file, self._topics[topic])
                except OSError as exc:
                    self._fail(exc)

    def write(self, topic, message, log_time_ns, publish_time_ns=None, sequence=0):
        """
        Record one message.

        Parameters
        ----------
        topic : str
        message : bytes-like or ROS 2 message
            CDR bytes (e.g. from a ``raw=True`` subscription; the topic must be declared with
            :meth:`add_topic`) or a message object (serialised exactly; declares the topic).
        log_time_ns : int
            Receive time [ns].
        publish_time_ns : int, optional
            Send time [ns]; defaults to ``log_time_ns``.
        sequence : int

        Returns
        -------
        bool
            True if recorded, False if dropped because the recorder failed earlier.

        Raises
        ------
        RecorderError
            Writing fails now (or failed in the flush thread and was not reported yet), or the
            recorder is not open.

        """
        data = self._message_bytes(topic, message)
        log_time_ns = int(log_time_ns)
        publish_time_ns = log_time_ns if publish_time_ns is None else int(publish_time_ns)
        with self._lock:
            if self._state is not RecorderState.RECORDING:
                return self._refuse()
            try:
                self._maybe_split(log_time_ns)
                current = self._file
                current.writer.add_message(current.channel_ids[topic], log_time_ns, data,
                                           publish_time_ns, sequence)
            except OSError as exc:
                self._fail(exc)
                return self._refuse()
            if current.first_log_ns is None:
                current.first_log_ns = log_time_ns
                current.last_log_ns = log_time_ns
            else:
                current.first_log_ns = min(current.first_log_ns, log_time_ns)
                current.last_log_ns = max(current.last_log_ns, log_time_ns)
            current.message_count += 1
            self._topics[topic].message_count += 1
            self._message_count += 1
            self._unflushed += 1
            if self._last_flush_log_ns is None:
                self._last_flush_log_ns = log_time_ns
            elif log_time_ns - self._last_flush_log_ns >= self.flush_period_ns:
                self._flush_locked(log_time_ns)
            return True

    def _message_bytes(self, topic, message):
        """CDR bytes of ``message`` (bytes as given, for a declared topic; or serialised)."""
        if isinstance(message, (bytes, bytearray, memoryview)):
            if topic not in self._topics:
                raise ValueError(f'`topic` {topic!r}: declare it with add_topic() before '
                                 'writing serialised bytes')
            return bytes(message)
        if topic not in self._topics:
            self.add_topic(topic, message_type_name(message))
        return serialize_exact(message)

    def enqueue(self, topic, message, log_time_ns):
        """
        Record one message without writing it in the calling thread.

        For a latency-sensitive caller (the node's subscription callback): the message is
        queued and the background thread writes the queue every ``QUEUE_PERIOD_S`` in one
        :meth:`write_batch` (so neither the per-message cost of :meth:`write` nor a slow disk
        holding the recorder's lock lands in the caller); :meth:`flush` and :meth:`close`
        write what is left. It records what :meth:`write` calls in the same order would.
        Without the background thread (``flush_thread=False``) this is :meth:`write`.

        Parameters and errors as :meth:`write`; a failure in the background thread is raised
        (once) by the next call.

        """
        if not self._use_flush_thread:
            return self.write(topic, message, log_time_ns)
        data = self._message_bytes(topic, message)
        if self._state is not RecorderState.RECORDING:
            with self._lock:
                return self._refuse()
        self._queue.append((topic, data, int(log_time_ns)))
        return True

    def write_batch(self, topics, messages, log_times_ns, publish_times_ns=None):
        """
        Record many serialised messages, exactly as the same :meth:`write` calls in order.

        The file is the same (chunk boundaries, flushes, indexes, statistics), but the
        message and index records are built in bulk (numpy), not one Python call each: use
        it for offline writing (replay) where per-message cost dominates.

        Parameters
        ----------
        topics : str or sequence of str
            One topic for every message, or the topic of each (declared with
            :meth:`add_topic`).
        messages : sequence of bytes
            CDR bytes.
        log_times_ns : array-like of int, shape (n,)
        publish_times_ns : array-like of int, shape (n,), optional
            Default: the log times.

        Returns
        -------
        int
            Messages recorded (0 if dropped because the recorder failed earlier).

        Raises
        ------
        RecorderError
            As :meth:`write`.

        """
        names, index, log, publish = self._batch_arguments(topics, messages, log_times_ns,
                                                           publish_times_ns)
        count = len(messages)
        if count == 0:
            return 0
        with self._lock:
            if self._state is not RecorderState.RECORDING:
                if self._state is RecorderState.FAILED:
                    self._dropped += count - 1
                self._refuse()
                return 0
            if self.split_size_bytes or self.split_duration_ns:   # a split may fall inside
                topic_of = [names[k] for k in index.tolist()]
                recorded = 0
                for n, (log_ns, publish_ns) in enumerate(zip(log.tolist(), publish.tolist())):
                    recorded += bool(self.write(topic_of[n], messages[n], log_ns, publish_ns))
                return recorded
            current = self._file
            channel_of = np.array([current.channel_ids[name] for name in names],
                                  dtype=np.uint16)[index]
            try:
                flushes = current.writer.add_messages(channel_of, messages, log, publish,
                                                      self.flush_period_ns,
                                                      self._last_flush_log_ns)
            except OSError as exc:
                self._dropped += count - 1
                self._fail(exc)
                self._refuse()
                return 0
            self._count_batch(names, index, log, flushes)
            return count

    def _batch_arguments(self, topics, messages, log_times_ns, publish_times_ns):
        """Check write_batch's arguments: (topic names, topic index per message, log, publish)."""
        count = len(messages)
        if isinstance(topics, str):
            names, index = [topics], np.zeros(count, dtype=np.intp)
        else:
            if len(topics) != count:
                raise ValueError(f'`topics` has {len(topics)} entries for {count} messages')
            names = list(dict.fromkeys(topics))
            lookup = {name: k for k, name in enumerate(names)}
            index = np.fromiter((lookup[t] for t in topics), dtype=np.intp, count=count)
        for name in names:
            if name not in self._topics:
                raise ValueError(f'`topic` {name!r}: declare it with add_topic() before '
                                 'writing serialised bytes')
        log = np.asarray(log_times_ns, dtype=np.int64).reshape(-1)
        publish = log if publish_times_ns is None else np.asarray(
            publish_times_ns, dtype=np.int64).reshape(-1)
        if log.size != count or publish.size != count:
            raise ValueError('`log_times_ns` and `publish_times_ns` need one entry per message')
        return names, index, log, publish

    def _count_batch(self, names, index, log, flushes):
        """Counts, times and flush state after a written batch (as its write calls would)."""
        current = self._file
        count = len(log)
        first, last = int(log.min()), int(log.max())
        if current.first_log_ns is None:
            current.first_log_ns, current.last_log_ns = first, last
        else:
            current.first_log_ns = min(current.first_log_ns, first)
            current.last_log_ns = max(current.last_log_ns, last)
        current.message_count += count
        for k, number in enumerate(np.bincount(index, minlength=len(names)).tolist()):
            self._topics[names[k]].message_count += number
        self._message_count += count
        if flushes:
            self._last_flush_log_ns = flushes[-1][1]
            self._unflushed = count - 1 - flushes[-1][0]
            self._last_flush_wall = time.monotonic()
        else:
            if self._last_flush_log_ns is None:
                self._last_flush_log_ns = int(log[0])
            self._unflushed += count

    def flush(self):
        """Write the queue and the open chunk and flush them to the OS (no fsync)."""
        self._write_queue()
        with self._lock:
            if self._state is RecorderState.RECORDING:
                self._flush_locked(self._last_flush_log_ns)

    # -- state ------------------------------------------------------------------------------

    @property
    def state(self):
        """The :class:`RecorderState`."""
        return self._state

    @property
    def error(self):
        """The OS error that stopped recording (None if none)."""
        return self._error

    @property
    def files(self):
        """Paths of every file written or being written."""
        paths = [entry['path'] for entry in self._closed_files]
        current = self._file    # read once: another thread may close it meanwhile
        if current is not None:
            paths.append(current.path)
        return paths

    def status(self):
        """
        Summary of the recording, for diagnostics and the CLI.

        Returns
        -------
        dict
            ``state``, ``error``, ``path``, ``files``, ``message_count``, ``dropped_count``,
            ``topics`` (name -> count), ``bytes_written``.

        """
        # Without the lock: the writing thread may hold it through a slow disk write, and
        # diagnostics must not wait for that (each field is read atomically; the set may be
        # one write apart).
        size = 0
        for path in self.files:
            try:
                size += os.stat(path).st_size
            except OSError:
                pass
        return {
            'state': self._state.value,
            'error': None if self._error is None else str(self._error),
            'path': str(self.path),
            'files': [str(p) for p in self.files],
            'message_count': self._message_count,
            'dropped_count': self._dropped,
            'topics': {t.name: t.message_count for t in self._topics.values()},
            'bytes_written': size,
        }

    # -- internals --------------------------------------------------------------------------

    def _refuse(self):
        if self._state is RecorderState.FAILED:
            self._dropped += 1
            if not self._error_reported:
                self._error_reported = True
                raise RecorderError(f'recording to {self.path} stopped: {self._error}')
            return False
        raise RecorderError(f'recorder for {self.path} is {self._state.value}, not recording')

    def _fail(self, exc):
        LOGGER.error('MCAP recording to %s stopped: %s', self.path, exc)
        self._state = RecorderState.FAILED
        self._error = exc
        if self._file is not None:
            try:
                self._file.stream.close()
            except (OSError, ValueError):
                # The buffered tail cannot be written; drop the descriptor regardless.
                try:
                    os.close(self._file.stream.fileno())
                except (OSError, ValueError):
                    pass
            if self._file.writer is not None:
                self._file.writer.close()
            self._closed_files.append(self._file_entry(self._file, complete=False))
            self._file = None

    def _file_path(self, index):
        if self.bare:
            return self.path
        return self.path / f'{self.path.name}_{index}.mcap'

    def _open_file(self):
        path = self._file_path(len(self._closed_files))
        stream = create_exclusive(path)
        try:
            writer = McapFileWriter(stream, chunk_size=self.chunk_size_bytes,
                                    compression=self.compression, spill_directory=path.parent)
            writer.start(profile='ros2', library=LIBRARY)
            current = _OpenFile(path, stream, writer, {})
            for topic in self._topics.values():
                self._register(current, topic)
            self._file = current
            writer.flush()
        except BaseException:
            self._file = _OpenFile(path, stream, None, {})
            raise

    def _register(self, current, topic):
        schema_id = current.schema_ids.get(topic.type_name)
        if schema_id is None:
            schema_id = current.writer.register_schema(
                name=topic.type_name, encoding='ros2msg',
                data=message_definition(topic.type_name).encode('utf-8'))
            current.schema_ids[topic.type_name] = schema_id
        current.channel_ids[topic.name] = current.writer.register_channel(
            topic=topic.name, message_encoding='cdr', schema_id=schema_id,
            metadata={'offered_qos_profiles': offered_qos_yaml(topic.qos_profiles),
                      'topic_type_hash': type_hash(topic.type_name)})

    def _finish_file(self):
        current = self._file
        current.writer.finish()
        current.stream.close()
        self._closed_files.append(self._file_entry(current, complete=True))
        self._file = None

    @staticmethod
    def _file_entry(current, complete):
        return {'path': current.path, 'message_count': current.message_count,
                'first_log_ns': current.first_log_ns, 'last_log_ns': current.last_log_ns,
                'complete': complete}

    def _maybe_split(self, log_time_ns):
        current = self._file
        if current.message_count == 0:
            return
        too_big = self.split_size_bytes and current.stream.tell() >= self.split_size_bytes
        too_long = (self.split_duration_ns
                    and log_time_ns - current.first_log_ns >= self.split_duration_ns)
        if too_big or too_long:
            self._finish_file()
            self._open_file()

    def _flush_locked(self, log_time_ns):
        if self._file is None or not self._unflushed:
            return
        try:
            self._file.writer.flush()
        except OSError as exc:
            self._fail(exc)
            return
        self._unflushed = 0
        self._last_flush_log_ns = log_time_ns
        self._last_flush_wall = time.monotonic()

    def _write_queue(self):
        """Write the messages enqueued so far (enqueue), in order, as one batch."""
        # Under the lock: flush() and the background thread may both get here, and two
        # writers popping one queue would interleave its messages (enqueue only appends,
        # without the lock).
        with self._lock:
            queue = self._queue
            count = len(queue)      # appends may go on meanwhile: take only these
            if not count:
                return
            items = [queue.popleft() for _ in range(count)]
            topics, messages, log_times = zip(*items)
            try:
                self.write_batch(list(topics), list(messages), log_times)
            except RecorderError:
                # told to the enqueuing thread at its next call, or by close
                self._error_reported = False

    def _flush_loop(self):
        period_s = self.flush_period_ns / 1e9
        while not self._stop_flusher.wait(QUEUE_PERIOD_S):
            self._write_queue()
            with self._lock:
                if (self._state is RecorderState.RECORDING and self._unflushed
                        and time.monotonic() - self._last_flush_wall >= period_s):
                    self._flush_locked(self._last_flush_log_ns)


# O_NOFOLLOW is POSIX; where it is missing O_EXCL alone still refuses a symlink.
_EXCLUSIVE_FLAGS = (os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, 'O_NOFOLLOW', 0)
                    | getattr(os, 'O_CLOEXEC', 0))


def refuse_existing(path):
    """
    Raise FileExistsError naming what ``path`` is, if anything is there (links not followed).

    Parameters
    ----------
    path : pathlib.Path

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


def create_exclusive(path):
    """Open a new file for writing; fail if anything (even a dangling link) is at ``path``."""
    try:
        descriptor = os.open(path, _EXCLUSIVE_FLAGS, 0o644)
    except FileExistsError:
        refuse_existing(path)   # says what is there
        raise
    return os.fdopen(descriptor, 'wb')


class _PlainDumper(yaml.SafeDumper):
    """YAML without anchors/aliases (shared QoS dicts are written out each time)."""

    def ignore_aliases(self, data):
        return True


def _since_epoch(nanoseconds):
    return {'nanoseconds_since_epoch': int(nanoseconds)}


def write_bag_metadata(bag_dir, files, topics):
    """
    Write a rosbag2 (version 9) ``metadata.yaml`` for MCAP files in a bag directory.

    Parameters
    ----------
    bag_dir : pathlib.Path
    files : list of dict
        Per file: ``path``, ``message_count``, ``first_log_ns``, ``last_log_ns``.
    topics : dict
        Topic name -> object with ``name``, ``type_name``, ``qos_profiles``, ``message_count``.

    """
    starts = [f['first_log_ns'] for f in files if f['first_log_ns'] is not None]
    ends = [f['last_log_ns'] for f in files if f['last_log_ns'] is not None]
    start = min(starts) if starts else 0
    duration = max(ends) - start if ends else 0
    metadata = {
        'version': ROSBAG2_METADATA_VERSION,
        'storage_identifier': 'mcap',
        'relative_file_paths': [pathlib.Path(f['path']).name for f in files],
        'duration': {'nanoseconds': duration},
        'starting_time': _since_epoch(start),
        'message_count': sum(f['message_count'] for f in files),
        'topics_with_message_count': [
            {'topic_metadata': {'name': t.name, 'type': t.type_name,
                                'serialization_format': 'cdr',
                                'offered_qos_profiles': list(t.qos_profiles),
                                'type_description_hash': type_hash(t.type_name)},
             'message_count': t.message_count}
            for t in topics.values()],
        'compression_format': '',
        'compression_mode': '',
        'files': [
            {'path': pathlib.Path(f['path']).name,
             'starting_time': _since_epoch(f['first_log_ns'] or 0),
             'duration': {'nanoseconds': (f['last_log_ns'] or 0) - (f['first_log_ns'] or 0)},
             'message_count': f['message_count']}
            for f in files],
        'custom_data': {},
        'ros_distro': ROS_DISTRO,
    }
    bag_dir = pathlib.Path(bag_dir)
    temporary = bag_dir / 'metadata.yaml.tmp'
    text = yaml.dump({'rosbag2_bagfile_information': metadata}, Dumper=_PlainDumper,
                     sort_keys=False)
    if os.path.lexists(temporary):   # left by an earlier close that failed half-way
        os.unlink(temporary)
    with create_exclusive(temporary) as stream:
        stream.write(text.encode('utf-8'))
    temporary.replace(bag_dir / 'metadata.yaml')   # replaces a link itself, never its target
