"""
When each recorded message and each ``/clock`` tick of a playback goes out, as `ros2 bag play`.

One pass of a playback is a sequence of events at wall times measured from the pass's start:
message ``n`` at ``(log_ns[n] - log_ns[0]) / rate``, and with a clock, ``/clock`` carrying the
recording's time. ``ros2 bag play --clock [HZ]`` (default 40 Hz) publishes the player's time at
a fixed wall-clock frequency; ``--clock-topics-all`` publishes it just before each replayed
message. Both are here: tick ``k`` goes out at wall time ``k / HZ`` and carries
``log_ns[0] + k * rate / HZ`` (the recording's time at that wall time, from the schedule, not
from when the tick happened to be sent, so a late process publishes the same times); a
per-message tick carries the message's log time. Ticks stop with the pass's last message.

Log times that make no sense (one going back, as crafted ones by 1 ms per message or after a
first log time of 2**63 - 1) would play as one burst: :func:`playback_times` then takes the
header stamps if they run forward, else a constant period (the median positive spacing), and
says which in one line.

No rclpy here: :mod:`ros.republish` sleeps until each event and publishes it.
"""

import math

import numpy as np

DEFAULT_CLOCK_HZ = 40.0     # `ros2 bag play --clock` without a value
# Highest fixed /clock frequency [Hz] of wall time. A time source takes each tick in a
# callback, and one Python publisher manages some 10^4 messages/s in all: at 1 kHz (the
# node's input rate) the ticks cost the player about a tenth of that, beyond it they delay
# the messages (1 MHz made a 2 s playback take 36 s). Exact per-message time:
# --clock-topics-all.
MAX_CLOCK_HZ = 1000.0
# Spacing of messages when neither log times nor stamps run forward and none is positive.
FALLBACK_PERIOD_NS = 1_000_000
MESSAGE = 'message'
CLOCK = 'clock'


def tick_recording_ns(start_ns, tick, rate, clock_hz):
    """
    Return the recording time [ns] carried by ``/clock`` tick ``tick`` of a pass.

    The player's clock runs at ``rate`` times the wall clock from the recording's first log
    time, and tick ``k`` goes out ``k / clock_hz`` seconds of wall time into the pass.

    """
    return start_ns + int(round(tick * rate / clock_hz * 1e9))


def ticks_in_pass(span_ns, rate, clock_hz):
    """
    Return the number of fixed-frequency ``/clock`` ticks in one pass spanning ``span_ns``.

    Ticks ``0 … K`` with ``K / clock_hz <= span / rate``: a quarter as many at rate 4.

    """
    if clock_hz <= 0:
        return 0
    return int(math.floor(max(span_ns, 0) * 1e-9 / rate * clock_hz + 1e-9)) + 1


def pass_events(log_ns, rate=1.0, clock_hz=0.0, clock_per_message=False):
    """
    Yield the events of one pass in the order they go out.

    Parameters
    ----------
    log_ns : array_like of int
        Log (receive) times of the recorded messages [ns], in file order.
    rate : float
        Playback speed factor (2: twice as fast), > 0.
    clock_hz : float
        Frequency of the fixed ``/clock`` ticks [Hz] of wall time; 0: none.
    clock_per_message : bool
        Publish ``/clock`` just before every message too.

    Yields
    ------
    wall_s : float
        When the event is due, from the start of the pass [s].
    kind : str
        ``MESSAGE`` or ``CLOCK``.
    value : int
        The message's index, or the clock's time [ns]. Clock times never go back within a
        pass (a message logged before an earlier one leaves the clock where it was).

    """
    if not rate > 0:
        raise ValueError(f'the playback rate must be positive, got {rate}')
    if not 0 <= clock_hz <= MAX_CLOCK_HZ:
        raise ValueError(f'the /clock frequency must be in 0..{MAX_CLOCK_HZ:g} Hz, got {clock_hz}')
    log_ns = np.asarray(log_ns, dtype=np.int64)
    if log_ns.size == 0:
        return
    start = int(log_ns[0])
    last_clock = start
    tick = 0
    for index, logged in enumerate(log_ns.tolist()):
        wall_s = max(logged - start, 0) * 1e-9 / rate
        while clock_hz > 0 and tick <= wall_s * clock_hz + 1e-9:
            last_clock = max(last_clock, tick_recording_ns(start, tick, rate, clock_hz))
            yield tick / clock_hz, CLOCK, last_clock
            tick += 1
        if clock_per_message:
            last_clock = max(last_clock, logged)
            yield wall_s, CLOCK, last_clock
        yield wall_s, MESSAGE, index


def _goes_back(times_ns):
    """Index of the first time before the one preceding it, or None."""
    back = np.flatnonzero(np.diff(times_ns) < 0)
    return int(back[0]) + 1 if back.size else None


def playback_times(log_ns, stamps_ns=None):
    """
    Return the times [ns] to play messages at, in stored order, and a note if not the logs'.

    Log times that go back (the recording was crafted or its clock jumped) would make the
    rest of a pass one burst. Then the header stamps are used if they never go back, else a
    constant period: the median positive spacing of the log times (or 1 ms if none).

    Parameters
    ----------
    log_ns : array_like of int
        Log times in stored order [ns].
    stamps_ns : array_like of int or None
        Header stamps of the same messages [ns].

    Returns
    -------
    times_ns : ndarray of int64
    note : str
        '' when the log times are used, else one line saying why and what instead.

    """
    log_ns = np.asarray(log_ns, dtype=np.int64)
    first = _goes_back(log_ns)
    if first is None:
        return log_ns, ''
    why = (f'log times go back {int(np.count_nonzero(np.diff(log_ns) < 0))} time(s), first '
           f'at message {first}')
    if stamps_ns is not None and len(stamps_ns) == log_ns.size:
        stamps_ns = np.asarray(stamps_ns, dtype=np.int64)
        if _goes_back(stamps_ns) is None:
            return stamps_ns, f'{why}: played at the spacing of the header stamps'
    steps = np.diff(log_ns)
    positive = steps[steps > 0]
    period = int(np.median(positive)) if positive.size else FALLBACK_PERIOD_NS
    # From the first stamp if it is a time at all (/clock carries these times).
    base = int(stamps_ns[0]) if stamps_ns is not None and len(stamps_ns) and 0 < int(
        stamps_ns[0]) < (1 << 62) else 0
    return (base + np.arange(log_ns.size, dtype=np.int64) * period,
            f'{why}, stamps too: played in stored order every {period * 1e-6:.6g} ms '
            '(the median positive spacing of the log times)')
