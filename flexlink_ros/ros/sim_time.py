"""
Simulated time without a clock: a warning, and recorded log times that are never zero.

With ``use_sim_time`` the node clock is ``/clock``'s time and reads 0 until the first
``/clock`` message. :class:`ClockWatch` says so: one warning once the clock has been missing
for :data:`GRACE_S`, then one every :data:`WARN_PERIOD_S` while it stays away, and a line when
it comes. It is driven by a wall
timer (the node's /diagnostics timer runs on the steady clock for this reason: a timer on the
node clock never fires without ``/clock``).

:class:`LogTime` gives the log time of a record. rosbag2 takes it from the node clock (the
receive time); so does the node while that clock runs. While it reads 0 the log time is the
input's own stamp: the stamp is the publisher's clock at the sample, in the time base of the
system (simulated time when a simulator stamps), so the records stay in one time base with
what the node records once ``/clock`` runs. Records without an input (``/diagnostics``) take
the newest stamp plus the steady time since it came, and the system clock before any input.
"""

import struct
import time

WARN_PERIOD_S = 30.0     # repeat the no-clock warning this often while it lasts
GRACE_S = 3.0            # no warning before this long without a clock (discovery takes 0-3 s)
NO_CLOCK_WARNING = ('use_sim_time is true but no /clock has been received: the node clock '
                    'reads 0; recorded log times follow the input stamps until a clock '
                    'publishes /clock (set use_sim_time false if none will)')
CLOCK_STARTED = '/clock received: the node clock runs'
# header.stamp of a little-endian CDR message: int32 sec, uint32 nanosec after the 4-byte
# encapsulation header (a Header is every stamped message's first field).
_STAMP = struct.Struct('<iI')
_CDR_LITTLE_ENDIAN = b'\x00\x01'


def cdr_stamp_ns(data):
    """Return the header stamp [ns] of a stamped message's CDR, or 0 if it has none."""
    if len(data) < 4 + _STAMP.size or bytes(data[:2]) != _CDR_LITTLE_ENDIAN:
        return 0
    sec, nanosec = _STAMP.unpack_from(data, 4)
    return max(sec * 1_000_000_000 + nanosec, 0)


class LogTime:
    """Log times for the recording: the node clock, or what stands in while it reads 0."""

    def __init__(self):
        self._last = None   # (stamp_ns, steady ns when it came)

    def __call__(self, clock_ns, stamp_ns=0):
        """
        Return the log time [ns] of a record.

        Parameters
        ----------
        clock_ns : int
            The node clock now [ns] (0: simulated time without /clock).
        stamp_ns : int
            The stamp of the input the record belongs to [ns] (0: none).

        """
        if clock_ns > 0:
            return clock_ns
        now = time.monotonic_ns()
        if stamp_ns > 0:
            self._last = (stamp_ns, now)
            return stamp_ns
        if self._last is not None:
            return self._last[0] + now - self._last[1]
        return time.time_ns()


class ClockWatch:
    """
    Warn while a node on simulated time has no clock (once after a grace, then periodically).

    Parameters
    ----------
    warn, info : callable
        Called with the warning, and with the line when the clock starts.
    period_s : float
        Time between repeated warnings [s] (steady time).
    grace_s : float
        How long the clock may be missing before the first warning [s].

    """

    def __init__(self, warn, info, period_s=WARN_PERIOD_S, grace_s=GRACE_S):
        self.warn, self.info, self.period_s, self.grace_s = warn, info, period_s, grace_s
        self.missing_since = self.last_warning = None
        self.warnings = 0

    def check(self, use_sim_time, clock_ns):
        """
        Look at the clock once (from a wall timer, and at start).

        Parameters
        ----------
        use_sim_time : bool
            The node's ``use_sim_time`` parameter.
        clock_ns : int
            The node clock now [ns].

        """
        if not use_sim_time or clock_ns > 0:
            if self.last_warning is not None:
                self.info(CLOCK_STARTED)
            self.missing_since = self.last_warning = None
            return
        now = time.monotonic()
        if self.missing_since is None:
            self.missing_since = now
        if now - self.missing_since < self.grace_s:
            return
        if self.last_warning is None or now - self.last_warning >= self.period_s:
            self.warn(NO_CLOCK_WARNING)
            self.last_warning = now
            self.warnings += 1
