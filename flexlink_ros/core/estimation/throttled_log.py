"""Warnings at most once per period, so a storm of bad samples does not flood the log."""

import time

# At most one warning per this many seconds of each kind (skipped warm starts, estimates out
# of bound) [s].
WARNING_PERIOD_S = 1.0


class ThrottledWarning:
    """
    One kind of warning, logged at most once per WARNING_PERIOD_S of the wall clock.

    Parameters
    ----------
    logger : logging.Logger
        Where the warnings go.

    """

    def __init__(self, logger):
        self.logger = logger
        self.last = None        # time.monotonic() of the last warning logged

    def warn(self, message, *args):
        """
        Log ``message % args`` unless a warning was logged less than WARNING_PERIOD_S ago.

        Parameters
        ----------
        message : str
            Format of the warning (logging's %-style).
        *args
            Its arguments.

        """
        now = time.monotonic()
        if self.last is None or now - self.last > WARNING_PERIOD_S:
            self.last = now
            self.logger.warning(message, *args)
