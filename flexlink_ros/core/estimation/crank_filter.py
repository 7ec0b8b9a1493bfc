"""
The crank's unwrapped angle, speed and acceleration from jittery, gappy samples.

:class:`CrankRateFilter` is an exponentially weighted local least-squares polynomial fit,
updated recursively (:class:`_ForgettingPolyFit`); :class:`CompiledCrankRateFilter` is the
same filter in C (_radau_step.c), the same doubles.
"""

import math

import numpy as np

from . import native
from ..numerics import wrap_to_2pi, wrap_to_pi

# Default time constant of the exponentially weighted fit [s]: about 20 samples at 1 kHz,
# short against the 150 ms revolution at 391 rpm.
DEFAULT_FIT_TIME_CONSTANT_S = 0.02
# The fit always spans at least this many recent samples, whatever the sample rate.
MIN_FIT_SAMPLES = 4.0


def _shift_quadratic_moments(s, t, d, f, dy):
    """
    Shift the moments of a degree-2 fit: origin moved by ``d``, values by ``dy``, weights by ``f``.

    The values are re-referred to ``y - dy`` and every weight is multiplied by ``f`` (before
    the new sample is added).

    ``s`` = (s0..s4), ``t`` = (t0..t2); returns the new ``(s, t)`` tuples.
    """
    s0, s1, s2, s3, s4 = s
    t0, t1, t2 = t
    # Re-refer the values (y - dy) with the old moments, then move the origin.
    t0, t1, t2 = t0 - dy * s0, t1 - dy * s1, t2 - dy * s2
    d2 = d * d
    return ((f * s0, f * (s1 + d * s0), f * (s2 + 2 * d * s1 + d2 * s0),
             f * (s3 + 3 * d * s2 + 3 * d2 * s1 + d2 * d * s0),
             f * (s4 + 4 * d * s3 + 6 * d2 * s2 + 4 * d2 * d * s1 + d2 * d2 * s0)),
            (f * t0, f * (t1 + d * t0), f * (t2 + 2 * d * t1 + d2 * t0)))


def _parabola_coefficients(s, t):
    """(c0, c1, c2) of the weighted parabola through moments ``s``, ``t``; None if singular."""
    a00, a01, a02, a12, a22 = s
    a11 = a02
    m00 = a11 * a22 - a12 * a12
    m01 = a02 * a12 - a01 * a22
    m02 = a01 * a12 - a02 * a11
    det = a00 * m00 + a01 * m01 + a02 * m02
    if not abs(det) > 1e-12 * abs(a00 * a11 * a22):
        return None
    m11 = a00 * a22 - a02 * a02
    m12 = a01 * a02 - a00 * a12
    m22 = a00 * a11 - a01 * a01
    t0, t1, t2 = t
    return ((m00 * t0 + m01 * t1 + m02 * t2) / det,
            (m01 * t0 + m11 * t1 + m12 * t2) / det,
            (m02 * t0 + m12 * t1 + m22 * t2) / det)


def _line_coefficients(s, t, count):
    """(c0, c1) of the weighted line through moments ``s``, ``t`` (constant if degenerate)."""
    if count == 0:
        return 0.0, 0.0
    det = s[0] * s[2] - s[1] * s[1]
    if count < 2 or abs(det) <= 1e-12 * s[0] * s[2]:
        return t[0] / s[0], 0.0
    c1 = (s[0] * t[1] - s[1] * t[0]) / det
    return (t[0] - s[1] * c1) / s[0], c1


class _ForgettingPolyFit:
    """
    Exponentially weighted least-squares polynomial of degree 1 or 2, updated recursively.

    Keeps the weighted moments ``S_k = sum w_i u_i^k`` (k <= 2 d) and ``T_k = sum w_i y_i u_i^k``
    (k <= d) about the newest sample (u = scaled time since it, <= 0). A new sample shifts the
    origin (binomial re-expansion of the moments), multiplies every weight by the forgetting
    factor and adds itself at u = 0. The fit is exact for data that are a polynomial of the
    fitted degree, for any spacing of the samples.
    """

    def __init__(self, degree):
        self.degree = degree
        self.reset()

    def reset(self):
        self.s = [0.0] * (2 * self.degree + 1)
        self.t = [0.0] * (self.degree + 1)
        self.count = 0

    def add(self, shift, forget, value_shift, value):
        """
        Add a sample ``shift`` (scaled time) after the previous one.

        The origin moves to the new sample (u' = u - shift), the stored values are re-referred
        to ``y' = y - value_shift``, every weight is multiplied by ``forget`` and the sample
        ``value`` (already relative to the new reference) enters with weight 1 at u' = 0.
        """
        if self.count:
            d, f, dy = -shift, forget, value_shift
            if self.degree == 2:
                moments, values = _shift_quadratic_moments(self.s, self.t, d, f, dy)
                self.s, self.t = list(moments), list(values)
            else:
                s0, s1, s2 = self.s
                t0, t1 = self.t
                t0, t1 = t0 - dy * s0, t1 - dy * s1
                self.s = [f * s0, f * (s1 + d * s0), f * (s2 + 2 * d * s1 + d * d * s0)]
                self.t = [f * t0, f * (t1 + d * t0)]
        self.s[0] += 1.0
        self.t[0] += value
        self.count += 1

    def coefficients(self):
        """Fitted (c0, c1, c2) of y = c0 + c1 u + c2 u^2 at the newest sample (c2 = 0: line)."""
        if self.degree == 2 and self.count >= 3:
            coefficients = _parabola_coefficients(self.s, self.t)
            if coefficients is not None:
                return coefficients
        # Linear fit (degree 1, or too few distinct samples for a parabola).
        return (*_line_coefficients(self.s, self.t, self.count), 0.0)


class CrankRateFilter:
    """
    Unwrapped crank angle, speed and acceleration from jittery, gappy samples.

    The filter is an exponentially weighted local least-squares fit, updated recursively in
    O(1) per sample and exact for any sample spacing when the signal is a polynomial of the
    fitted degree:

    - with a measured speed, a parabola w(t) is fitted to the recent speeds; the speed
      reported is the measurement and the acceleration is the parabola's slope at the newest
      sample (exact for constant jerk: no lag on ramps, little on slow speed ripple);
    - without one (a JointState without velocity), a parabola theta(t) is fitted to the
      unwrapped angles; speed and acceleration are its first and second derivatives at the
      newest sample (exact for constant acceleration; lags about tau behind a changing one).

    Sample weights decay as exp(-age / tau) with ``tau = max(time_constant_s, 4 mean_dt)``, so
    the fit always spans a few samples at slow rates. Angles may come in any range (wrapped or
    not); they are unwrapped with the predicted advance, which requires the crank to turn less
    than half a revolution between samples when no speed is measured.

    Parameters
    ----------
    time_constant_s : float
        Time constant tau of the weights [s]; longer is smoother and lags more.

    """

    def __init__(self, time_constant_s=DEFAULT_FIT_TIME_CONSTANT_S):
        if not time_constant_s > 0.0:
            raise ValueError(f'`time_constant_s` must be positive, got {time_constant_s!r}')
        self.time_constant_s = float(time_constant_s)
        self._speed_fit = _ForgettingPolyFit(2)
        self._angle_fit = _ForgettingPolyFit(2)
        self.reset()

    def reset(self):
        """Forget every sample."""
        self._speed_fit.reset()
        self._angle_fit.reset()
        self._mode = None
        self._time = None
        self._angle = 0.0        # unwrapped angle of the newest sample [rad]
        self.speed = 0.0         # [rad/s]
        self.accel = 0.0         # [rad/s^2]
        self.advance = 0.0       # unwrapped angle increment of the newest sample [rad]
        self._mean_dt = None

    @property
    def count(self):
        """Count the samples in the active fit since the last reset or change of input kind."""
        return (self._speed_fit if self._mode == 'speed' else self._angle_fit).count

    def update(self, time_s, angle, speed=None):
        """
        Add a sample; return (wrapped angle, speed, acceleration).

        Parameters
        ----------
        time_s : float
            Sample time [s], strictly after the previous sample's (the caller resets on
            repeated or backward times).
        angle : float
            Measured crank angle [rad], any range.
        speed : float or None
            Measured crank speed [rad/s], or None (or NaN) when the input has none.

        Returns
        -------
        angle, speed, accel : float
            Crank angle wrapped to [0, 2 pi) [rad], speed [rad/s], acceleration [rad/s^2].

        """
        has_speed = speed is not None and math.isfinite(speed)
        mode = 'speed' if has_speed else 'angle'
        if self._time is None:
            self._start(time_s, angle, speed, mode)
            return wrap_to_2pi(self._angle), self.speed, self.accel
        dt = time_s - self._time
        shift, forget = self._forgetting(dt)
        advance = self._accept(time_s, dt, angle, speed)
        if mode != self._mode:
            self._speed_fit.reset()
            self._angle_fit.reset()
            self._mode = mode
            shift = 0.0
        self._refit(dt, shift, forget, advance, speed)
        return wrap_to_2pi(self._angle), self.speed, self.accel

    def _start(self, time_s, angle, speed, mode):
        """Take the first sample since a reset: speed as measured (or 0), no acceleration."""
        has_speed = mode == 'speed'
        self._time, self._angle, self._mode = time_s, float(angle), mode
        self.speed, self.accel = (float(speed), 0.0) if has_speed else (0.0, 0.0)
        if has_speed:
            self._speed_fit.add(0.0, 1.0, 0.0, 0.0)
        else:
            self._angle_fit.add(0.0, 1.0, 0.0, 0.0)

    def _forgetting(self, dt):
        """Return (shift, forget): the fit's time shift and the weights' decay over ``dt``."""
        self._mean_dt = dt if self._mean_dt is None else 0.9 * self._mean_dt + 0.1 * dt
        tau = max(self.time_constant_s, MIN_FIT_SAMPLES * self._mean_dt)
        forget = math.exp(-dt / tau)
        shift = dt / self.time_constant_s  # fixed time scale keeps the stored moments valid
        return shift, forget

    def _accept(self, time_s, dt, angle, speed):
        """
        Unwrap the sample's angle with the predicted advance; return the advance [rad].

        The prediction is the mean of the measured speeds times ``dt``, or without a measured
        speed the filter's speed and acceleration carried over ``dt``.
        """
        if speed is not None and math.isfinite(speed):
            predicted = 0.5 * (self.speed + speed) * dt
        else:
            predicted = self.speed * dt + 0.5 * self.accel * dt * dt
        advance = predicted + wrap_to_pi(angle - self._angle - predicted)
        self._angle += advance
        self.advance = advance
        self._time = time_s
        return advance

    def _refit(self, dt, shift, forget, advance, speed):
        """Add the sample to the active fit; take speed and acceleration from it."""
        if speed is not None and math.isfinite(speed):
            self._speed_fit.add(shift, forget, speed - self.speed, 0.0)
            _, slope, _ = self._speed_fit.coefficients()
            self.speed = float(speed)
            self.accel = slope / self.time_constant_s
        else:
            self._angle_fit.add(shift, forget, advance, 0.0)
            _, c1, c2 = self._angle_fit.coefficients()
            if self._angle_fit.count < 2:
                self.speed, self.accel = advance / dt, 0.0
            else:
                self.speed = c1 / self.time_constant_s
                self.accel = 2.0 * c2 / self.time_constant_s ** 2

    def signal(self, times, angles, speeds=None):
        """
        Run update() over arrays: rows of (wrapped angle, speed, accel, advance).

        Parameters
        ----------
        times : array_like
            Sample times [s].
        angles : array_like
            Measured crank angles [rad].
        speeds : array_like or None
            None, or per sample a speed [rad/s] or NaN where there is none.

        """
        speeds = [None] * len(times) if speeds is None else np.asarray(speeds).tolist()
        motion = np.empty((len(times), 4))
        for n, (time_s, angle, speed) in enumerate(zip(np.asarray(times).tolist(),
                                                       np.asarray(angles).tolist(), speeds)):
            motion[n, :3] = self.update(time_s, angle, speed)
            motion[n, 3] = self.advance
        return motion


class CompiledCrankRateFilter:
    """
    :class:`CrankRateFilter` in C (_radau_step.c): the same arithmetic, the same doubles.

    The state is one float64 array (layout: native.FILTER_*), so a sample costs one call:
    1.1 us per update against 6 us for the Python filter, timed on the development machine.
    Needs the compiled extension (:func:`native.compiled_step_available`).

    Parameters
    ----------
    time_constant_s : float
        Time constant tau of the weights [s]; longer is smoother and lags more.

    """

    def __init__(self, time_constant_s=DEFAULT_FIT_TIME_CONSTANT_S):
        if native.impl is None:
            raise RuntimeError('the compiled step (core/estimation/_radau_step.c) is not built')
        if not time_constant_s > 0.0:
            raise ValueError(f'`time_constant_s` must be positive, got {time_constant_s!r}')
        self.time_constant_s = float(time_constant_s)
        self._state = np.zeros(native.FILTER_STATE)
        self._update = native.impl.filter_update
        self.reset()

    def reset(self):
        """Forget every sample."""
        state = self._state
        state[:] = 0.0
        state[native.FILTER_MEAN_DT] = math.nan
        state[native.FILTER_TC] = self.time_constant_s
        state[native.FILTER_MIN_SAMPLES] = MIN_FIT_SAMPLES

    state = property(lambda self: self._state,
                     doc='The state array (native.FILTER_*; the compiled update shares it).')

    @property
    def count(self):
        """Count the samples in the active fit since the last reset or change of input kind."""
        fit = (native.FILTER_SPEED_FIT if self._state[native.FILTER_MODE] == native.MODE_SPEED
               else native.FILTER_ANGLE_FIT)
        return int(self._state[fit + native.FIT_COUNT])

    @property
    def speed(self):
        """Speed of the newest sample [rad/s]."""
        return float(self._state[native.FILTER_SPEED])

    @property
    def accel(self):
        """Acceleration of the newest sample [rad/s^2]."""
        return float(self._state[native.FILTER_ACCEL])

    @property
    def advance(self):
        """Unwrapped angle increment of the newest sample [rad]."""
        return float(self._state[native.FILTER_ADVANCE])

    def update(self, time_s, angle, speed=None):
        """
        Add a sample; return (wrapped angle, speed, accel), as :meth:`CrankRateFilter.update`.

        Parameters
        ----------
        time_s : float
            Sample time [s].
        angle : float
            Measured crank angle [rad], any range.
        speed : float or None
            Measured crank speed [rad/s], or None (or NaN).

        """
        return self._update(self._state, time_s, angle, math.nan if speed is None else speed)

    def signal(self, times, angles, speeds=None):
        """
        Run update() over arrays: rows of (wrapped angle, speed, accel, advance).

        Parameters
        ----------
        times : array_like
            Sample times [s].
        angles : array_like
            Measured crank angles [rad].
        speeds : array_like or None
            Measured speeds [rad/s], NaN where a sample has none; None for none at all.

        """
        times = np.ascontiguousarray(times, dtype=float)
        angles = np.ascontiguousarray(angles, dtype=float)
        # None (no speed) becomes NaN, which the filter reads as not measured.
        speeds = (np.full(times.shape, math.nan) if speeds is None
                  else np.ascontiguousarray(speeds, dtype=float))
        motion = np.empty((times.size, 4))
        native.impl.filter_signal(self._state, times, angles, speeds, motion)
        return motion
