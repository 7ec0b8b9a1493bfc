"""
Streaming estimation of the crank's motion and of the linkage's elastic response.

:class:`CrankRateFilter` turns a stream of (time, crank angle[, crank speed]) samples with
jitter, drops and wrap-around into the unwrapped angle, speed and acceleration the model needs.
:class:`StreamingEstimator` advances the reduced model (core/reduced.py) by one Radau IIA step
(core/integrators.py) per sample and returns a :class:`Sample` with the deflections, the joint
criteria and flags.

Per-sample path. Everything the step needs at the new sample (M, C, K, f, output operator,
residual correction, joint reactions) is one dot product of 4 x 7 weights with one grid cell
of a precomputed table, and the first Radau stage (at 1/3 of the step, crank state
interpolated between the samples) is a second such product. (Interpolating the stage-1
matrices linearly in time instead saves that product but, with flexible bearings near
resonance, shifted the response by up to 40 %: the ground-frame stiffness of the rotating
links is not linear over a step.) The two stages' block matrix and right-hand-side operator
come out of one small matrix product with coefficients that depend only on the step h.

The same step is compiled (core/estimation/_radau_step.c, built with the package): one call per sample
instead of about thirty numpy calls, the same arithmetic to rounding (a test compares the two).
Without the extension (a source tree that was not built) the numpy step runs.

Hostile input. :class:`InputGate` refuses implausible samples before the filter sees them
(:class:`OutlierSample`; the state is untouched), so one bad sample changes no later output;
an estimate beyond the model's deflection bound, or a non-finite one, is flagged OUT_OF_BOUND
with NaN deflections and the next sample restarts; warm starts that shoot are rate-limited
(:class:`WarmStartLimiter`), so a storm of restarts degrades to cold starts.
"""

import dataclasses
import enum
import logging
import math
import time

import numpy as np
from scipy.linalg import lapack

from ..numerics import TWO_PI, wrap_to_2pi, wrap_to_pi
from ..reduction import model as reduced
from ...errors import FlexlinkError, OutlierSample
from ..integrators import RADAU_TABLEAUX

try:
    from . import _radau_step
except ImportError:     # not built: the numpy step serves
    _radau_step = None

LOGGER = logging.getLogger(__name__)

# Default time constant of the exponentially weighted fit [s]: about 20 samples at 1 kHz,
# short against the 150 ms revolution at 391 rpm.
DEFAULT_FIT_TIME_CONSTANT_S = 0.02
# The fit always spans at least this many recent samples, whatever the sample rate.
MIN_FIT_SAMPLES = 4.0


def compiled_step_available():
    """True when the compiled step (core/estimation/_radau_step.c) is built and estimators use it."""
    return _radau_step is not None


def _hermite_basis(t):
    """Cubic Hermite basis h00, h10, h01, h11 at t in [0, 1] (floats or arrays)."""
    t2 = t * t
    t3 = t2 * t
    h01 = t2 * (3.0 - 2.0 * t)
    return 1.0 - h01, t - 2.0 * t2 + t3, h01, t3 - t2


def _shift_quadratic_moments(s, t, d, f, dy):
    """
    Moments of a degree-2 fit with the origin moved by ``d``, the values re-referred to
    ``y - dy`` and every weight multiplied by ``f`` (before the new sample is added).

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
        """Samples in the active fit since the last reset or change of input kind."""
        return (self._speed_fit if self._mode == 'speed' else self._angle_fit).count

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
            return wrap_to_2pi(self._angle), self.speed, self.accel
        dt = time_s - self._time
        self._mean_dt = dt if self._mean_dt is None else 0.9 * self._mean_dt + 0.1 * dt
        tau = max(self.time_constant_s, MIN_FIT_SAMPLES * self._mean_dt)
        forget = math.exp(-dt / tau)
        shift = dt / self.time_constant_s  # fixed time scale keeps the stored moments valid
        if has_speed:
            predicted = 0.5 * (self.speed + speed) * dt
        else:
            predicted = self.speed * dt + 0.5 * self.accel * dt * dt
        advance = predicted + wrap_to_pi(angle - self._angle - predicted)
        self._angle += advance
        self.advance = advance
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
        return wrap_to_2pi(self._angle), self.speed, self.accel

    def signal(self, times, angles, speeds=None):
        """update() over arrays: rows of (wrapped angle, speed, accel, advance).

        ``speeds`` None, or per sample a speed or NaN where there is none.
        """
        speeds = [None] * len(times) if speeds is None else np.asarray(speeds).tolist()
        motion = np.empty((len(times), 4))
        for n, (time_s, angle, speed) in enumerate(zip(np.asarray(times).tolist(),
                                                       np.asarray(angles).tolist(), speeds)):
            motion[n, :3] = self.update(time_s, angle, speed)
            motion[n, 3] = self.advance
        return motion


# The compiled filter's state (core/estimation/_radau_step.c, enum F_*): started, time, unwrapped angle,
# mode (0 none, 1 speed, 2 angle), speed, accel, advance, mean step, time constant, minimum
# samples, then the speed and the angle fit (s0..s4, t0..t2, count each).
_FILTER_MODE, _FILTER_SPEED, _FILTER_ACCEL, _FILTER_ADVANCE, _FILTER_MEAN_DT = 3, 4, 5, 6, 7
_FILTER_TC, _FILTER_MIN_SAMPLES, _FILTER_SPEED_FIT, _FILTER_ANGLE_FIT = 8, 9, 10, 19
_FILTER_STATE = 28


class CompiledCrankRateFilter:
    """
    :class:`CrankRateFilter` in C (core/estimation/_radau_step.c): the same arithmetic, the same doubles.

    The state is one float64 array, so a sample costs one call: 1.1 us per update against
    6 us for the Python filter, timed on the development machine. Needs the compiled extension
    (:func:`compiled_step_available`).
    """

    def __init__(self, time_constant_s=DEFAULT_FIT_TIME_CONSTANT_S):
        if _radau_step is None:
            raise RuntimeError('the compiled step (core/estimation/_radau_step.c) is not built')
        if not time_constant_s > 0.0:
            raise ValueError(f'`time_constant_s` must be positive, got {time_constant_s!r}')
        self.time_constant_s = float(time_constant_s)
        self._state = np.zeros(_FILTER_STATE)
        self._update = _radau_step.filter_update
        self.reset()

    def reset(self):
        """Forget every sample."""
        state = self._state
        state[:] = 0.0
        state[_FILTER_MEAN_DT] = math.nan
        state[_FILTER_TC] = self.time_constant_s
        state[_FILTER_MIN_SAMPLES] = MIN_FIT_SAMPLES

    @property
    def count(self):
        """Samples in the active fit since the last reset or change of input kind."""
        fit = _FILTER_SPEED_FIT if self._state[_FILTER_MODE] == 1.0 else _FILTER_ANGLE_FIT
        return int(self._state[fit + 8])

    @property
    def speed(self):
        return float(self._state[_FILTER_SPEED])

    @property
    def accel(self):
        return float(self._state[_FILTER_ACCEL])

    @property
    def advance(self):
        return float(self._state[_FILTER_ADVANCE])

    def update(self, time_s, angle, speed=None):
        """As :meth:`CrankRateFilter.update`."""
        return self._update(self._state, time_s, angle, math.nan if speed is None else speed)

    def signal(self, times, angles, speeds=None):
        """update() over arrays: rows of (wrapped angle, speed, accel, advance)."""
        times = np.ascontiguousarray(times, dtype=float)
        angles = np.ascontiguousarray(angles, dtype=float)
        # None (no speed) becomes NaN, which the filter reads as not measured.
        speeds = (np.full(times.shape, math.nan) if speeds is None
                  else np.ascontiguousarray(speeds, dtype=float))
        motion = np.empty((times.size, 4))
        _radau_step.filter_signal(self._state, times, angles, speeds, motion)
        return motion


# ---------------------------------------------------------------------------------------
# Streaming estimator

# A step longer than this is flagged as large (accuracy degrades; still stable) [s].
DEFAULT_LARGE_STEP_S = 0.01
# A gap longer than this restarts the estimate (state too stale to carry) [s].
DEFAULT_RESET_GAP_S = 0.5
# Crank accelerations beyond this are clipped (speed steps give filter spikes) [rad/s^2].
DEFAULT_ACCEL_LIMIT = 5000.0
# A joint reaction below this fraction of its cycle RMS at the current speed is "near zero".
DEFAULT_NEAR_ZERO_FRACTION = 0.05
# Reactions are clamped to this fraction of their cycle RMS in the criterion (finite at R = 0).
REACTION_FLOOR_FRACTION = 1e-6
# Output magnitude floor of the error indicator [m] (1 um: below it relative errors mean little).
ERROR_INDICATOR_FLOOR_M = 1e-6
# Steps longer than this are split into equal sub-steps, the crank state interpolated linearly
# between the samples: one Radau step across a gap loses the state of the fast modes (at
# 391 rpm, a 15 ms gap left an error of 28 % of the coupler's peak-to-peak for a revolution;
# 0.9 % with sub-steps) [ns].
MAX_SUBSTEP_NS = 2_000_000
# Steps per revolution of the warm-start shooting.
WARM_START_STEPS = 720
# A warm start reuses the periodic orbit of the last one (interpolated at the new angle)
# when the speed differs by less than this fraction: a restart after a gap or a looped
# recording costs a fraction of a millisecond instead of the shooting's ~0.2 s.
WARM_START_SPEED_TOLERANCE = 1e-4
# Samples per batch of the offline replay (bounds its memory to a few MB).
REPLAY_CHUNK = 4096
# Plausibility of an input sample (InputGate). A measured |speed| beyond this multiple of the
# model's speed_max is an outlier (between speed_max and it the model sees the clipped speed,
# as before): 2 leaves room for a model built a little short of the run's top speed.
SPEED_PLAUSIBLE_FACTOR = 2.0
# A measured speed may change between samples by this multiple of accel_limit times the
# interval ...
JUMP_ACCEL_FACTOR = 4.0
# ... plus this fraction of speed_max: a commanded step across the whole speed range in one
# sample still passes (it is clipped for the model, as before), a jump beyond it does not.
JUMP_ALLOWANCE_FRACTION = 1.0
# The angle may advance by the plausible speed times the interval plus this [rad].
ANGLE_ALLOWANCE_RAD = 0.05
# This many consecutive outliers that agree with each other are a new regime, not outliers:
# the estimate restarts from the last of them (a real change is never locked out).
REGIME_SAMPLES = 5
# Deflection bound: this factor times the resonant amplification 1 / (2 zeta) times the
# largest quasi-static deflection over the grid at constant speeds up to speed_max.
DEFLECTION_SAFETY_FACTOR = 2.0
# Speeds 0 ... speed_max at which the quasi-static deflection is evaluated.
QUASI_STATIC_SPEEDS = 5
# Warm starts that shoot (about 0.1 s each) come from a token bucket: this many at once ...
WARM_START_BURST = 3
# ... then this many per second; beyond it the state starts cold (static deflection).
WARM_START_RATE_HZ = 1.0
# At most one warning per this many seconds about skipped warm starts, and one about
# out-of-bound estimates [s].
WARNING_PERIOD_S = 1.0
# A sample's record (the compiled step's output; _StepTables.record in numpy): deflections
# with the residual correction (outputs), the correction alone (outputs), joint reactions
# (joints x 2), their time derivative (joints x 2) and squared cycle-RMS reactions (joints).
RECORD_SIZE = 2 * len(reduced.OUTPUT_NAMES) + 5 * len(reduced.JOINTS)


class SampleFlag(enum.IntFlag):
    """What happened at a sample."""

    NONE = 0
    RESET = 1            # state restarted (first sample, backward stamp, long gap)
    WARM_START = 2       # state set to the periodic steady state at the current speed
    LARGE_STEP = 4       # step longer than the large-step threshold
    CLIPPED_SPEED = 8    # |speed| beyond the model's range, clipped for the model
    CLIPPED_ACCEL = 16   # |acceleration| beyond the limit, clipped
    REPEATED = 32        # same stamp and angle again: previous estimate returned
    SPEED_FROM_ANGLE = 64  # no measured speed: differentiated from angles
    NO_CRITERIA = 128    # the model has no joint-reaction data: criteria are zero
    OUTLIER = 256        # an implausible input sample was skipped before this one
    OUT_OF_BOUND = 512   # deflection beyond the model's bound: not a number to publish; reset
    COLD_START = 1024    # warm start skipped (rate limit of warm starts): static start


# Node of the first Radau IIA stage (2 stages).
_STAGE1 = float(RADAU_TABLEAUX[2][1][0])
# Plain-int copies of the flags for the per-sample path (IntFlag arithmetic is slow).
_RESET, _WARM_START, _LARGE_STEP = int(SampleFlag.RESET), int(SampleFlag.WARM_START), \
    int(SampleFlag.LARGE_STEP)
_CLIPPED_SPEED, _CLIPPED_ACCEL = int(SampleFlag.CLIPPED_SPEED), int(SampleFlag.CLIPPED_ACCEL)
_REPEATED, _SPEED_FROM_ANGLE = int(SampleFlag.REPEATED), int(SampleFlag.SPEED_FROM_ANGLE)
_NO_CRITERIA = int(SampleFlag.NO_CRITERIA)
_OUTLIER, _OUT_OF_BOUND = int(SampleFlag.OUTLIER), int(SampleFlag.OUT_OF_BOUND)
_COLD_START = int(SampleFlag.COLD_START)


@dataclasses.dataclass(slots=True)
class Sample:
    """
    One estimate.

    Attributes
    ----------
    stamp_ns : int
        Input stamp [ns].
    crank_angle, crank_speed, crank_accel : float
        Wrapped angle [rad] in [0, 2 pi), speed [rad/s], acceleration [rad/s^2].
    lever_tip, coupler_mid : tuple of float
        Elastic deflection (dx, dy) of the lever's upper end and the coupler's mid-point in
        the ground frame [m].
    reaction_n, gamma_dot, criterion : tuple of float
        Per joint (O2, A, B, O4): rigid-body reaction magnitude R [N], rate of its direction
        [rad/s], and the Earles-Wu criterion |gamma-dot / R| [rad/(s N)].
    near_zero : tuple of bool
        Per joint: R below the near-zero fraction of its cycle RMS at this speed.
    error_indicator : float
        Size of the residual-flexibility correction relative to the deflection (see
        core/reduced.py); large values mean the reduced basis misses part of the response.
    flags : int
        What happened: bits of :class:`SampleFlag` (``sample.flags & SampleFlag.RESET``).
    message : str
        Warning text, empty if none.
    modal : tuple of float
        Reduced coordinates q (for :meth:`StreamingEstimator.link_shapes`).

    """

    stamp_ns: int
    crank_angle: float
    crank_speed: float
    crank_accel: float
    lever_tip: tuple
    coupler_mid: tuple
    reaction_n: tuple
    gamma_dot: tuple
    criterion: tuple
    near_zero: tuple
    error_indicator: float
    flags: int
    message: str
    modal: tuple


class InputGate:
    """
    Plausibility of input samples, checked before the crank filter sees them.

    A sample is an outlier (the filter and the model never see it) when its measured |speed|
    exceeds ``SPEED_PLAUSIBLE_FACTOR * speed_max``, when its speed differs from the last
    accepted one by more than ``JUMP_ACCEL_FACTOR * accel_limit * dt + JUMP_ALLOWANCE_FRACTION
    * speed_max``, or when its angle moved by more than ``SPEED_PLAUSIBLE_FACTOR * speed_max *
    dt + ANGLE_ALLOWANCE_RAD`` (modulo a revolution). ``REGIME_SAMPLES`` consecutive outliers
    that pass these tests against each other start a new regime (RESET | OUTLIER). Stamps that
    go back or leave a gap restart the estimate, as before; exact repeats are ignored.
    StreamingEstimator.update and the offline replay (:func:`plan_rows`) share this class.

    Parameters
    ----------
    speed_max : float
        The model's speed range [rad/s].
    accel_limit : float
        The estimator's acceleration clip [rad/s^2].
    reset_gap_s : float
        Gaps longer than this restart the estimate [s].

    """

    STEP, START, OUTLIER, REPEATED = 0, 1, 2, 3

    def __init__(self, speed_max, accel_limit, reset_gap_s=DEFAULT_RESET_GAP_S):
        self.speed_bound = SPEED_PLAUSIBLE_FACTOR * float(speed_max)
        self.jump_accel = JUMP_ACCEL_FACTOR * float(accel_limit)
        self.jump_allowance = JUMP_ALLOWANCE_FRACTION * float(speed_max)
        self.reset_gap_s = float(reset_gap_s)
        self.reset()

    def reset(self):
        """Forget the last accepted sample: the next one starts afresh."""
        self.last = None        # (stamp_ns, angle, speed) of the last accepted sample
        self.pending = []       # consecutive outliers that agree with each other
        self.skipped = 0        # outliers since the last accepted sample

    def implausible(self, reference, stamp_ns, angle, speed):
        """Why a sample cannot follow ``reference`` (stamp_ns, angle, speed); '' if it can."""
        dt = (stamp_ns - reference[0]) * 1e-9
        if not dt > 0.0:
            return f'stamp {stamp_ns} not after {reference[0]}'
        if speed is not None and reference[2] is not None:
            jump = abs(speed - reference[2])
            if jump > self.jump_accel * dt + self.jump_allowance:
                return f'speed jumped by {jump:.6g} rad/s in {dt:.6g} s'
        advance = abs(wrap_to_pi(angle - reference[1]))
        if advance > self.speed_bound * dt + ANGLE_ALLOWANCE_RAD:
            return f'angle moved by {advance:.6g} rad in {dt:.6g} s'
        return ''

    def decide(self, stamp_ns, angle, speed):
        """
        (kind, flags, message) of a sample: STEP, START, OUTLIER or REPEATED.

        An accepted sample (STEP, START) becomes the reference of the next; ``flags`` has
        RESET for START and OUTLIER when outliers were skipped before it.
        """
        if not math.isfinite(angle):
            return self._outlier(f'angle {angle!r} not finite')
        if speed is not None and not abs(speed) <= self.speed_bound:
            return self._outlier(f'speed {speed:.6g} rad/s beyond the plausible '
                                 f'{self.speed_bound:.6g} rad/s')
        kind, message, last = self.STEP, '', self.last
        if last is None:
            kind = self.START
        else:
            dt = (stamp_ns - last[0]) * 1e-9
            if dt == 0.0 and abs(wrap_to_2pi(angle) - wrap_to_2pi(last[1])) < 1e-12:
                return self.REPEATED, 0, 'repeated sample ignored'
            if dt <= 0.0 or dt > self.reset_gap_s:
                kind = self.START
                message = f'stamp went back by {-dt:.6g} s' if dt <= 0.0 else f'gap of {dt:.6g} s'
            else:
                reason = self.implausible(last, stamp_ns, angle, speed)
                if reason:
                    sample = (stamp_ns, angle, speed)
                    if self.pending and not self.implausible(self.pending[-1], *sample):
                        self.pending.append(sample)
                    else:
                        self.pending = [sample]
                    if len(self.pending) < REGIME_SAMPLES:
                        return self._outlier(reason)
                    kind = self.START
                    message = f'new regime after {REGIME_SAMPLES} consistent outliers ({reason})'
        # A new regime follows its REGIME_SAMPLES - 1 skipped outliers: RESET | OUTLIER.
        flags = (_OUTLIER if self.skipped else 0) | (_RESET if kind == self.START else 0)
        self.last, self.pending, self.skipped = (stamp_ns, angle, speed), [], 0
        return kind, flags, message

    def _outlier(self, reason):
        self.skipped += 1
        return self.OUTLIER, 0, reason

    def candidates(self, stamps_ns, angles, speeds):
        """
        Rows of a signal that might not be a plain STEP after the row before (vectorised).

        Conservative (thresholds scaled by 0.999): :func:`plan_rows` decides these rows one
        by one with :meth:`decide`; any other row after an accepted row is a STEP.
        """
        margin = 0.999
        has_speed = ~np.isnan(speeds)
        out = has_speed & ~(np.abs(speeds) <= margin * self.speed_bound)
        out |= ~np.isfinite(angles)
        dt = np.diff(stamps_ns) * 1e-9
        later = out[1:]
        later |= (dt <= 0.0) | (dt > margin * self.reset_gap_s)
        both = has_speed[1:] & has_speed[:-1]
        jump = np.abs(np.diff(np.where(has_speed, speeds, 0.0)))
        later |= both & (jump > margin * (self.jump_accel * dt + self.jump_allowance))
        advance = np.abs(np.mod(np.diff(angles) + math.pi, TWO_PI) - math.pi)
        later |= ~(advance <= margin * (self.speed_bound * dt + ANGLE_ALLOWANCE_RAD))
        out[0] = True
        return out


def plan_rows(stamps_ns, angles, speeds, gate):
    """
    What :meth:`StreamingEstimator.update` does with each row of a signal (its InputGate).

    Parameters
    ----------
    stamps_ns : ndarray of int, shape (m,)
    angles, speeds : ndarray, shape (m,)
        Speeds NaN where a sample has none.
    gate : InputGate
        Fresh or carried over; left at the end of the signal.

    Returns
    -------
    kinds : ndarray of int8, shape (m,)
        InputGate.STEP, START, OUTLIER or REPEATED per row.
    flags : ndarray of int, shape (m,)
        RESET and OUTLIER bits of the accepted rows (as :meth:`InputGate.decide`).

    """
    stamps_ns = np.asarray(stamps_ns, dtype=np.int64)
    angles = np.asarray(angles, dtype=float)
    speeds = np.asarray(speeds, dtype=float)
    count = stamps_ns.size
    kinds = np.zeros(count, dtype=np.int8)
    flags = np.zeros(count, dtype=np.int64)
    if count == 0:
        return kinds, flags
    candidates = gate.candidates(stamps_ns, angles, speeds)
    candidate_rows = np.flatnonzero(candidates)
    synced = False          # the gate's reference is the row before
    n = 0
    while n < count:
        if synced and not candidates[n]:
            # Every row up to the next candidate passes against the row before it.
            after = np.searchsorted(candidate_rows, n)
            stop = int(candidate_rows[after]) if after < candidate_rows.size else count
            speed = float(speeds[stop - 1])
            gate.last = (int(stamps_ns[stop - 1]), float(angles[stop - 1]),
                         None if math.isnan(speed) else speed)
            n = stop
            continue
        speed = float(speeds[n])
        kind, flag, _ = gate.decide(int(stamps_ns[n]), float(angles[n]),
                                    None if math.isnan(speed) else speed)
        kinds[n], flags[n] = kind, flag
        synced = kind in (gate.STEP, gate.START)
        n += 1
    return kinds, flags


class WarmStartLimiter:
    """
    Token bucket of warm starts that shoot (about 0.1 s each): a storm degrades to cold starts.

    ``burst`` at once, then ``rate_hz`` per second of ``clock`` (seconds): the node uses
    ``time.monotonic``, the offline replay the recording's stamps. Counts what it refused.
    """

    def __init__(self, burst=WARM_START_BURST, rate_hz=WARM_START_RATE_HZ, clock=time.monotonic):
        self.burst, self.rate_hz, self.clock = float(burst), float(rate_hz), clock
        self._tokens = self.burst
        self._time = None
        self.refused = 0

    def take(self):
        """True (and one token less) if a warm start may shoot now."""
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


class _StepTables:
    """
    Tables and coefficient stacks of the per-sample step (built once per model).

    M, C and [K | f] are kept at the grid nodes as cubic Hermite data: per monomial the
    node's value V and slope S (d/dt, cell units) of the model's periodic cubic spline (see
    core/reduced.py), which is C1, so cell k's cubic is exactly
    ``h00(t) V_k + h10(t) S_k + h01(t) V_k+1 + h11(t) S_k+1``. A cell then reads two rows
    per monomial of its own and two of the next node, which the next cell reads again:
    streaming through the cells (a new cell's tables are not in the core's own caches at
    most sample rates) reads half the bytes of the per-cell power form, and the tables take
    half the memory.
    ``mass`` M (monomial 1), ``damping`` C (1, w2, w, w4) and ``kf`` [K | f] (a, 1, w2):
    node x (monomial, V/S) x width. ``out`` (the output operator [O | corr], outputs x
    (r + 1), leading rows used) and ``joint`` [reactions F (joints x 2), their time
    derivative (joints x 2), squared cycle-RMS reaction (joints)] stay per cell in power form
    (rows ``monomial * 4 + power``; small, read once per sample).
    Two samples' [M, C, K, F] (F an r x r block holding f in its first r entries) in
    alternating slots times a 8 x 8 coefficient matrix G(h) give, in one product, the
    Radau IIA block matrix and the right-hand-side operator on (q, v).

    The unknowns are the state increment dz = (dq, dv) rather than the stage accelerations X:
    with ``dz = (D2 (x) I) X + (h v, 0)`` and ``D2 = [[h^2 (aa)_21, h^2 (aa)_22],
    [h a_21, h a_22]]`` (invertible for Radau IIA), the matrix becomes ``A (D2^-1 (x) I)`` and
    the operator gains ``h`` times its first block column, so the solve returns dz directly.
    G(h) is a Laurent polynomial in h (powers -2..2).
    """

    POWERS = (-2, -1, 0, 1, 2)
    FIRST_MC = 1               # M and C start at monomial 1
    GROUPS_C = 4               # C: monomials 1, w2, w, w4
    GROUPS_KF = 3              # K, f: monomials a, 1, w2

    def __init__(self, model, stages=2):
        if stages != 2:
            raise ValueError('the streaming step is written for 2-stage Radau IIA')
        if reduced.MONOMIALS[:5] != ('a', '1', 'w2', 'w', 'w4'):
            raise ValueError('monomial order changed: update _StepTables')
        if reduced.CELL_POWERS != 4:
            raise ValueError('the step tables are written for cubic cells')
        a, c = RADAU_TABLEAUX[stages]
        a2 = a @ a
        layout = model.layout
        r = model.size
        table = model.table
        n_cells, n_rows = table.shape[:2]
        self.size = r

        def block(name, rows=slice(0, n_rows)):
            return layout.block(table[:, rows], name).reshape(
                n_cells, rows.stop - rows.start, -1)

        def rows_used(name, first=0):
            used = np.flatnonzero(np.any(block(name)[:, first:] != 0.0, axis=(0, 2)))
            return int(used[-1]) + 1 if used.size else 1

        def nodes(name, first_group, groups):
            """Node values and slopes (node, group * 2 + V/S, width) of cells' cubics."""
            cells = block(name, slice(4 * first_group, 4 * (first_group + groups)))
            cells = cells.reshape(n_cells, groups, 4, -1)
            return cells[:, :, :2].reshape(n_cells, 2 * groups, -1)

        for name, stop in (('M', 1 + self.GROUPS_C), ('C', 1 + self.GROUPS_C),
                           ('K', self.GROUPS_KF), ('f', self.GROUPS_KF)):
            if np.any(block(name)[:, 4 * stop:] != 0.0):
                raise ValueError(f'{name} uses monomials beyond the first {stop}: '
                                 'update _StepTables')
        self.mass_groups = -(-(rows_used('M', 4 * self.FIRST_MC)) // 4)
        # M and C in float32: a sample reads 31 % fewer bytes (the table reads are about
        # a third of the step) and the outputs move by 2e-8 of their size; K and f stay in
        # float64 (float32 there moves them by 1e-3: the static directions are stiff).
        self.mass = np.ascontiguousarray(nodes('M', self.FIRST_MC, self.mass_groups),
                                         dtype=np.float32)
        self.damping = np.ascontiguousarray(nodes('C', self.FIRST_MC, self.GROUPS_C),
                                            dtype=np.float32)
        self.kf = np.ascontiguousarray(np.concatenate(
            [nodes('K', 0, self.GROUPS_KF), nodes('f', 0, self.GROUPS_KF)], axis=2))
        self.out_rows = max(rows_used('out'), rows_used('corr'))
        rows = slice(0, self.out_rows)
        outputs = len(reduced.OUTPUT_NAMES)
        out = np.zeros((n_cells, self.out_rows, outputs, r + 1))
        out[..., :r] = block('out', rows).reshape(n_cells, self.out_rows, outputs, r)
        out[..., r] = block('corr', rows)
        self.out = out.reshape(n_cells, self.out_rows, -1)
        self.joint = np.ascontiguousarray(np.concatenate(
            [block(name) for name in ('force', 'force_dot', 'rms2')], axis=2))

        npow = len(self.POWERS)
        zero = self.POWERS.index(0)
        big = np.zeros((npow, 2, 2, 3))            # block matrix on the stage values M, C, K
        for i in range(2):
            big[zero, i, i, 0] = 1.0
            for j in range(2):
                big[zero + 1, i, j, 1] = a[i, j]
                big[zero + 2, i, j, 2] = a2[i, j]
        det = a2[1, 0] * a[1, 1] - a2[1, 1] * a[1, 0]
        d_inv = np.zeros((npow, 2, 2))             # D2^-1
        d_inv[zero - 2, 0, 0] = a[1, 1] / det
        d_inv[zero - 1, 0, 1] = -a2[1, 1] / det
        d_inv[zero - 2, 1, 0] = -a[1, 0] / det
        d_inv[zero - 1, 1, 1] = a2[1, 0] / det
        matrix = np.zeros((npow, 2, 2, 3))         # A D2^-1
        for p1 in range(npow):
            for p2 in range(npow):
                p = p1 + p2 - zero
                if 0 <= p < npow:
                    matrix[p] += np.einsum('ijm,jk->ikm', big[p1], d_inv[p2])
        operator = np.zeros((npow, 2, 2, 3))       # on (q, v); f is added separately
        for i in range(2):
            operator[zero, i, 0, 2] = -1.0                     # -K q
            operator[zero, i, 1, 1] = -1.0                     # -C v
            operator[zero + 1, i, 1, 2] = -c[i]                # -c_i h K v
        operator[1:, :, 1, :] += matrix[:-1, :, 0, :]          # + h (A D2^-1)_{i0} on v
        rows = np.concatenate([matrix, operator], axis=2)      # (npow, 2, 4, 3)
        self.g_stack = np.zeros((2, npow, 2, 4, 2, 4))
        for parity in (0, 1):
            # Stage 1 in the other slot, stage 2 (the sample) in slot `parity`.
            for i, slot in ((0, 1 - parity), (1, parity)):
                self.g_stack[parity, :, i, :, slot, :3] = rows[:, i]
        self.g_stack = self.g_stack.reshape(2, npow, 64)
        # The compiled step's convention: the sample in slot 0, stage 1 in slot 1.
        self.g0 = np.ascontiguousarray(self.g_stack[0])
        self._bounds = {}

    def deflection_bound(self, estimator):
        """The ``deflection_bound_m`` of an estimator on these tables (computed once)."""
        zeta = float(estimator.model.zeta)
        key = (estimator.model.speed_max, zeta)
        if key not in self._bounds:
            bound = math.inf
            if zeta > 0.0:
                bound = DEFLECTION_SAFETY_FACTOR / (2.0 * zeta) * estimator.quasi_static_peak()
            # No load at all (or a singular K somewhere): no bound rather than a zero one.
            self._bounds[key] = bound if math.isfinite(bound) and bound > 0.0 else math.inf
        return self._bounds[key]

    def record(self, weights, k, z, out):
        """
        The sample's record (RECORD_SIZE) from the row weights at cell k and z = [q, v, 1].

        The numpy twin of the compiled step's record.
        """
        r = self.size
        operator = np.dot(weights[:self.out_rows], self.out[k]).reshape(-1, r + 1)
        outputs = operator.shape[0]
        np.dot(operator[:, :r], z[:r], out=out[:outputs])
        out[:outputs] += operator[:, r]
        out[outputs:2 * outputs] = operator[:, r]
        np.dot(weights, self.joint[k], out=out[2 * outputs:])


def step_tables(model):
    """The per-sample step's tables of a model (to share between estimators: replay)."""
    return _StepTables(model)


class StreamingEstimator:
    """
    Elastic deflections and joint criteria of the linkage, one crank sample at a time.

    Parameters
    ----------
    model : ReducedModel
        Precomputed reduced model (core/reduced.py).
    fit_time_constant_s : float
        Time constant of the crank-rate filter [s].
    warm_start : bool
        Start (and restart) from the periodic steady state at the current speed, so the
        output is right from the first revolution; otherwise from the static deflection.
    large_step_s : float
        Steps longer than this are flagged LARGE_STEP [s].
    reset_gap_s : float
        Gaps longer than this restart the estimate [s].
    accel_limit : float
        |crank acceleration| clip [rad/s^2].
    near_zero_fraction : float
        Reaction below this fraction of its cycle RMS flags the joint as near zero.
    compiled : bool
        Use the compiled step when it is built (see :func:`compiled_step_available`);
        False runs the numpy step (the same numbers to rounding).
    step_tables : object or None
        :func:`step_tables` of ``model``, to share between estimators of one model (they
        are read only); built here if None.
    warm_start_limiter : WarmStartLimiter or None
        Rate limit of the warm starts that shoot; a new one (wall clock) if None.

    Attributes
    ----------
    deflection_bound_m : float
        Largest |deflection component| published as a number [m]: DEFLECTION_SAFETY_FACTOR
        / (2 zeta) times the largest quasi-static deflection over the grid at constant
        speeds up to speed_max (:meth:`quasi_static_peak`). Beyond it a sample is
        OUT_OF_BOUND.
    outliers, out_of_bound, warm_starts, cold_starts : int
        Samples refused as outliers, estimates out of bound (or non-finite), warm starts
        that shot, and warm starts the rate limit turned into cold starts.

    """

    def __init__(self, model, fit_time_constant_s=DEFAULT_FIT_TIME_CONSTANT_S,
                 warm_start=True, large_step_s=DEFAULT_LARGE_STEP_S,
                 reset_gap_s=DEFAULT_RESET_GAP_S, accel_limit=DEFAULT_ACCEL_LIMIT,
                 near_zero_fraction=DEFAULT_NEAR_ZERO_FRACTION, compiled=True,
                 step_tables=None, warm_start_limiter=None):
        for name, value in (('large_step_s', large_step_s), ('reset_gap_s', reset_gap_s),
                            ('accel_limit', accel_limit)):
            if not value > 0.0:
                raise ValueError(f'`{name}` must be positive, got {value!r}')
        if not 0.0 <= near_zero_fraction < 1.0:
            raise ValueError(f'`near_zero_fraction` must be in [0, 1), got {near_zero_fraction!r}')
        self.model = model
        self.warm_start = bool(warm_start)
        self.large_step_s = float(large_step_s)
        self.reset_gap_s = float(reset_gap_s)
        self.accel_limit = float(accel_limit)
        self.near_zero_fraction = float(near_zero_fraction)
        compiled = compiled and _radau_step is not None
        self.rate_filter = (CompiledCrankRateFilter if compiled else CrankRateFilter)(
            fit_time_constant_s)
        self._speed_max = float(model.speed_max)
        # Without reaction data (core/dynamics.py absent at precompute) report zeros, flagged.
        self._base_flags = 0 if np.any(model.force_moments) else _NO_CRITERIA
        if len(reduced.JOINTS) != 4:
            raise ValueError('the criteria path is written for four joints')
        self._tables = _StepTables(model) if step_tables is None else step_tables
        if (self._tables.size, self._tables.mass.shape[0]) != (model.size, model.grid_size):
            raise ValueError('`step_tables` do not match the model (size and grid)')
        self._cells_per_radian = model.grid_size / TWO_PI
        self._force_moments = model.force_moments.tolist()
        r = model.size
        self._z = np.zeros(2 * r + 1)   # [q, v, 1]
        self._z[2 * r] = 1.0
        # [M, C, K, F] of stage 1 and of the sample, in alternating slots (the numpy step).
        self._stored = np.zeros((2, 4, r * r))
        self._flat = self._stored.reshape(2, 4 * r * r)
        self._record = np.zeros(RECORD_SIZE)
        self._parity = 0
        self._previous = np.zeros(3)    # crank state (angle, speed, accel) of the last step
        self._kernel = _radau_step if compiled else None
        self._row = np.zeros(6)         # the compiled step's row: h, sub-steps, state, advance
        self._no_states = np.empty(0)
        self._last = None
        self._pending_warm_start = False
        self._orbit = None      # (speed, start angle, q, v) of the last periodic orbit
        self._weights = np.zeros(reduced.CELL_POWERS * len(reduced.MONOMIALS))
        self._hermite = np.zeros((2, 2 * len(reduced.MONOMIALS)))
        if reduced.MONOMIALS != ('a', '1', 'w2', 'w', 'w4', 'wa', 'w3'):
            raise ValueError('monomial order changed: update StreamingEstimator._evaluate')
        self.samples = 0
        self.outliers = self.out_of_bound = self.warm_starts = self.cold_starts = 0
        self._gate = InputGate(self._speed_max, self.accel_limit, self.reset_gap_s)
        self.warm_start_limiter = (WarmStartLimiter() if warm_start_limiter is None
                                   else warm_start_limiter)
        self._cold_warned_at = self._bound_warned_at = None
        self.deflection_bound_m = self._tables.deflection_bound(self)

    # -- state -------------------------------------------------------------------------

    def reset(self):
        """Forget the state; the next sample starts afresh."""
        self._gate.reset()
        self._restart()

    def _restart(self):
        """Forget the filter and the model state (the gate keeps its reference)."""
        self.rate_filter.reset()
        self._last = None
        self._pending_warm_start = False

    def quasi_static_peak(self):
        """
        Largest |deflection component| of the quasi-static response over the grid [m].

        K q = f at every grid node, at constant speeds 0 ... speed_max (QUASI_STATIC_SPEEDS
        of them) and zero acceleration: batched solves of the step tables. (At accel_limit
        the axial inertia loads take the geometric stiffness of the node's default model to
        buckling, K indefinite: no bound of anything. Acceleration loads are left to
        DEFLECTION_SAFETY_FACTOR.)
        """
        model, tables, r = self.model, self._tables, self.model.size
        theta = np.arange(model.grid_size) / self._cells_per_radian
        operator_rows = np.zeros(tables.out_rows)
        peak = 0.0
        for w in np.linspace(0.0, self._speed_max, QUASI_STATIC_SPEEDS).tolist():
            _, _, stiffness, load = self.system_blocks(theta, w, 0.0)
            q = np.linalg.solve(stiffness, load[..., None])[..., 0]
            # Power 0 of each monomial (a, 1, w2, w, w4, wa, w3): the node's operator.
            monomials = (0.0, 1.0, w * w, w, w ** 4, 0.0, w ** 3)
            operator_rows[0::4] = monomials[:operator_rows[0::4].size]
            operator = np.einsum('k,nkj->nj', operator_rows, tables.out).reshape(
                theta.size, -1, r + 1)
            deflection = np.einsum('nor,nr->no', operator[..., :r], q) + operator[..., r]
            peak = max(peak, float(np.max(np.abs(deflection))))
        return peak

    def _evaluate(self, angle, speed, accel):
        """
        Row weights of the power-form tables (monomial times t^p, in table-row order), the
        Hermite weights of the node tables ((2, monomials x 2): node k's monomial times h00,
        h10 and node k + 1's times h01, h11) and the cell.

        The weights go to reused buffers: use them before the next call.
        """
        x = angle * self._cells_per_radian
        k = int(x)
        if k >= self.model.grid_size:
            k = self.model.grid_size - 1
        t = x - k
        t2 = t * t
        t3 = t2 * t
        h00, h10, h01, h11 = _hermite_basis(t)
        w, a = speed, accel
        w2 = w * w
        # Order of reduced.MONOMIALS: a, 1, w2, w, w4, wa, w3.
        monomials = (a, 1.0, w2, w, w2 * w2, w * a, w2 * w)
        self._weights[:] = [m * p for m in monomials for p in (1.0, t, t2, t3)]
        self._hermite[0] = [m * p for m in monomials for p in (h00, h10)]
        self._hermite[1] = [m * p for m in monomials for p in (h01, h11)]
        return self._weights, self._hermite, k

    def _combine_nodes(self, hermite, k, first_group, groups, table, out):
        """Hermite weights times the node rows of cell k (nodes k and k + 1) into ``out``."""
        rows = slice(2 * first_group, 2 * (first_group + groups))
        if k + 1 < self.model.grid_size:
            # Nodes k and k + 1 are adjacent: one product over both (a float32 table is
            # converted once).
            weights = np.concatenate((hermite[0, rows], hermite[1, rows]))
            np.dot(weights, table[k:k + 2].reshape(-1, table.shape[2]), out=out)
        else:
            np.dot(hermite[0, rows], table[k], out=out)
            out += np.dot(hermite[1, rows], table[0])

    def _load(self, slot, hermite, k):
        """Write M, C and [K, f] of the node tables at (Hermite weights, cell k) into a slot."""
        tables, r2 = self._tables, self.model.size ** 2
        flat = self._flat[slot]
        first = tables.FIRST_MC
        self._combine_nodes(hermite, k, first, tables.mass_groups, tables.mass, flat[:r2])
        self._combine_nodes(hermite, k, first, tables.GROUPS_C, tables.damping,
                            flat[r2:2 * r2])
        self._combine_nodes(hermite, k, 0, tables.GROUPS_KF, tables.kf,
                            flat[2 * r2:3 * r2 + self.model.size])

    def _set_state(self, angle, speed, accel, warm):
        """
        Start from the periodic state at this speed (warm) or the static deflection.

        Returns the flags: WARM_START, COLD_START (the rate limit refused the shooting) or 0.
        """
        r = self.model.size
        flags = 0
        if warm and speed != 0.0:
            flags = _WARM_START if self._may_warm_start(speed) else _COLD_START
        if flags == _WARM_START:
            q0, v0 = self.periodic_state(angle, speed)
        else:
            _, _, stiffness, load = self.system_blocks(np.array([angle]), speed, accel)
            q0, v0 = np.linalg.solve(stiffness[0], load[0]), np.zeros(r)
        self._z[:r] = q0
        self._z[r:2 * r] = v0
        weights, _, k = self._evaluate(angle, speed, accel)
        self._tables.record(weights, k, self._z, self._record)
        self._previous[:] = (angle, speed, accel)
        return flags

    def _orbit_serves(self, speed):
        """True if the kept periodic orbit serves a warm start at ``speed`` (no shooting)."""
        orbit = self._orbit
        return (orbit is not None
                and abs(orbit[0] - speed) <= WARM_START_SPEED_TOLERANCE * abs(speed))

    def _may_warm_start(self, speed):
        """True if a warm start at ``speed`` is cheap or the rate limit allows a shooting."""
        if self._orbit_serves(speed) or self.warm_start_limiter.take():
            return True
        self.cold_starts += 1
        now = time.monotonic()
        last = self._cold_warned_at
        if last is None or now - last > WARNING_PERIOD_S:
            self._cold_warned_at = now
            LOGGER.warning('warm start skipped (at most %d at once, then %g per second): cold '
                           'start from the static deflection (%d so far)', WARM_START_BURST,
                           WARM_START_RATE_HZ, self.cold_starts)
        return False

    def periodic_state(self, angle, speed):
        """
        (q, v) of the periodic steady state at crank ``angle`` and constant ``speed`` != 0.

        Shooting over one revolution (reduced.periodic_response, WARM_START_STEPS steps); the
        orbit is kept, and a later call within WARM_START_SPEED_TOLERANCE of its speed takes
        the state from it by cubic Hermite interpolation in time (v is dq/dt) instead.
        """
        orbit = self._orbit
        if not self._orbit_serves(speed):
            self.warm_starts += 1
            _, q, v = reduced.periodic_response(self.model, speed, start_angle=angle,
                                                steps=WARM_START_STEPS,
                                                blocks=self.system_blocks)
            self._orbit = (speed, angle, q, v)
            return q[0].copy(), v[0].copy()
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

    @property
    def compiled(self):
        """True when this estimator steps with the compiled kernel."""
        return self._kernel is not None

    def system_blocks(self, theta, w, a):
        """
        M, C, K, f at crank angles ``theta`` (array), speed ``w``, acceleration ``a``.

        From the step tables (the rows each block uses), so the estimator needs nothing of
        the model's full table: see :meth:`release_model_table`.
        """
        model, tables, r = self.model, self._tables, self.model.size
        theta = np.asarray(theta, dtype=float)
        cells, t = model.cell(theta)
        basis = np.stack(_hermite_basis(t), axis=-1)
        monomials = np.stack(np.broadcast_arrays(*reduced.monomial_values(
            np.full(theta.size, float(w)), np.full(theta.size, float(a)))), axis=-1)
        # (angle, monomial, node k / k + 1, V / S)
        weights = (monomials[:, :, None] * basis[:, None, :]).reshape(theta.size, -1, 2, 2)
        mass = np.empty((theta.size, r * r))
        damping = np.empty((theta.size, r * r))
        kf = np.empty((theta.size, r * r + r))
        first, after = tables.FIRST_MC, tables.FIRST_MC + tables.mass_groups
        for k, group in reduced.cell_groups(cells):
            k1 = (k + 1) % model.grid_size
            for out, table, groups in ((mass, tables.mass, slice(first, after)),
                                       (damping, tables.damping,
                                        slice(first, first + tables.GROUPS_C)),
                                       (kf, tables.kf, slice(0, tables.GROUPS_KF))):
                node = weights[group, groups]
                out[group] = (node[:, :, 0].reshape(group.size, -1) @ table[k]
                              + node[:, :, 1].reshape(group.size, -1) @ table[k1])
        shape = (theta.size, r, r)
        return (mass.reshape(shape), damping.reshape(shape), kf[:, :r * r].reshape(shape),
                kf[:, r * r:])

    def release_model_table(self):
        """
        Drop this estimator's reference to the model's full table (tens of MB).

        Streaming, warm starts and link shapes need only the step tables and the shape
        table; ``model.evaluate`` of the model this estimator then holds returns rows of zero
        width. For a process that only streams (the node), which must drop its own references
        to the model too (it gets the released model back).
        """
        empty = np.empty((self.model.grid_size,) + self.model.table.shape[1:2] + (0,))
        self.model = dataclasses.replace(self.model, table=empty)
        return self.model

    # -- the per-sample path -----------------------------------------------------------

    def update(self, stamp_ns, crank_angle, crank_speed=None):
        """
        Add one crank sample and return the estimate at its stamp.

        Parameters
        ----------
        stamp_ns : int
            Sample time [ns].
        crank_angle : float
            Crank angle [rad], any range (wrapped here).
        crank_speed : float or None
            Measured crank speed [rad/s]; None (or NaN) to derive it from angles.

        Returns
        -------
        Sample
            Flagged OUT_OF_BOUND (deflections NaN, the state reset) when the estimate left
            :attr:`deflection_bound_m` or went non-finite.

        Raises
        ------
        OutlierSample
            The sample is implausible (:class:`InputGate`); nothing of the state changed.

        """
        angle_in = float(crank_angle)
        if not math.isfinite(angle_in):
            raise ValueError(f'`crank_angle` must be finite, got {crank_angle!r}')
        if crank_speed is not None:
            crank_speed = float(crank_speed)
            if math.isnan(crank_speed):
                crank_speed = None
        stamp_ns = int(stamp_ns)
        kind, flags, message = self._gate.decide(stamp_ns, angle_in, crank_speed)
        if kind == InputGate.OUTLIER:
            self.outliers += 1
            raise OutlierSample(message)
        if kind == InputGate.REPEATED:
            return dataclasses.replace(self._last, flags=self._last.flags | _REPEATED,
                                       message=message)
        if kind == InputGate.START:
            if message:
                LOGGER.warning('estimator reset: %s', message)
            self._restart()
            return self._start(stamp_ns, angle_in, crank_speed, flags, message)
        last = self._last
        dt_ns = stamp_ns - last.stamp_ns
        dt = dt_ns * 1e-9
        angle, speed, accel = self.rate_filter.update((stamp_ns - self._stamp0_ns) * 1e-9,
                                                      angle_in, crank_speed)
        if crank_speed is None:
            flags |= _SPEED_FROM_ANGLE
        if dt > self.large_step_s:
            flags |= _LARGE_STEP
        if not (math.isfinite(angle) and math.isfinite(speed) and math.isfinite(accel)):
            return self._out_of_bound(stamp_ns, angle, speed, accel, flags,
                                      'non-finite crank filter state')
        model_speed, model_accel = speed, accel
        if abs(speed) > self._speed_max:
            model_speed = math.copysign(self._speed_max, speed)
            flags |= _CLIPPED_SPEED
        if abs(accel) > self.accel_limit:
            model_accel = math.copysign(self.accel_limit, accel)
            flags |= _CLIPPED_ACCEL
        try:
            if self._pending_warm_start and self.rate_filter.count >= 3:
                self._pending_warm_start = False
                flags |= self._set_state(angle, model_speed, model_accel, True)
            else:
                self._row[:] = (dt, -(-dt_ns // MAX_SUBSTEP_NS), angle, model_speed,
                                model_accel, self.rate_filter.advance)
                self._step_rows(self._row, self._no_states, self._record)
        except (ValueError, FlexlinkError) as exc:    # singular or non-finite step
            return self._out_of_bound(stamp_ns, angle, speed, accel, flags, str(exc))
        return self._finish(stamp_ns, angle, speed, accel, model_speed, flags, message)

    def _start(self, stamp_ns, angle_in, crank_speed, flags, message):
        self._stamp0_ns = int(stamp_ns)
        angle, speed, accel = self.rate_filter.update(0.0, angle_in, crank_speed)
        if crank_speed is None:
            flags |= _SPEED_FROM_ANGLE
        model_speed = max(-self._speed_max, min(self._speed_max, speed))
        if model_speed != speed:
            flags |= _CLIPPED_SPEED
        warm = self.warm_start and crank_speed is not None
        try:
            flags |= self._set_state(angle, model_speed, 0.0, warm)
        except (ValueError, FlexlinkError) as exc:    # singular K or a failed shooting
            return self._out_of_bound(stamp_ns, angle, speed, accel, flags, str(exc))
        self._pending_warm_start = self.warm_start and crank_speed is None
        return self._finish(stamp_ns, angle, speed, accel, model_speed, flags, message)

    def _out_of_bound(self, stamp_ns, angle, speed, accel, flags, message):
        """A sample flagged OUT_OF_BOUND, not a number to publish; the next one restarts."""
        self.out_of_bound += 1
        now = time.monotonic()
        if self._bound_warned_at is None or now - self._bound_warned_at > WARNING_PERIOD_S:
            self._bound_warned_at = now
            LOGGER.warning('estimate out of bound, state reset: %s (%d so far)', message,
                           self.out_of_bound)
        nan2, nan4 = (math.nan,) * 2, (math.nan,) * 4
        sample = Sample(
            stamp_ns=int(stamp_ns), crank_angle=angle, crank_speed=speed, crank_accel=accel,
            lever_tip=nan2, coupler_mid=nan2, reaction_n=nan4, gamma_dot=nan4,
            criterion=nan4, near_zero=(False,) * 4, error_indicator=math.nan,
            flags=flags | _OUT_OF_BOUND | self._base_flags, message=message,
            modal=(math.nan,) * self.model.size)
        self.samples += 1
        self.reset()
        return sample

    def _step_rows(self, rows, states, records):
        """
        Advance through sample rows (h, sub-steps, angle, speed, acceleration, advance).

        The compiled step in one call, or the numpy step row by row. ``states`` is empty or
        rows x 2 r (z[:2 r] after each row); ``records`` is rows x RECORD_SIZE, or one record
        (of the last row).
        """
        tables = self._tables
        if self._kernel is not None:
            self._kernel.advance(tables.mass, tables.damping, tables.kf, tables.out,
                                 tables.joint, tables.g0, self._cells_per_radian, _STAGE1,
                                 self._z, self._previous, rows, states, records)
            return
        rows = rows.reshape(-1, 6).tolist()
        every = records.ndim == 2
        for n, (h, splits, angle, w, a, step) in enumerate(rows):
            self._advance(h, int(splits), angle, w, a, step)
            if every or n == len(rows) - 1:
                weights, _, k = self._evaluate(angle, w, a)
                tables.record(weights, k, self._z, records[n] if every else records)
            if states.size:
                states[n] = self._z[:states.shape[1]]

    def _advance(self, h, count, angle, speed, accel, advance):
        """
        ``count`` equal Radau IIA steps over ``h`` to the new sample (MAX_SUBSTEP_NS).

        Between the samples the crank state is linear: angle previous + f advance, speed and
        acceleration interpolated (replay() builds the same sub-step rows).
        """
        if count > 1:
            angle0, speed0, accel0 = self._previous.tolist()
            for i in range(1, count):
                f = i / count
                self._step(h / count, (angle0 + advance * f) % TWO_PI,
                           speed0 + f * (speed - speed0), accel0 + f * (accel - accel0),
                           advance / count)
            h, advance = h / count, advance / count
        self._step(h, angle, speed, accel, advance)

    def _step(self, h, angle, speed, accel, advance):
        """One Radau IIA step to the new crank state (the numpy path; see _radau_step.c)."""
        tables = self._tables
        r = tables.size
        parity = 1 - self._parity
        self._parity = parity
        # Stage 1 at c_1 h: crank state interpolated between the samples, into the other slot.
        c1 = _STAGE1
        previous = self._previous.tolist()
        stage_angle = previous[0] + c1 * advance
        if stage_angle >= TWO_PI:
            stage_angle -= TWO_PI
        elif stage_angle < 0.0:
            stage_angle += TWO_PI
        _, hermite, k = self._evaluate(stage_angle, previous[1] + c1 * (speed - previous[1]),
                                       previous[2] + c1 * (accel - previous[2]))
        self._load(1 - parity, hermite, k)
        _, hermite, k = self._evaluate(angle, speed, accel)
        self._load(parity, hermite, k)
        self._previous[:] = (angle, speed, accel)
        inv = 1.0 / h
        g = np.dot(np.array((inv * inv, inv, 1.0, h, h * h)), tables.g_stack[parity])
        blocks = np.dot(g.reshape(8, 8), self._stored.reshape(8, r * r))
        # Transposed system (column block, l, i, k): its first 2 r rows are the Fortran-order
        # block matrix LAPACK wants, the rest the transposed right-hand-side operator.
        system_t = blocks.reshape(2, 4, r, r).transpose(1, 3, 0, 2).reshape(4 * r, 2 * r)
        z = self._z
        stored = self._stored
        loads = np.concatenate((stored[1 - parity, 3, :r], stored[parity, 3, :r]))
        _, _, increment, info = lapack.dgesv(system_t[:2 * r].T,
                                             np.dot(z[:2 * r], system_t[2 * r:]) + loads,
                                             overwrite_a=1, overwrite_b=1)
        if info != 0 or not np.all(np.isfinite(increment)):
            raise ValueError('singular or non-finite Radau step')   # as the compiled step
        z[:2 * r] += increment

    def _finish(self, stamp_ns, angle, speed, accel, model_speed, flags, message):
        values = self._record.tolist()
        outputs = len(reduced.OUTPUT_NAMES)
        deflection = values[:outputs]
        correction = values[outputs:2 * outputs]
        if self._kernel is not None:
            criteria = self._kernel.criteria(self._record, self.near_zero_fraction,
                                             REACTION_FLOOR_FRACTION)
        else:
            criteria = self._criteria(values[2 * outputs:], model_speed)
        z = self._z
        r = self._tables.size
        largest = max([abs(d) for d in deflection])
        if not largest <= self.deflection_bound_m:     # also NaN
            return self._out_of_bound(
                stamp_ns, angle, speed, accel, flags,
                f'deflection {largest:.6g} m beyond the bound {self.deflection_bound_m:.6g} m')
        size = math.sqrt(sum([d * d for d in deflection]))
        sample = Sample(
            stamp_ns=int(stamp_ns), crank_angle=angle, crank_speed=speed, crank_accel=accel,
            lever_tip=(deflection[0], deflection[1]),
            coupler_mid=(deflection[2], deflection[3]),
            reaction_n=criteria[0], gamma_dot=criteria[1], criterion=criteria[2],
            near_zero=criteria[3],
            error_indicator=math.sqrt(sum([c * c for c in correction]))
            / max(size, ERROR_INDICATOR_FLOOR_M),
            flags=flags | self._base_flags, message=message, modal=tuple(z[:r].tolist()))
        self._last = sample
        self.samples += 1
        return sample

    def _criteria(self, values, w):
        """
        R, gamma-dot, |gamma-dot / R| and near-zero flags per joint from table values.

        A reaction below REACTION_FLOOR_FRACTION of its cycle RMS is clamped to that floor
        (as core/criteria.py does), so the criterion stays finite; it is flagged near zero.
        """
        limit2 = self.near_zero_fraction * self.near_zero_fraction
        floor_fraction2 = REACTION_FLOOR_FRACTION * REACTION_FLOOR_FRACTION
        reactions, gamma_dots, ratios, near = [0.0] * 4, [0.0] * 4, [0.0] * 4, [False] * 4
        for j in range(4):
            fx, fy = values[2 * j], values[2 * j + 1]
            r2 = fx * fx + fy * fy
            rms2 = values[16 + j]
            near[j] = r2 < limit2 * rms2
            r2 = max(r2, floor_fraction2 * rms2)
            if r2 > 0.0:
                magnitude = math.sqrt(r2)
                gamma_dot = (fx * values[9 + 2 * j] - fy * values[8 + 2 * j]) / r2
                reactions[j], gamma_dots[j] = math.sqrt(fx * fx + fy * fy), gamma_dot
                ratios[j] = abs(gamma_dot) / magnitude
        return tuple(reactions), tuple(gamma_dots), tuple(ratios), tuple(near)

    def link_shapes(self, sample):
        """
        Rigid positions and elastic deflections of points along each link at a sample.

        Returns
        -------
        positions, deflections : ndarray, shape (3, points, 2)
            Ground frame [m].

        """
        return self.model.shapes(sample.crank_angle, np.array(sample.modal))


def replay(model, stamps_ns, angles, speeds=None,
           fit_time_constant_s=DEFAULT_FIT_TIME_CONSTANT_S, warm_start=True,
           accel_limit=DEFAULT_ACCEL_LIMIT, compiled=True, orbit=None, on_rows=None,
           tables=None, warm_start_limiter=None, resume=None):
    """
    Offline estimate of a recorded crank signal: the streaming step over the whole signal.

    Same numbers as feeding :meth:`StreamingEstimator.update` sample by sample (a test checks
    this), for strictly increasing stamps without gaps or outliers (one segment of
    :func:`plan_rows`): the crank filter runs over the signal in one loop, then the compiled
    step advances through all samples in one call per chunk (the numpy step, sample by
    sample, where the extension is not built). An estimate beyond the deflection bound, a
    non-finite one or a failed step ends the replay at that sample ('stopped'): the streaming
    estimator restarts at the next one, so the caller replays the rest as a new segment.

    Parameters
    ----------
    model : ReducedModel
    stamps_ns : ndarray of int, shape (m,)
        Strictly increasing stamps [ns].
    angles : ndarray, shape (m,)
        Crank angles [rad], any range.
    speeds : ndarray, shape (m,), or None
        Measured crank speeds [rad/s]; None to derive them from the angles.
    fit_time_constant_s, warm_start, accel_limit, compiled
        As for :class:`StreamingEstimator`.
    orbit : tuple or None
        The periodic orbit a streaming estimator would remember from earlier warm starts
        (the 'orbit' of a previous call): pass it on from segment to segment of one recording
        and the segments restart exactly as one streaming estimator does.
    tables : object or None
        :func:`step_tables` of ``model``, when one caller replays many segments.
    warm_start_limiter : WarmStartLimiter or None
        Shared by the segments of one recording (a new one, wall clock, if None).
    resume : tuple or None
        The 'resume' of the previous call when these samples continue its segment (same
        numbers as one call; the first call must hold at least 3 samples, or all of them).
        A caller that replays a long segment in pieces wastes at most a piece when one
        goes out of bound.
    on_rows : callable or None
        ``on_rows(result, done)`` after each chunk of rows: ``result`` is the returned dict
        (its arrays are being filled), final for the first ``done`` samples. Lets a caller
        use the estimate while the rest is computed (the compiled step releases the GIL).

    Returns
    -------
    dict of str to ndarray
        'crank_angle', 'crank_speed', 'crank_accel' (m,); 'lever_tip', 'coupler_mid' (m, 2)
        [m]; 'modal' (m, r); 'force', 'force_dot' (m, joints, 2) and 'rms2' (m, joints): the
        tabulated joint reactions at the model's (clipped) crank state; 'orbit' for the next
        call; 'stopped': the index of the sample that went out of bound (the rows after it
        are not computed), or None; 'resume' for a call on the samples that follow.

    """
    stamps_ns = np.asarray(stamps_ns, dtype=np.int64)
    count = stamps_ns.size
    if count < 1 or np.any(np.diff(stamps_ns) <= 0):
        raise ValueError('`stamps_ns` must be strictly increasing')
    angles = np.asarray(angles, dtype=float)
    if speeds is not None:
        speeds = np.asarray(speeds, dtype=float)
    if not fit_time_constant_s > 0.0:
        raise ValueError(f'`time_constant_s` must be positive, got {fit_time_constant_s!r}')
    if resume is None:
        estimator = StreamingEstimator(model, fit_time_constant_s, warm_start=warm_start,
                                       accel_limit=accel_limit, compiled=compiled,
                                       step_tables=tables,
                                       warm_start_limiter=warm_start_limiter)
        estimator._orbit = orbit
        # A fresh filter of the estimator's kind (compiled or not) over the whole signal.
        rate_filter = type(estimator.rate_filter)(fit_time_constant_s)
        stamp0_ns, previous_ns = int(stamps_ns[0]), None
    else:
        estimator, rate_filter, stamp0_ns, previous_ns = resume
        if not stamps_ns[0] > previous_ns:
            raise ValueError('`stamps_ns` must continue after the resumed ones')
    motion = rate_filter.signal((stamps_ns - stamp0_ns) * 1e-9, angles, speeds)
    result = {'crank_angle': motion[:, 0], 'crank_speed': motion[:, 1],
              'crank_accel': motion[:, 2], 'orbit': None, 'stopped': None}
    _replay_rows(estimator, stamps_ns, angles, speeds, motion, result, on_rows, previous_ns)
    result['orbit'] = estimator._orbit
    result['resume'] = (estimator, rate_filter, stamp0_ns, int(stamps_ns[-1]))
    return result


def _replay_rows(estimator, stamps_ns, angles, speeds, motion, result, on_rows, previous_ns):
    """The steps of :func:`replay` into ``result`` (its 'stopped' set where one failed)."""
    model, count, r = estimator.model, stamps_ns.size, estimator.model.size
    wrapped, speed, accel, advance = motion.T
    model_speed = np.clip(speed, -model.speed_max, model.speed_max)
    model_accel = np.clip(accel, -estimator.accel_limit, estimator.accel_limit)
    modal = np.full((count, r), math.nan)
    records = np.full((count, RECORD_SIZE), math.nan)
    outputs, joints = len(reduced.OUTPUT_NAMES), len(reduced.JOINTS)
    joint = records[:, 2 * outputs:]
    result.update({'lever_tip': records[:, 0:2], 'coupler_mid': records[:, 2:4],
                   'modal': modal, 'force': joint[:, :2 * joints].reshape(count, joints, 2),
                   'force_dot': joint[:, 2 * joints:4 * joints].reshape(count, joints, 2),
                   'rms2': joint[:, 4 * joints:]})
    # The first samples (start and, without measured speeds, the deferred warm start) go
    # through update() itself; the steps continue from its state.
    prefix = min(3 if (estimator.warm_start and speeds is None) else 1, count)
    if previous_ns is not None:
        prefix = 0              # a resumed segment: the estimator has its state
    for n in range(prefix):
        sample = estimator.update(int(stamps_ns[n]), float(angles[n]),
                                  None if speeds is None else float(speeds[n]))
        if sample.flags & _OUT_OF_BOUND:
            return _stop(result, n, on_rows)
        modal[n] = estimator._z[:r]
        records[n] = estimator._record
    # A non-finite filter output ends the steps before it (the stepper must not see it).
    finite = np.all(np.isfinite(motion[prefix:]), axis=1)
    last = prefix + (int(np.argmin(finite)) if not np.all(finite) else finite.size)
    # Rows as update() builds them: step [s], sub-steps, crank state, advance.
    before = stamps_ns[0] if previous_ns is None else previous_ns
    dt_ns = np.diff(stamps_ns, prepend=before)[prefix:last]
    rows = np.column_stack([dt_ns * 1e-9, -(-dt_ns // MAX_SUBSTEP_NS), wrapped[prefix:last],
                            model_speed[prefix:last], model_accel[prefix:last],
                            advance[prefix:last]])
    states = np.empty((min(REPLAY_CHUNK, rows.shape[0]), 2 * r))
    if on_rows is not None:
        on_rows(result, prefix)
    for first in range(0, rows.shape[0], REPLAY_CHUNK):
        chunk = rows[first:first + REPLAY_CHUNK]
        done = slice(prefix + first, prefix + first + chunk.shape[0])
        states[:] = math.nan            # rows after a failed step stay NaN
        try:
            estimator._step_rows(chunk, states[:chunk.shape[0]], records[done])
        except ValueError:              # singular or non-finite step: found below
            pass
        modal[done] = states[:chunk.shape[0], :r]
        good = np.all(np.isfinite(states[:chunk.shape[0]]), axis=1) & np.all(
            np.abs(records[done, :outputs]) <= estimator.deflection_bound_m, axis=1)
        if not np.all(good):
            return _stop(result, done.start + int(np.argmin(good)), on_rows)
        if on_rows is not None:
            on_rows(result, done.stop)
    if last < count:
        return _stop(result, last, on_rows)
    return None


def _stop(result, row, on_rows):
    """Mark ``row`` out of bound (NaN) in a replay's result; the rows before it are final."""
    for key in ('lever_tip', 'coupler_mid', 'modal', 'force', 'force_dot', 'rms2'):
        result[key][row:] = math.nan
    result['stopped'] = row
    if on_rows is not None:
        on_rows(result, row)
