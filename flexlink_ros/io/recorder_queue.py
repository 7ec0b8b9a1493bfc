"""
Writing many messages at once: the queue of :meth:`McapRecorder.enqueue` and its flush thread.

:class:`QueuedWriting` is the part of :class:`~flexlink_ros.io.recorder.McapRecorder` that
records messages in bulk: :meth:`~QueuedWriting.write_batch` (the same file as the same
``write`` calls, built with numpy), the queue a latency-sensitive caller appends to, and the
background thread that writes the queue every :data:`QUEUE_PERIOD_S` and flushes the open chunk
once a flush period of wall time has passed without a message.
"""

import enum
import logging
import threading
import time

import numpy as np

from ..errors import RecorderError

LOGGER = logging.getLogger(__name__)
QUEUE_PERIOD_S = 0.02  # the background thread writes enqueued messages this often
# The queue holds at most this much (data plus a queued item's own size): a few seconds of the
# node's 1 kHz output, a backlog the writer clears in about 2 s at close even message by
# message (splits on) on a loaded machine, so a signal still ends the node within 5 s.
QUEUE_MAX_BYTES = 4 << 20
QUEUE_ITEM_BYTES = 128   # a queued (topic, bytes, int) tuple's own memory, about


@enum.unique
class RecorderState(enum.Enum):
    """Life cycle of a :class:`~flexlink_ros.io.recorder.McapRecorder`."""

    NEW = 'new'
    RECORDING = 'recording'
    FAILED = 'failed'
    CLOSED = 'closed'


def batch_arguments(topics, messages, log_times_ns, publish_times_ns, known_topics):
    """
    Check write_batch's arguments: (topic names, topic index per message, log, publish).

    Parameters
    ----------
    topics : str or sequence of str
        One topic for every message, or the topic of each.
    messages : sequence of bytes
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


class QueuedWriting:
    """Batch writing, the enqueue queue and the flush thread of the recorder (a mixin)."""

    def flush(self):
        """Write the queue and the open chunk and flush them to the OS (no fsync)."""
        self._write_queue()
        with self._lock:
            if self._state is RecorderState.RECORDING:
                self._flush_locked(self._last_flush_log_ns)

    def _start_flusher(self):
        if self._use_flush_thread:
            self._flusher = threading.Thread(target=self._flush_loop, name='mcap-flush',
                                             daemon=True)
            self._flusher.start()

    def _stop_flushing(self):
        """Stop the flush thread and write what is left in the queue."""
        self._stop_flusher.set()
        if self._flusher is not None and self._flusher is not threading.current_thread():
            self._flusher.join()
        self._write_queue()

    def enqueue(self, topic, message, log_time_ns):
        """
        Record one message without writing it in the calling thread.

        For a latency-sensitive caller (the node's subscription callback): the message is
        queued and the background thread writes the queue every ``QUEUE_PERIOD_S`` in one
        :meth:`write_batch` (so neither the per-message cost of :meth:`write` nor a slow disk
        holding the recorder's lock lands in the caller); :meth:`flush` and :meth:`close`
        write what is left. It records what :meth:`write` calls in the same order would.
        Without the background thread (``flush_thread=False``) this is :meth:`write`.

        The queue is bounded (:data:`QUEUE_MAX_BYTES`): while the writer is that far behind
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
        size = len(data) + QUEUE_ITEM_BYTES
        with self._queue_lock:
            if self._queued_bytes + size > QUEUE_MAX_BYTES:
                self._overflow += 1
                if self._overflow == 1:
                    LOGGER.error('MCAP recording to %s cannot keep up: its write queue is full '
                                 '(%d MiB); messages are dropped and counted', self.path,
                                 QUEUE_MAX_BYTES >> 20)
                return False
            self._queue.append((topic, data, int(log_time_ns)))
            self._queued_bytes += size
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
        current = self._file
        channel_of = np.array([current.channel_ids[name] for name in names],
                              dtype=np.uint16)[index]
        sequences = np.zeros(count, dtype=np.uint64)
        for k, name in enumerate(names):
            chosen = index == k
            sequences[chosen] = self._topics[name].next_sequences(int(chosen.sum()))
        try:
            flushes = current.writer.add_messages(channel_of, messages, log, publish,
                                                  self.flush_period_ns,
                                                  self._last_flush_log_ns, sequences)
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
        if flushes:
            self._last_flush_log_ns = flushes[-1][1]
            self._unflushed = count - 1 - flushes[-1][0]
            self._last_flush_wall = time.monotonic()
        else:
            if self._last_flush_log_ns is None:
                self._last_flush_log_ns = int(log[0])
            self._unflushed += count

    def _write_queue(self):
        """Write the messages enqueued so far (enqueue), in order, as one batch."""
        # Under the lock: flush() and the background thread may both get here, and two
        # writers popping one queue would interleave its messages (enqueue only appends,
        # without the lock).
        with self._lock:
            with self._queue_lock:
                queue = self._queue
                count = len(queue)      # appends may go on later: take only these
                if not count:
                    return
                items = [queue.popleft() for _ in range(count)]
                self._queued_bytes -= sum(len(item[1]) for item in items) + (
                    count * QUEUE_ITEM_BYTES)
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
