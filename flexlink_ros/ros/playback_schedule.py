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

No rclpy here: :mod:`ros.republish` sleeps until each event and publishes it.
"""

import math

import numpy as np

DEFAULT_CLOCK_HZ = 40.0     # `ros2 bag play --clock` without a value
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
