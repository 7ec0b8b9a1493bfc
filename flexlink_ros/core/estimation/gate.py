"""
Plausibility of input samples, decided before the crank filter sees them.

:class:`InputGate` refuses implausible samples (outliers: the state is untouched, so one bad
sample changes no later output), restarts the estimate on backward stamps and long gaps,
ignores exact repeats and refuses a sample with the last one's stamp but another angle.
:func:`plan_rows` decides a whole recorded signal the same way.
"""

import math

import numpy as np

from .sample import OUTLIER, RESET
from ..numerics import TWO_PI, wrap_to_2pi, wrap_to_pi

# A gap longer than this restarts the estimate (state too stale to carry) [s].
DEFAULT_RESET_GAP_S = 0.5
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


def restart_reason(step_ns):
    """
    Say why a sample ``step_ns`` after the last accepted one restarts the estimate.

    Parameters
    ----------
    step_ns : int
        Its stamp minus the last accepted stamp [ns]: negative, or beyond the reset gap.

    Returns
    -------
    str
        A backward step as its magnitude in ms (never "-0 s").

    """
    if step_ns < 0:
        return f'stamp went back by {-step_ns * 1e-6:.6g} ms'
    return f'gap of {step_ns * 1e-9:.6g} s'


class InputGate:
    """
    Plausibility of input samples, checked before the crank filter sees them.

    A sample is an outlier (the filter and the model never see it) when its measured |speed|
    exceeds ``SPEED_PLAUSIBLE_FACTOR * speed_max``, when its speed differs from the last
    accepted one by more than ``JUMP_ACCEL_FACTOR * accel_limit * dt + JUMP_ALLOWANCE_FRACTION
    * speed_max``, or when its angle moved by more than ``SPEED_PLAUSIBLE_FACTOR * speed_max *
    dt + ANGLE_ALLOWANCE_RAD`` (modulo a revolution). ``REGIME_SAMPLES`` consecutive outliers
    that pass these tests against each other start a new regime (RESET | OUTLIER). Stamps that
    go back or leave a gap restart the estimate, as before; exact repeats are ignored; the
    last accepted stamp again with another angle is CONFLICTING (nothing changes).
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

    STEP, START, OUTLIER, REPEATED, CONFLICTING = 0, 1, 2, 3, 4

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
        (kind, flags, message) of a sample: STEP, START, OUTLIER, REPEATED or CONFLICTING.

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
            if dt == 0.0:
                if abs(wrap_to_2pi(angle) - wrap_to_2pi(last[1])) < 1e-12:
                    return self.REPEATED, 0, 'repeated sample ignored'
                return self.CONFLICTING, 0, (f'stamp {stamp_ns} already taken with angle '
                                             f'{last[1]:.6g} rad, not {angle:.6g} rad')
            if dt <= 0.0 or dt > self.reset_gap_s:
                kind = self.START
                message = restart_reason(stamp_ns - last[0])
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
        flags = (OUTLIER if self.skipped else 0) | (RESET if kind == self.START else 0)
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
    Decide each row of a signal as :meth:`StreamingEstimator.update` does (its InputGate).

    Parameters
    ----------
    stamps_ns : ndarray of int, shape (m,)
        Sample stamps [ns].
    angles, speeds : ndarray, shape (m,)
        Speeds NaN where a sample has none.
    gate : InputGate
        Fresh or carried over; left at the end of the signal.

    Returns
    -------
    kinds : ndarray of int8, shape (m,)
        InputGate.STEP, START, OUTLIER or REPEATED per row (a CONFLICTING row is given as
        OUTLIER: the offline replay flags both alike).
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
        kinds[n], flags[n] = (gate.OUTLIER if kind == gate.CONFLICTING else kind), flag
        synced = kind in (gate.STEP, gate.START)
        n += 1
    return kinds, flags
