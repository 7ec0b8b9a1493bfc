"""
MCAP recorder that writes what rosbag2 writes, built to lose at most about a second on a crash.

Files are what ``ros2 bag record -s mcap`` produces: header profile ``ros2``; one schema per type
(``pkg/msg/Type``, encoding ``ros2msg``, the concatenated .msg definition); one channel per
topic with ``message_encoding='cdr'`` and metadata ``offered_qos_profiles`` and
``topic_type_hash``; message ``log_time`` = receive time, ``publish_time`` = send time (integer
ns); a summary with Statistics, so ``ros2 bag play FILE.mcap`` opens a bare file.

Layout. A ``path`` ending in ``.mcap`` is one bare file. Any other ``path`` is a rosbag2 bag
directory (created; must be absent or empty) holding ``<name>_0.mcap``, ``<name>_1.mcap``, ...
(split by size and/or duration) and a ``metadata.yaml`` (rosbag2 version 9) written on close,
which ``ros2 bag play DIR``, ``ros2 bag info DIR`` and ``rosbags`` need.

Crash safety. Chunks are small (128 KiB before compression) and the open chunk is written and
flushed to the OS whenever a flush period (0.5 s) of data has accumulated, and also by a
background timer when no message comes. A SIGKILL therefore loses at most one flush period
plus what was in the chunk; the file lacks its summary but every complete chunk is readable by
a streaming reader (``flexlink mcap-recover`` rewrites it with a summary). Data are not
fsync'ed: a killed process loses nothing the kernel already has; power loss is out of scope.

Errors. An unwritable path or a full disk raises :class:`RecorderError` once (from ``open``,
``write`` or ``close``); afterwards the recorder is in state ``FAILED``, drops messages and
counts them, so the caller can report it (a diagnostic) and carry on.
"""

import dataclasses
import enum
import logging
import os
import pathlib
import threading
import time

import yaml
from mcap.writer import LIBRARY_IDENTIFIER, CompressionType, Writer

from .core.errors import RecorderError
from .rosbag_schema import (message_definition, message_type_name, offered_qos_yaml,
                            qos_profile_dict, serialize_exact, type_hash)

LOGGER = logging.getLogger(__name__)

DEFAULT_CHUNK_SIZE = 128 * 1024  # bytes before compression; one chunk is the unit of loss
DEFAULT_FLUSH_PERIOD_S = 0.5  # at most this much data (log time, or wall time) sits in memory
ROSBAG2_METADATA_VERSION = 9  # rosbag2 metadata.yaml version written (QoS policies as names)
ROS_DISTRO = 'kilted'
LIBRARY = f'flexlink_ros recorder; {LIBRARY_IDENTIFIER}'
COMPRESSION = {'zstd': CompressionType.ZSTD, 'none': CompressionType.NONE}
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
    writer: Writer
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
        if compression not in COMPRESSION:
            raise ValueError(f'`compression` must be one of {sorted(COMPRESSION)}, '
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
                if not self.bare:
                    self.path.mkdir(parents=True, exist_ok=True)
                    if any(self.path.iterdir()):
                        raise FileExistsError(f'bag directory {self.path} exists and is not '
                                              'empty')
                self._state = RecorderState.RECORDING
                self._open_file()
            except OSError as exc:
                # FAILED (not NEW): later writes are dropped quietly, not refused one by one.
                self._fail(exc)
                self._error_reported = True
                raise RecorderError(f'cannot record to {self.path}: {exc}') from exc
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
        if isinstance(message, (bytes, bytearray, memoryview)):
            data = bytes(message)
            if topic not in self._topics:
                raise ValueError(f'`topic` {topic!r}: declare it with add_topic() before '
                                 'writing serialised bytes')
        else:
            if topic not in self._topics:
                self.add_topic(topic, message_type_name(message))
            data = serialize_exact(message)
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

    def flush(self):
        """Write the open chunk and flush it to the OS (no fsync)."""
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
        if self._file is not None:
            paths.append(self._file.path)
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
        with self._lock:
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
            self._closed_files.append(self._file_entry(self._file, complete=False))
            self._file = None

    def _file_path(self, index):
        if self.bare:
            return self.path
        return self.path / f'{self.path.name}_{index}.mcap'

    def _open_file(self):
        path = self._file_path(len(self._closed_files))
        stream = open(path, 'wb')
        try:
            writer = Writer(stream, chunk_size=self.chunk_size_bytes,
                            compression=COMPRESSION[self.compression])
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

    def _flush_loop(self):
        period_s = self.flush_period_ns / 1e9
        while not self._stop_flusher.wait(period_s / 2):
            with self._lock:
                if (self._state is RecorderState.RECORDING and self._unflushed
                        and time.monotonic() - self._last_flush_wall >= period_s):
                    self._flush_locked(self._last_flush_log_ns)


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
    temporary.write_text(text, encoding='utf-8')
    temporary.replace(bag_dir / 'metadata.yaml')
