"""
Progress of the long subcommands on stderr (stdout keeps the result and ``--json``).

On a terminal a tqdm bar (redrawn at least every :data:`TICK_S`, so the elapsed time moves
while one long step runs); otherwise, for logs and pipes, one plain line every
:data:`LINE_PERIOD_S` and a last line when the job ends. The jobs report through a callable
(``progress(done, total, what)``; the studies and the replay writer take one), so the
numerical layers do not depend on how progress is shown.
"""

import sys
import threading
import time

from tqdm import tqdm

TICK_S = 1.0           # seconds between redraws of the bar (and checks for a plain line)
LINE_PERIOD_S = 10.0   # seconds between plain progress lines when stderr is not a terminal


class Progress:
    """
    Show how far a job is: a bar on a terminal, periodic lines otherwise.

    Call it with the count done (and the total and the current step when they change); use
    it as a context manager or call :meth:`close`, which writes the last state.

    Parameters
    ----------
    label : str
        What is in progress (the line's prefix).
    total : int or None
        The count at 100 % (None: not known yet).
    unit : str
        What is counted.
    stream : file, optional
        Where to write (default: ``sys.stderr`` at the time of the call).
    tty : bool or None
        Draw a bar (default: whether ``stream`` is a terminal).

    """

    def __init__(self, label, total=None, unit='step', stream=None, tty=None):
        self.stream = sys.stderr if stream is None else stream
        self.tty = self.stream.isatty() if tty is None else tty
        self.label, self.total, self.unit = label, total, unit
        self.done, self.what, self.closed = 0, '', False
        self.started = self.last_line = time.monotonic()
        self.lock = threading.Lock()
        self.bar = (tqdm(total=total, desc=label, unit=unit, file=self.stream,
                         dynamic_ncols=True, mininterval=0.2) if self.tty else None)
        self.stop = threading.Event()
        self.ticker = threading.Thread(target=self._tick, daemon=True)
        self.ticker.start()

    def __call__(self, done, total=None, what=None, force=False):
        """
        Record ``done`` of the total (the replay writer's ``force=True`` ends the job).

        Parameters
        ----------
        done : int
            Count done so far.
        total : int or None
            New total, if it changed.
        what : str or None
            The step under way, if it changed.
        force : bool
            The job is finished: write the last state and close.

        """
        with self.lock:
            self.done = done
            if total is not None:
                self.total = total
            if what is not None:
                self.what = what
            if self.bar is not None and not self.closed:
                self.bar.total = self.total
                self.bar.set_postfix_str(self.what, refresh=False)
                self.bar.update(done - self.bar.n)
        if force:
            self.close()

    def show(self):
        """Write the state now as a plain line (the bar redraws itself)."""
        with self.lock:
            if self.bar is None and not self.closed:
                self._write_line()

    def line(self):
        """Return the state as one plain line: count, percentage, elapsed, rate, step."""
        text = tqdm.format_meter(self.done, self.total, time.monotonic() - self.started,
                                 ncols=0, prefix=self.label, unit=self.unit)
        return f'{text} {self.what}'.rstrip()

    def _tick(self):
        while not self.stop.wait(TICK_S):
            with self.lock:
                if self.closed:
                    return
                if self.bar is not None:
                    self.bar.refresh()
                elif time.monotonic() - self.last_line >= LINE_PERIOD_S:
                    self._write_line()

    def _write_line(self):
        self.last_line = time.monotonic()
        self.stream.write(self.line() + '\n')
        self.stream.flush()

    def close(self):
        """Stop the redraws and write the last state (idempotent)."""
        self.stop.set()
        with self.lock:
            if self.closed:
                return
            self.closed = True
            if self.bar is not None:
                if self.total is not None and self.done >= self.total:
                    self.bar.update(self.total - self.bar.n)
                self.bar.close()
            else:
                self._write_line()

    def __enter__(self):
        """Return the progress itself."""
        return self

    def __exit__(self, *exc_info):
        """Close it: the last state is written whatever happened."""
        self.close()


class OnDemandProgress:
    """
    A :class:`Progress` opened at the first report: a job that reports nothing shows nothing.

    For the model build (``progress(percent, 100, what)``, called only while a model is
    built): a cold cache shows the build's percentage, a cached model loads silently.

    Parameters
    ----------
    label : str
        What is in progress (the line's prefix).
    unit : str
        What is counted.

    """

    def __init__(self, label, unit='%'):
        self.label, self.unit = label, unit
        self.progress = None

    def __call__(self, done, total=None, what=None):
        """Report ``done`` of ``total`` (whole units), opening the progress at the first."""
        first = self.progress is None
        if first:
            self.progress = Progress(self.label, total, unit=self.unit)
        self.progress(int(done), total, what)
        if first:     # a plain line at once: the build has started
            self.progress.show()

    def close(self):
        """Write the last state, if there was any report."""
        if self.progress is not None:
            self.progress.close()

    def __enter__(self):
        """Return the progress itself."""
        return self

    def __exit__(self, *exc_info):
        """Close it."""
        self.close()
