"""
The node's first-start model build in its log: plain lines with the percentage done.

The build (core/reduction/build_progress.py) reports often; :class:`ProgressLog` writes a line
at the first report, then at most one a period while the percentage rises, and one at 100 %.
A node logs lines rather than drawing a bar: its output is a log (a terminal, launch's screen
output or a file alike).
"""

import time

LINE_PERIOD_S = 1.0   # at most one progress line a second
BUILD_MESSAGE = 'building the model (first start with these options; cached afterwards)'


class ProgressLog:
    """
    A ``progress(done, total, what)`` callable that logs periodic percentage lines.

    Parameters
    ----------
    log : callable
        Called with each line (e.g. a node logger's ``info``).
    period_s : float
        Shortest time between two lines (the first and the 100 % line always come).

    """

    def __init__(self, log, period_s=LINE_PERIOD_S):
        self.log, self.period_s = log, period_s
        self.last_line = None     # monotonic time of the last line
        self.last_percent = None
        self.lines = 0

    def __call__(self, done, total, what=''):
        """Take a report; log it if it is the first, the last, or a period has passed."""
        percent = 100.0 * done / total if total else 0.0
        now = time.monotonic()
        due = (self.last_line is None or percent >= 100.0
               or (now - self.last_line >= self.period_s
                   and round(percent) > round(self.last_percent)))
        if not due or (percent >= 100.0 and self.last_percent == percent):
            return
        self.log(f'{BUILD_MESSAGE}: {percent:3.0f} %' + (f' ({what})' if what else ''))
        self.last_line, self.last_percent = now, percent
        self.lines += 1
