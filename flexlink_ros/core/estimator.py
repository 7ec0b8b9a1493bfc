"""
Streaming estimation of the crank's motion and of the linkage's elastic response.

:class:`CrankRateFilter` turns a stream of (time, crank angle[, crank speed]) samples with
jitter, drops and wrap-around into the unwrapped angle, speed and acceleration the model needs.
"""

import math

# Default time constant of the exponentially weighted fit [s]: about 20 samples at 1 kHz,
# short against the 150 ms revolution at 391 rpm.
DEFAULT_FIT_TIME_CONSTANT_S = 0.02
# The fit always spans at least this many recent samples, whatever the sample rate.
MIN_FIT_SAMPLES = 4.0
TWO_PI = 2.0 * math.pi


def wrap_angle(angle):
    """Angle wrapped to [0, 2 pi)."""
    wrapped = math.fmod(angle, TWO_PI)
    if wrapped < 0.0:
        wrapped += TWO_PI
    return wrapped if wrapped < TWO_PI else 0.0


def _wrap_pi(angle):
    """Angle wrapped to [-pi, pi)."""
    return (angle + math.pi) % TWO_PI - math.pi


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
                s0, s1, s2, s3, s4 = self.s
                t0, t1, t2 = self.t
                # Re-refer the values (y - dy) with the old moments, then move the origin.
                t0, t1, t2 = t0 - dy * s0, t1 - dy * s1, t2 - dy * s2
                d2 = d * d
                self.s = [f * s0, f * (s1 + d * s0), f * (s2 + 2 * d * s1 + d2 * s0),
                          f * (s3 + 3 * d * s2 + 3 * d2 * s1 + d2 * d * s0),
                          f * (s4 + 4 * d * s3 + 6 * d2 * s2 + 4 * d2 * d * s1 + d2 * d2 * s0)]
                self.t = [f * t0, f * (t1 + d * t0), f * (t2 + 2 * d * t1 + d2 * t0)]
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
        s, t = self.s, self.t
        if self.degree == 2 and self.count >= 3:
            a00, a01, a02, a12, a22 = s[0], s[1], s[2], s[3], s[4]
            a11 = a02
            m00 = a11 * a22 - a12 * a12
            m01 = a02 * a12 - a01 * a22
            m02 = a01 * a12 - a02 * a11
            det = a00 * m00 + a01 * m01 + a02 * m02
            if abs(det) > 1e-12 * abs(a00 * a11 * a22):
                m11 = a00 * a22 - a02 * a02
                m12 = a01 * a02 - a00 * a12
                m22 = a00 * a11 - a01 * a01
                t0, t1, t2 = t
                return ((m00 * t0 + m01 * t1 + m02 * t2) / det,
                        (m01 * t0 + m11 * t1 + m12 * t2) / det,
                        (m02 * t0 + m12 * t1 + m22 * t2) / det)
        # Linear fit (degree 1, or too few distinct samples for a parabola).
        if self.count == 0:
            return 0.0, 0.0, 0.0
        det = s[0] * s[2] - s[1] * s[1]
        if self.count < 2 or abs(det) <= 1e-12 * s[0] * s[2]:
            return t[0] / s[0], 0.0, 0.0
        c1 = (s[0] * t[1] - s[1] * t[0]) / det
        return (t[0] - s[1] * c1) / s[0], c1, 0.0


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
        self._mean_dt = None

    def update(self, time_s, angle, speed=None):
        """
        Add a sample; returns (wrapped angle, speed, acceleration).

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
            self._time, self._angle, self._mode = time_s, float(angle), mode
            self.speed, self.accel = (float(speed), 0.0) if has_speed else (0.0, 0.0)
            if has_speed:
                self._speed_fit.add(0.0, 1.0, 0.0, 0.0)
            else:
                self._angle_fit.add(0.0, 1.0, 0.0, 0.0)
            return wrap_angle(self._angle), self.speed, self.accel
        dt = time_s - self._time
        self._mean_dt = dt if self._mean_dt is None else 0.9 * self._mean_dt + 0.1 * dt
        tau = max(self.time_constant_s, MIN_FIT_SAMPLES * self._mean_dt)
        forget = math.exp(-dt / tau)
        shift = dt / self.time_constant_s  # fixed time scale keeps the stored moments valid
        if has_speed:
            predicted = 0.5 * (self.speed + speed) * dt
        else:
            predicted = self.speed * dt + 0.5 * self.accel * dt * dt
        advance = predicted + _wrap_pi(angle - self._angle - predicted)
        self._angle += advance
        self._time = time_s
        if mode != self._mode:
            self._speed_fit.reset()
            self._angle_fit.reset()
            self._mode = mode
            shift = 0.0
        if has_speed:
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
        return wrap_angle(self._angle), self.speed, self.accel
