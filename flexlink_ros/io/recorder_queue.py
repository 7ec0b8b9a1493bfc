"""
When the recorder writes and flushes: its write queue, written by a thread, and its flush clock.

:class:`WriteQueue` is what :meth:`flexlink_ros.io.recorder.McapRecorder.enqueue` appends
to: a queue bounded in bytes (:data:`QUEUE_MAX_BYTES`; what overflows is dropped and
counted, never held in ever more memory) and a background thread that calls the recorder back
every :data:`QUEUE_PERIOD_S` to write what was queued and flush the open chunk when due. The
queue's own lock guards only its items and byte count and is never held while writing, so an
enqueuing caller never waits for the disk. :class:`FlushClock` says when the open chunk is
flushed to the OS: what bounds the loss of a crash.
"""

import collections
import logging
import threading
import time

LOGGER = logging.getLogger(__name__)
QUEUE_PERIOD_S = 0.02  # the background thread writes enqueued messages this often
# The queue holds at most this much (data plus a queued item's own size): a few seconds of the
# node's 1 kHz output, a backlog the writer clears in about 2 s at close even message by
# message (splits on) on a loaded machine, so a signal still ends the node within 5 s.
QUEUE_MAX_BYTES = 4 << 20
QUEUE_ITEM_BYTES = 128   # a queued (topic, bytes, int) tuple's own memory, about


class WriteQueue:
    """
    Messages waiting to be written, bounded in bytes, and the thread that has them written.

    Parameters
    ----------
    on_period : callable
        Called without arguments every :data:`QUEUE_PERIOD_S` by the thread (the recorder
        writes what :meth:`take` gives and flushes when due).
    name : str
        What the queue writes to, for the overflow message.

    """

    def __init__(self, on_period, name):
        self._on_period = on_period
        self._name = name
        self._items = collections.deque()   # (topic, bytes, log_ns)
        self._lock = threading.Lock()       # items and byte count; never held while writing
        self._bytes = 0
        self._overflow = 0
        self._stop = threading.Event()
        self._thread = None

    @property
    def queued_bytes(self):
        """Bytes queued, with each item's own size."""
        return self._bytes

    @property
    def overflow_count(self):
        """Messages dropped because the queue was full."""
        return self._overflow

    def put(self, topic, data, log_time_ns):
        """Queue one message; False (and counted) if the queue is full."""
        size = len(data) + QUEUE_ITEM_BYTES
        with self._lock:
            if self._bytes + size > QUEUE_MAX_BYTES:
                self._overflow += 1
                if self._overflow == 1:
                    LOGGER.error('MCAP recording to %s cannot keep up: its write queue is full '
                                 '(%d MiB); messages are dropped and counted', self._name,
                                 QUEUE_MAX_BYTES >> 20)
                return False
            self._items.append((topic, data, log_time_ns))
            self._bytes += size
        return True

    def take(self):
        """Remove and return the messages queued so far, in order: (topics, messages, times)."""
        with self._lock:
            count = len(self._items)      # appends may go on later: take only these
            if not count:
                return (), (), ()
            items = [self._items.popleft() for _ in range(count)]
            self._bytes -= sum(len(item[1]) for item in items) + count * QUEUE_ITEM_BYTES
        return tuple(zip(*items))

    def start(self):
        """Start the thread."""
        self._thread = threading.Thread(target=self._run, name='mcap-flush', daemon=True)
        self._thread.start()

    def stop(self):
        """Stop the thread and wait for it (unless called from it); :meth:`take` still works."""
        self._stop.set()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join()

    def _run(self):
        while not self._stop.wait(QUEUE_PERIOD_S):
            self._on_period()


class FlushClock:
    """
    When the open chunk is flushed: a flush period of log time, or of wall time, after the last.

    Log time is checked at every message written, wall time by the queue's thread (no message
    comes); the recorder flushes when told and reports each flush back (:meth:`flushed`).

    Parameters
    ----------
    period_ns : int
        The flush period [ns].

    """

    def __init__(self, period_ns):
        self.period_ns = period_ns
        self.unflushed = 0          # messages written since the last flush
        self.last_log_ns = None     # log time of the last flush (at first: the first message)
        self._last_wall = time.monotonic()

    def wrote(self, log_time_ns):
        """Count one message written; tell whether a flush period of log time has passed."""
        self.unflushed += 1
        if self.last_log_ns is None:
            self.last_log_ns = log_time_ns
            return False
        return log_time_ns - self.last_log_ns >= self.period_ns

    def wrote_batch(self, first_log_ns, count, flushes):
        """Count a batch written with the writer's own flushes ((index, log time) of each)."""
        if flushes:
            self.last_log_ns = flushes[-1][1]
            self.unflushed = count - 1 - flushes[-1][0]
            self._last_wall = time.monotonic()
        else:
            if self.last_log_ns is None:
                self.last_log_ns = first_log_ns
            self.unflushed += count

    def idle_due(self):
        """Tell whether messages have waited unflushed for a flush period of wall time."""
        return bool(self.unflushed) and (
            time.monotonic() - self._last_wall >= self.period_ns / 1e9)

    def flushed(self, log_time_ns):
        """Note a flush, at log time ``log_time_ns``."""
        self.unflushed = 0
        self.last_log_ns = log_time_ns
        self._last_wall = time.monotonic()
