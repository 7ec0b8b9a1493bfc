"""
MCAP recorder that writes what rosbag2 writes, built to lose at most about a second on a crash.

Files are what ``ros2 bag record -s mcap`` produces: header profile ``ros2``; one schema per type
(``pkg/msg/Type``, encoding ``ros2msg``, the concatenated .msg definition); one channel per
topic with ``message_encoding='cdr'`` and metadata ``offered_qos_profiles`` and
``topic_type_hash``; message ``log_time`` = receive time, ``publish_time`` = send time (integer
ns); a summary with Statistics, so ``ros2 bag play FILE.mcap`` opens a bare file. A ``path``
ending in ``.mcap`` is one bare file, any other a rosbag2 bag directory (split files and a
``metadata.yaml`` written on close); nothing is ever overwritten or followed
(:mod:`flexlink_ros.io.recorder_files`). A bag directory is locked while it is recorded
(:mod:`flexlink_ros.io.bag_lock`), so ``flexlink reindex`` refuses it.

Crash safety. Chunks are small (128 KiB before compression) and the open chunk is written and
flushed to the OS whenever a flush period (0.5 s) of data has accumulated, and also by a
background timer when no message comes (which also writes what :meth:`McapRecorder.enqueue`
queued, every 20 ms). A SIGKILL therefore loses at most one flush period plus what was in the
chunk; the file lacks its summary but every complete chunk is readable by
a streaming reader (``flexlink mcap-recover`` rewrites it with a summary). Data are not
fsync'ed: a killed process loses nothing the kernel already has; power loss is out of scope.

Memory. Files are written by :class:`~flexlink_ros.io.mcap_writer.McapFileWriter`, composed over
the mcap library's public record classes, which keeps the summary's chunk indexes encoded and
spills them to a temporary file (:mod:`flexlink_ros.io.chunk_index`), so memory stays flat
however long a file grows.

Errors. An unwritable path or a full disk raises :class:`RecorderError` once (from ``open``,
``write`` or ``close``); afterwards the recorder is in state ``FAILED``, drops messages and
counts them, so the caller can report it (a diagnostic) and carry on.
"""

import enum
import logging
import os
import pathlib
import threading

import numpy as np

from .bag_lock import lock_bag, unlock_bag
from .bag_metadata import (
    DEFAULT_QOS, METADATA_RECORD, serialized_metadata, UNSET_NS, write_bag_metadata,
)
from .msg_schema import (
    message_definition, message_type_name, qos_profile_dict, serialize_exact,
)
from .provenance import custom_data
from .recorder_files import (
    abandon, add_batch, batch_arguments, check_settings, count_appended, create_exclusive,
    DEFAULT_ZSTD_LEVEL, file_path, make_directories, OpenFile, refuse_existing, register_topic,
    remove_directories, split_due, start_file, Topic,
)
from .recorder_queue import FlushClock, WriteQueue
from ..errors import RecorderError

LOGGER = logging.getLogger(__name__)

DEFAULT_CHUNK_SIZE = 128 * 1024  # bytes before compression; one chunk is the unit of loss
DEFAULT_FLUSH_PERIOD_S = 0.5  # at most this much data (log time, or wall time) sits in memory


@enum.unique
class RecorderState(enum.Enum):
    """Life cycle of a :class:`McapRecorder`."""

    NEW = 'new'
    RECORDING = 'recording'
    FAILED = 'failed'
    CLOSED = 'closed'


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
    compression_level : int
        zstd level of the chunks (default zstandard's, 3).
    flush_thread : bool
        Run the background flusher; without it only writes trigger flushes.
    provenance : dict, optional
        What makes the recording (:func:`.provenance.provenance_entries`): written as a
        ``flexlink_ros`` Metadata record in every file and into ``custom_data``.

    """

    def __init__(self, path, *, split_size_bytes=0, split_duration_s=0.0,
                 chunk_size_bytes=DEFAULT_CHUNK_SIZE, flush_period_s=DEFAULT_FLUSH_PERIOD_S,
                 compression='zstd', flush_thread=True, provenance=None,
                 compression_level=DEFAULT_ZSTD_LEVEL):
        self.path = pathlib.Path(path)
        self.bare = self.path.suffix == '.mcap'
        check_settings(self.path, split_size_bytes, split_duration_s, chunk_size_bytes,
                       flush_period_s, compression)
        self.split_size_bytes = int(split_size_bytes)
        self.split_duration_ns = int(round(split_duration_s * 1e9))
        self.chunk_size_bytes = int(chunk_size_bytes)
        self.flush_period_ns = int(round(flush_period_s * 1e9))
        self.compression = compression
        self.compression_level = int(compression_level)
        self._use_flush_thread = flush_thread
        self.provenance = dict(provenance or {})
        self._custom_data = custom_data(self.provenance)
        self._lock = threading.RLock()
        self._topics = {}
        self._file = None
        self._closed_files = []  # dicts: path, message_count, first/last log time
        self._state = RecorderState.NEW
        self._error = None
        self._error_reported = False
        self._dropped = 0
        self._message_count = 0
        self._flush_clock = FlushClock(self.flush_period_ns)
        self._queue = WriteQueue(self._on_queue_period, self.path)   # what enqueue() hands over
        self._closed_bytes = 0
        self._bag_lock = None   # descriptor holding the bag directory's lock (bag_lock)

    # -- life cycle -------------------------------------------------------------------------

    def open(self):   # noqa: A003  the public API (open/close, as a file)
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
            created = []    # directories made here, removed again if the open fails
            try:
                refuse_existing(self.path)
                created = make_directories(self.path.parent)
                if not self.bare:
                    self.path.mkdir()   # not exist_ok: a directory made meanwhile is refused
                    created.append(self.path)
                    self._bag_lock = lock_bag(self.path)   # held until metadata.yaml is written
                self._state = RecorderState.RECORDING
                self._open_file()
            except OSError as exc:
                # FAILED (not NEW): later writes are dropped quietly, not refused one by one.
                self._fail(exc)
                remove_directories(created)   # a retry with this path is then not refused
                self._error_reported = True
                where = '' if isinstance(exc, FileExistsError) else f' to {self.path}'
                raise RecorderError(f'cannot record{where}: {exc}') from exc
        if self._use_flush_thread:
            self._queue.start()
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
        self._queue.stop()
        self._write_queue()
        with self._lock:
            if self._state is RecorderState.RECORDING:
                try:
                    self._finish_file()
                    self._state = RecorderState.CLOSED
                    if not self.bare:
                        write_bag_metadata(self.path, self._closed_files, self._topics,
                                           self._custom_data)
                except OSError as exc:
                    self._fail(exc)
                unlock_bag(self._bag_lock)
                self._bag_lock = None
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

    # -- status -----------------------------------------------------------------------------

    @property
    def state(self):
        """Return the :class:`RecorderState`."""
        return self._state

    @property
    def error(self):
        """Return the OS error that stopped recording (None if none)."""
        return self._error

    @property
    def files(self):
        """Paths of every file written or being written."""
        paths = [entry['path'] for entry in self._closed_files]
        current = self._file    # read once: another thread may close it meanwhile
        if current is not None:
            paths.append(current.path)
        return paths

    def status(self, list_files=True):
        """
        Summary of the recording, for diagnostics and the CLI.

        Parameters
        ----------
        list_files : bool
            Include the path of every file (``files``); without it the cost does not grow
            with the number of files (diagnostics, every period).

        Returns
        -------
        dict
            ``state``, ``error``, ``path``, ``files`` (if listed), ``file_count``,
            ``message_count``, ``dropped_count`` (overflow included), ``overflow_count``
            (dropped because the write queue was full), ``queued_bytes``, ``topics``
            (name -> count), ``bytes_written``.

        """
        # Without the lock: the writing thread may hold it through a slow disk write, and
        # diagnostics must not wait for that (each field is read atomically; the set may be
        # one write apart).
        current = self._file    # read once: another thread may close it meanwhile
        size = self._closed_bytes
        if current is not None:
            try:
                size += os.fstat(current.stream.fileno()).st_size
            except (OSError, ValueError):
                pass
        status = {
            'state': self._state.value,
            'error': None if self._error is None else str(self._error),
            'path': str(self.path),
            'file_count': len(self._closed_files) + (current is not None),
            'message_count': self._message_count,
            'dropped_count': self._dropped + self._queue.overflow_count,
            'overflow_count': self._queue.overflow_count,
            'queued_bytes': self._queue.queued_bytes,
            'topics': {t.name: t.message_count for t in self._topics.values()},
            'bytes_written': size,
        }
        if list_files:
            status['files'] = [str(p) for p in self.files]
        return status

    # -- recording --------------------------------------------------------------------------

    def add_topic(self, topic, type_name, qos_profiles=None):
        """
        Declare a topic (needed before writing serialised bytes to it).

        Parameters
        ----------
        topic : str
            The topic's name.
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
            self._topics[topic] = Topic(topic, type_name, profiles)
            if self._state is RecorderState.RECORDING and self._file is not None:
                try:
                    register_topic(self._file.writer, self._file, self._topics[topic])
                except OSError as exc:
                    self._fail(exc)

    def write(self, topic, message, log_time_ns, publish_time_ns=None, sequence=None):
        """
        Record one message.

        Parameters
        ----------
        topic : str
            The topic's name.
        message : bytes-like or ROS 2 message
            CDR bytes (e.g. from a ``raw=True`` subscription; the topic must be declared with
            :meth:`add_topic`) or a message object (serialised exactly; declares the topic).
        log_time_ns : int
            Receive time [ns].
        publish_time_ns : int, optional
            Send time [ns]; defaults to ``log_time_ns``.
        sequence : int, optional
            The message's MCAP sequence number (e.g. the publisher's, taken modulo 2**32);
            default: the message's number in its topic (1, 2, ... over the whole recording).

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
                number = int(self._topics[topic].next_sequences(1)[0])
                sequence = number if sequence is None else int(sequence) % 2 ** 32
                current.writer.add_message(current.channel_ids[topic], log_time_ns, data,
                                           publish_time_ns, sequence)
            except OSError as exc:
                self._fail(exc)
                return self._refuse()
            current.note(log_time_ns, log_time_ns, 1)
            self._topics[topic].message_count += 1
            self._message_count += 1
            if self._flush_clock.wrote(log_time_ns):
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

    def flush(self):
        """Write the queue and the open chunk and flush them to the OS (no fsync)."""
        self._write_queue()
        with self._lock:
            if self._state is RecorderState.RECORDING:
                self._flush_locked(self._flush_clock.last_log_ns)

    def enqueue(self, topic, message, log_time_ns):
        """
        Record one message without writing it in the calling thread.

        For a latency-sensitive caller (the node's subscription callback): the message is
        queued (:class:`.recorder_queue.WriteQueue`) and the background thread writes the queue
        every ``QUEUE_PERIOD_S`` (20 ms) in one :meth:`write_batch` (so neither the per-message
        cost of :meth:`write` nor a slow disk holding the recorder's lock lands in the caller);
        :meth:`flush` and :meth:`close` write what is left. It records what :meth:`write`
        calls in the same order would.
        Without the background thread (``flush_thread=False``) this is :meth:`write`.

        The queue is bounded (``QUEUE_MAX_BYTES``, 4 MiB): while the writer is that far behind
        (a stalled disk), messages are dropped and counted (``overflow_count`` of
        :meth:`status`), never held in ever more memory.

        Parameters and errors as :meth:`write`; a failure in the background thread is raised
        (once) by the next call. Returns False for a message dropped on overflow.

        """
        if not self._use_flush_thread:
            return self.write(topic, message, log_time_ns)
        data = self._message_bytes(topic, message)
        if self._state is not RecorderState.RECORDING:
            with self._lock:
                return self._refuse()
        return self._queue.put(topic, data, int(log_time_ns))

    def write_batch(self, topics, messages, log_times_ns, publish_times_ns=None):
        """
        Record many serialised messages, exactly as the same :meth:`write` calls in order.

        The file is the same (chunk boundaries, flushes, indexes, statistics), but the
        message and index records are built in bulk (numpy), not one Python call each: use
        it for offline writing (replay) where per-message cost dominates.

        Parameters
        ----------
        topics : str or sequence of str
            One topic for every message, or the topic of each (of each column of a
            PackedMessages), declared with :meth:`add_topic`.
        messages : sequence of bytes, or :class:`.packed_messages.PackedMessages`
            CDR bytes.
        log_times_ns : array-like of int, shape (n,)
            Log (receive) times [ns].
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
        names, index, log, publish = batch_arguments(
            topics, messages, log_times_ns, publish_times_ns, self._topics)
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
                return self._write_each(names, index, messages, log, publish)
            return self._write_bulk(names, index, messages, log, publish)

    def append_part(self, source):
        """
        Append a :class:`.replay_writer.PartWriter`'s chunks (same topics; no splits).

        Its messages keep their sequence numbers; returns how many were appended.
        """
        if self.split_size_bytes or self.split_duration_ns:
            raise RecorderError('a part cannot be appended to a recording that splits')
        with self._lock:
            if self._state is not RecorderState.RECORDING:
                return self._refuse()
            try:
                appended, times = self._file.writer.append_chunks(source)
            except OSError as exc:
                self._fail(exc)
                return self._refuse()
            count = count_appended(self._topics, self._file, appended, times)
            self._message_count += count
            return count

    # -- batches and the queue ----------------------------------------------------------------

    def _write_each(self, names, index, messages, log, publish):
        """Write a batch one message at a time (a file split may fall inside it)."""
        topic_of = [names[k] for k in index.tolist()]
        recorded = 0
        for n, (log_ns, publish_ns) in enumerate(zip(log.tolist(), publish.tolist())):
            recorded += bool(self.write(topic_of[n], messages[n], log_ns, publish_ns))
        return recorded

    def _write_bulk(self, names, index, messages, log, publish):
        """Write a batch into the open file in one call of its writer."""
        count = len(messages)
        try:
            flushes = add_batch(self._file, self._topics, names, index, messages, log, publish,
                                self.flush_period_ns, self._flush_clock.last_log_ns)
        except OSError as exc:
            self._dropped += count - 1
            self._fail(exc)
            self._refuse()
            return 0
        self._count_batch(names, index, log, flushes)
        return count

    def _count_batch(self, names, index, log, flushes):
        """Update counts, times and flush state after a batch (as its write calls would)."""
        count = len(log)
        self._file.note(int(log.min()), int(log.max()), count)
        for k, number in enumerate(np.bincount(index, minlength=len(names)).tolist()):
            self._topics[names[k]].message_count += number
        self._message_count += count
        self._flush_clock.wrote_batch(int(log[0]), count, flushes)

    def _write_queue(self):
        """Write the messages enqueued so far (enqueue), in order, as one batch."""
        # Under the lock: flush() and the background thread may both get here, and two
        # writers popping one queue would interleave its messages (enqueue only appends,
        # without the lock).
        with self._lock:
            topics, messages, log_times = self._queue.take()
            if not topics:
                return
            try:
                self.write_batch(list(topics), list(messages), log_times)
            except RecorderError:
                # told to the enqueuing thread at its next call, or by close
                self._error_reported = False

    def _on_queue_period(self):
        """Write the queue; flush the open chunk once a flush period of wall time has passed."""
        self._write_queue()
        with self._lock:
            if self._state is RecorderState.RECORDING and self._flush_clock.idle_due():
                self._flush_locked(self._flush_clock.last_log_ns)

    def _flush_locked(self, log_time_ns):
        if self._file is None or not self._flush_clock.unflushed:
            return
        try:
            self._file.writer.flush()
        except OSError as exc:
            self._fail(exc)
            return
        self._flush_clock.flushed(log_time_ns)

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
        unlock_bag(self._bag_lock)      # a failed recording can be reindexed at once
        self._bag_lock = None
        if self._file is not None:
            try:
                self._closed_bytes += os.stat(self._file.path).st_size
            except OSError:
                pass
            abandon(self._file)
            self._closed_files.append(self._file.entry(complete=False))
            self._file = None

    def _open_file(self):
        # The rosbag2 records describe this file alone: their cost does not grow with the
        # files written before it (see bag_metadata.serialized_metadata).
        path = file_path(self.path, self.bare, len(self._closed_files))
        self._file = OpenFile(path, create_exclusive(path), None, {})
        self._file.counts_before = {t.name: t.message_count for t in self._topics.values()}
        opening = serialized_metadata([self._file.entry(complete=False)], self._topics,
                                      UNSET_NS, counts={},
                                      custom_data=self._custom_data)   # as rosbag2 at open
        start_file(self._file, self.chunk_size_bytes, self.compression, self._topics.values(),
                   opening, self.provenance, self.compression_level)

    def _finish_file(self):
        current = self._file
        before = current.counts_before
        counts = {t.name: t.message_count - before.get(t.name, 0)
                  for t in self._topics.values()}
        current.writer.add_metadata(METADATA_RECORD, serialized_metadata(
            [current.entry(complete=True)], self._topics, counts=counts,
            custom_data=self._custom_data))
        current.writer.finish()
        self._closed_bytes += current.stream.tell()
        current.stream.close()
        self._closed_files.append(current.entry(complete=True))
        self._file = None

    def _maybe_split(self, log_time_ns):
        if split_due(self._file, self.split_size_bytes, self.split_duration_ns, log_time_ns):
            self._finish_file()
            self._open_file()
