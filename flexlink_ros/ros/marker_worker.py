"""
The node's markers, drawn off the per-sample path.

The markers are the costliest output (the link shapes with their second-order motion and a
MarkerArray: some hundreds of microseconds) and the least urgent (a viewer needs tens of
frames a second). The input callback hands every n-th published sample to
:class:`MarkerWorker`, whose thread draws, publishes and records it while the executor's
thread goes on with the next input. A marker shows the sample it was drawn from and carries
that sample's stamp; its bytes are those drawing it in the callback gave. At most
``MAX_PENDING`` samples wait: a worker that far behind drops the oldest (counted), it never
holds ever more.
"""

import collections
import threading

MAX_PENDING = 1024    # samples waiting to be drawn (a second at 1 kHz); then the oldest go


class MarkerWorker:
    """
    A thread that draws and delivers the markers of the samples handed to it, in order.

    Parameters
    ----------
    draw : callable
        ``draw(stamp_ns, sample)`` -> the MarkerArray's CDR (bytes).
    deliver : callable
        ``deliver(data, log_ns)``: publish and record it.
    report : callable
        ``report(exc)``: an exception of ``draw`` or ``deliver`` (the worker goes on).

    """

    def __init__(self, draw, deliver, report):
        self._draw, self._deliver, self._report = draw, deliver, report
        self._pending = collections.deque()
        self._changed = threading.Condition()
        self._busy = self._stopping = False
        self.dropped = 0
        self._thread = threading.Thread(target=self._run, name='flexlink-markers', daemon=True)
        self._thread.start()

    def submit(self, stamp_ns, sample, log_ns):
        """Hand over a sample to draw (log_ns: the recording's log time of its outputs)."""
        with self._changed:
            if len(self._pending) >= MAX_PENDING:
                self._pending.popleft()
                self.dropped += 1
            self._pending.append((stamp_ns, sample, log_ns))
            self._changed.notify_all()

    def _run(self):
        while True:
            with self._changed:
                while not self._pending and not self._stopping:
                    self._changed.wait()
                if not self._pending:
                    return
                stamp_ns, sample, log_ns = self._pending.popleft()
                self._busy = True
            try:
                self._deliver(self._draw(stamp_ns, sample), log_ns)
            except Exception as exc:     # no marker may stop the markers
                self._report(exc)
            finally:
                with self._changed:
                    self._busy = False
                    self._changed.notify_all()

    def drain(self, timeout_s=5.0):
        """Wait until every sample handed over is delivered; False on timeout."""
        with self._changed:
            return self._changed.wait_for(lambda: not self._pending and not self._busy,
                                          timeout_s)

    def stop(self, timeout_s=5.0):
        """Deliver what waits, then end the thread (idempotent)."""
        self.drain(timeout_s)
        with self._changed:
            self._stopping = True
            self._changed.notify_all()
        if self._thread is not threading.current_thread():
            self._thread.join(timeout_s)
