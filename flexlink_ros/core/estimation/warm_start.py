"""
Warm starts: the periodic steady state at the current speed, reused and rate-limited.

A warm start shoots over one revolution (about 0.1 s); :class:`WarmStart` keeps the orbit it
found, so a restart at nearly the same speed interpolates it instead, and asks a
:class:`WarmStartLimiter` before shooting, so a storm of restarts degrades to cold starts.
"""

import logging
import math
import time

import numpy as np

from .sample import COLD_START, WARM_START
from .throttled_log import ThrottledWarning
from ..numerics import TWO_PI
from ..reduction.periodic import periodic_response

LOGGER = logging.getLogger(__name__)

# Steps per revolution of the warm-start shooting. The estimate then steps at its samples'
# rate (153 steps a revolution at 391 rpm and 1 kHz), and its first revolution differs from
# its steady state by 0.2-1 % of the peak-to-peak deflection at 269-600 rpm whatever this
# count: 360 steps put the state within 2e-4 of that range of 720 steps' (order 3: 720 would
# be within 3e-5 of the exact orbit), for half the cost of each warm start.
WARM_START_STEPS = 360
# A warm start reuses the periodic orbit of the last one (interpolated at the new angle)
# when the speed differs by less than this fraction: a restart after a gap or a looped
# recording costs a fraction of a millisecond instead of the shooting's ~0.2 s.
WARM_START_SPEED_TOLERANCE = 1e-4
# Warm starts that shoot (about 0.1 s each) come from a token bucket: this many at once ...
WARM_START_BURST = 3
# ... then this many per second; beyond it the state starts cold (static deflection).
WARM_START_RATE_HZ = 1.0


class WarmStartLimiter:
    """
    Token bucket of warm starts that shoot (about 0.1 s each): a storm degrades to cold starts.

    ``burst`` at once, then ``rate_hz`` per second of ``clock`` (seconds): the node uses
    ``time.monotonic``, the offline replay the recording's stamps. Counts what it refused.

    Parameters
    ----------
    burst : float
        Warm starts allowed at once.
    rate_hz : float
        Warm starts allowed per second after the burst.
    clock : callable
        Time [s].

    """

    def __init__(self, burst=WARM_START_BURST, rate_hz=WARM_START_RATE_HZ, clock=time.monotonic):
        self.burst, self.rate_hz, self.clock = float(burst), float(rate_hz), clock
        self._tokens = self.burst
        self._time = None
        self.refused = 0

    def take(self):
        """Take a token if a warm start may shoot now; return whether it may."""
        now = self.clock()
        if self._time is not None:
            self._tokens = min(self.burst,
                               self._tokens + max(0.0, now - self._time) * self.rate_hz)
        self._time = now
        if self._tokens >= 1.0:
            self._tokens -= 1.0
            return True
        self.refused += 1
        return False


def orbit_state(orbit, angle):
    """
    Return (q, v) at crank ``angle`` on a kept periodic orbit, by cubic Hermite interpolation.

    Parameters
    ----------
    orbit : tuple
        (speed, start angle, q, v) of a periodic orbit (v is dq/dt).
    angle : float
        Crank angle [rad].

    """
    orbit_speed, start, q, v = orbit
    steps = q.shape[0] - 1
    # Steps of the orbit from its start to this angle, in its direction of travel.
    x = ((angle - start) * math.copysign(1.0, orbit_speed)) % TWO_PI / TWO_PI * steps
    k = min(int(x), steps - 1)
    t = x - k
    h = TWO_PI / steps / abs(orbit_speed)
    t2, t3 = t * t, t * t * t
    q0 = ((2 * t3 - 3 * t2 + 1) * q[k] + (t3 - 2 * t2 + t) * h * v[k]
          + (-2 * t3 + 3 * t2) * q[k + 1] + (t3 - t2) * h * v[k + 1])
    return q0, (1.0 - t) * v[k] + t * v[k + 1]


class WarmStart:
    """
    An estimator's warm-start decisions: the kept orbit, the rate limit and the counts.

    Parameters
    ----------
    limiter : WarmStartLimiter or None
        Rate limit of the warm starts that shoot; a new one (wall clock) if None.

    Attributes
    ----------
    orbit : tuple or None
        (speed, start angle, q, v) of the last periodic orbit found by shooting.
    warm_starts, cold_starts : int
        Warm starts that shot, and warm starts the rate limit turned into cold starts.

    """

    def __init__(self, limiter=None):
        self.limiter = WarmStartLimiter() if limiter is None else limiter
        self.orbit = None
        self.warm_starts = self.cold_starts = 0
        self._warning = ThrottledWarning(LOGGER)

    def serves(self, speed):
        """Tell whether the kept periodic orbit serves a warm start at ``speed`` (no shooting)."""
        orbit = self.orbit
        return (orbit is not None
                and abs(orbit[0] - speed) <= WARM_START_SPEED_TOLERANCE * abs(speed))

    def allowed(self, speed):
        """Tell whether a warm start at ``speed`` is cheap or the rate limit allows a shooting."""
        if self.serves(speed) or self.limiter.take():
            return True
        self.cold_starts += 1
        self._warning.warn('warm start skipped (at most %d at once, then %g per second): cold '
                           'start from the static deflection (%d so far)', WARM_START_BURST,
                           WARM_START_RATE_HZ, self.cold_starts)
        return False

    def periodic_state(self, model, blocks, angle, speed):
        """
        Return (q, v) of the periodic steady state at crank ``angle`` and constant ``speed``.

        Shooting over one revolution (periodic_response, WARM_START_STEPS steps); the
        orbit is kept, and a later call within WARM_START_SPEED_TOLERANCE of its speed takes
        the state from it by cubic Hermite interpolation in time (:func:`orbit_state`).

        Parameters
        ----------
        model : ReducedModel
            The reduced model.
        blocks : callable
            ``blocks(theta, w, a)``: M, C, K, f at crank angles (the step tables').
        angle : float
            Crank angle [rad].
        speed : float
            Constant crank speed [rad/s], not 0.

        """
        if not self.serves(speed):
            self.warm_starts += 1
            _, q, v = periodic_response(model, speed, start_angle=angle,
                                        steps=WARM_START_STEPS, blocks=blocks)
            self.orbit = (speed, angle, q, v)
            return q[0].copy(), v[0].copy()
        return orbit_state(self.orbit, angle)

    def initial_state(self, model, blocks, crank, warm):
        """
        Return (q0, v0, flags): the periodic state at the crank's speed, or the static one.

        ``flags`` is WARM_START, COLD_START (the rate limit refused the shooting) or 0 (a
        static start was asked for, or the crank stands still).

        Parameters
        ----------
        model : ReducedModel
            The reduced model.
        blocks : callable
            ``blocks(theta, w, a)``: M, C, K, f at crank angles (the step tables').
        crank : tuple of float
            (angle, speed, accel) of the crank, as the model sees it.
        warm : bool
            Start from the periodic state if the speed is not 0.

        """
        angle, speed, accel = crank
        flags = 0
        if warm and speed != 0.0:
            flags = WARM_START if self.allowed(speed) else COLD_START
        if flags == WARM_START:
            q0, v0 = self.periodic_state(model, blocks, angle, speed)
        else:
            _, _, stiffness, load = blocks(np.array([angle]), speed, accel)
            q0, v0 = np.linalg.solve(stiffness[0], load[0]), np.zeros(model.step_size)
        return q0, v0, flags
