"""
The reduced nonlinear model following a linear estimator through its accepted samples.

The node (``model.nonlinear``) and ``flexlink replay --nonlinear`` run the same thing: the
linear estimator filters the crank signal and decides which samples it accepts; the nonlinear
model (:class:`.nonlinear_stream.NonlinearStepper`) steps from one accepted sample to the next
on that estimator's crank angle and speed, and starts again, at its quasi-static deflection,
after a gap longer than the estimator's reset gap. Fed the same samples, both give the same
numbers, so a recording replays to what the node published: the node steps sample by sample
(:meth:`NonlinearFollower.sample`), the replay a block of samples at a time
(:meth:`NonlinearFollower.follow`, one compiled call per run: 1.3 times as fast), which agrees
to rounding (the steps' lengths are differences of the run's times; within 3e-11 of the
deflections' range on the paper's linkage).

Its validity (:func:`nonlinear_validity`) is what the model cannot carry: the von Karman
strain keeps ``v'^2 / 2`` of a link's stretch and drops ``v'^4 / 8``, a relative error of
``v'^2 / 4`` at bending slope ``v'``. The indicator is scaled so that the linear model's
threshold (:data:`core.validity.VALIDITY_THRESHOLD`) falls at the slope limit
:data:`.nonlinear_stream.VON_KARMAN_SLOPE` (1 % strain error): the node's ``~/quality`` and
``/diagnostics`` judge either model's estimate by one threshold.
"""

import math

import numpy as np

from .nonlinear_stream import NonlinearStepper, unwrap_next, VON_KARMAN_SLOPE
from ..validity import VALIDITY_THRESHOLD


CHOICES = ('auto', 'on', 'off')


def choose_nonlinear(choice, nonlinearity, recorded=False):
    """
    Return (use the nonlinear model, why) for a choice and the linear run's verdict.

    Parameters
    ----------
    choice : str
        'on', 'off' or 'auto' (by the verdict).
    nonlinearity : dict or None
        :func:`core.validity.is_valid` of the linear estimate ('valid', 'indicator_max',
        'threshold'); only read for 'auto'.
    recorded : bool
        ``choice`` is what the recording's provenance says it was made with, not a flag.

    """
    if recorded and choice in ('on', 'off'):
        return choice == 'on', f"the recording's model (its provenance says nonlinear: {choice})"
    if choice == 'on':
        return True, 'asked for (--nonlinear on)'
    if choice == 'off':
        return False, 'asked for (--nonlinear off)'
    if nonlinearity['valid'] is None:
        return False, 'auto: the linear model has no validity indicator to decide by'
    reading = (f"validity indicator max {nonlinearity['indicator_max']:.3g}, threshold "
               f"{nonlinearity['threshold']:g}")
    if nonlinearity['valid']:
        return False, f'auto: the linear estimate is valid ({reading})'
    return True, f'auto: the linear estimate is not valid ({reading})'


def nonlinear_validity(link_slope):
    """
    Return the validity indicator of a nonlinear estimate: threshold x (slope / limit)^2.

    Parameters
    ----------
    link_slope : array_like
        RMS bending slope of each flexible link [rad]
        (:attr:`.nonlinear_stream.NonlinearStepper.slope`).

    Returns
    -------
    float
        Below :data:`core.validity.VALIDITY_THRESHOLD` where the strain's dropped term is
        under 1 % (NaN for a non-finite slope, 0 without links).

    """
    # plain floats: this runs per sample of the node, and numpy's reductions cost more than
    # the arithmetic on a few links
    slope = link_slope.ravel().tolist() if isinstance(link_slope, np.ndarray) else link_slope
    magnitudes = [abs(float(value)) for value in slope]
    if math.isnan(sum(magnitudes)):      # the sum of magnitudes is NaN only with a NaN
        return math.nan
    largest = max(magnitudes, default=0.0)
    return VALIDITY_THRESHOLD * (largest / VON_KARMAN_SLOPE) ** 2


class NonlinearFollower:
    """
    Step the nonlinear model through a linear estimator's accepted samples (module notes).

    Parameters
    ----------
    tables : NonlinearTables
        The reduced nonlinear model.
    reset_gap_s : float
        A gap between accepted samples longer than this starts the model again (as the linear
        estimator's segments).

    Attributes
    ----------
    counts : dict
        'samples', 'refused_samples' (a step Newton did not converge: the state is kept),
        'restarts', 'beyond_von_karman_samples'.
    slope_max : float
        Largest RMS link slope seen [rad].
    validity : float
        :func:`nonlinear_validity` of the last sample (NaN at a start).

    """

    def __init__(self, tables, reset_gap_s):
        self.tables, self.reset_gap_s = tables, float(reset_gap_s)
        self.stepper = NonlinearStepper(tables)
        self.last = None          # (stamp [ns], unwrapped angle, speed) of the last sample
        self.counts = {'samples': 0, 'refused_samples': 0, 'restarts': 0,
                       'beyond_von_karman_samples': 0}
        self.slope_max = 0.0
        self.validity = 0.0
        self._pending = False     # the last sample's slopes not judged yet (sample, judge)

    def restart(self):
        """Start again at the next sample (as after a gap)."""
        self.last = None

    def sample(self, stamp_ns, angle, speed, judge=True):
        """
        Step to one accepted sample; return its output deflections [m], shape (channels,).

        ``angle`` may be wrapped: it is unwrapped by the speed from the previous sample.
        With ``judge`` False the sample's validity and link-slope counts wait for
        :meth:`judge` (the node publishes the lever tip first), which must come before the
        next sample.
        """
        self._pending = False
        stepper, self.counts['samples'] = self.stepper, self.counts['samples'] + 1
        h = None if self.last is None else (stamp_ns - self.last[0]) * 1e-9
        if h is None or not 0.0 < h <= self.reset_gap_s:
            self.counts['restarts'] += self.last is not None
            stepper.start(angle, speed)
            self.last = (stamp_ns, angle, speed)
            self.validity = float('nan')     # a start is not judged
            return stepper.outputs(angle)
        _, theta0, speed0 = self.last
        theta, converged = stepper.step_to(h, theta0, float(angle), speed0, float(speed))
        if converged:
            # ndarray.dot: the same BLAS product as @ (the same bits), half its call's cost
            output = stepper.output_operator.dot(stepper.q)
        else:
            self.counts['refused_samples'] += 1
            output = stepper.outputs(theta)
        self.last = (stamp_ns, theta, speed)
        self._pending = True
        if judge:
            self.judge()
        return output

    def judge(self):
        """
        Return the last sample's validity, its link slopes judged and counted once.

        :meth:`sample` does it unless told to wait; a start is not judged (NaN).
        """
        if self._pending:
            self._pending = False
            slopes = self.stepper.slope.tolist()
            self.validity = nonlinear_validity(slopes)
            slope = max(slopes, default=0.0) if not math.isnan(self.validity) else math.nan
            self.slope_max = max(self.slope_max, slope)
            self.counts['beyond_von_karman_samples'] += slope > VON_KARMAN_SLOPE
        return self.validity

    def follow(self, stamps_ns, angles, speeds):
        """
        Step to many accepted samples in order; their output deflections [m], (K, channels).

        :meth:`sample` for each, with every run between starts marched in one call of the
        compiled step (no Python between its samples, the GIL released throughout): the same
        numbers to rounding (the steps are the stamps' differences in seconds taken from the
        run's first stamp, and the outputs summed in C). Without the compiled step, or for a
        single sample, :meth:`sample` itself.
        """
        stamps_ns = np.asarray(stamps_ns, dtype=np.int64)
        outputs = np.empty((stamps_ns.size, self.tables.outputs))
        if not self.stepper.compiled:
            for n, (stamp, angle, speed) in enumerate(zip(stamps_ns.tolist(), angles, speeds)):
                outputs[n] = self.sample(stamp, float(angle), float(speed))
            return outputs
        # Where sample() would start again: the first sample without a state, and gaps.
        steps_s = np.diff(stamps_ns, prepend=-1 if self.last is None else self.last[0]) * 1e-9
        starts = set(np.flatnonzero(~((steps_s > 0.0) & (steps_s <= self.reset_gap_s))).tolist())
        if self.last is None:
            starts.add(0)
        bounds = sorted({0, stamps_ns.size} | starts)
        for first, stop in zip(bounds[:-1], bounds[1:]):
            self._run(stamps_ns[first:stop], angles[first:stop], speeds[first:stop],
                      outputs[first:stop], starts=first in starts)
        return outputs

    def _run(self, stamps_ns, angles, speeds, outputs, starts):
        """March samples with no start among them but perhaps the first (``starts``)."""
        if starts:
            outputs[0] = self.sample(int(stamps_ns[0]), float(angles[0]), float(speeds[0]))
            stamps_ns, angles, speeds, outputs = (stamps_ns[1:], angles[1:], speeds[1:],
                                                  outputs[1:])
        if not stamps_ns.size:
            return
        stepper, counts = self.stepper, self.counts
        counts['samples'] += stamps_ns.size
        origin_ns, theta0, speed0 = self.last
        times_ns = np.concatenate([[origin_ns], stamps_ns])
        speeds = np.concatenate([[speed0], np.asarray(speeds, dtype=float)])
        theta = np.empty(times_ns.size)
        theta[0] = theta0
        for k, angle in enumerate(np.asarray(angles, dtype=float).tolist(), start=1):
            # sample()'s unwrapping, sample by sample (cheap beside the step)
            theta[k] = unwrap_next(theta[k - 1], angle, speeds[k - 1], speeds[k],
                                   int(times_ns[k] - times_ns[k - 1]) * 1e-9)
        outputs[:], _, slope, converged, _ = stepper.march((times_ns - origin_ns) * 1e-9,
                                                           theta, speeds)
        counts['refused_samples'] += int(np.count_nonzero(~converged))
        largest = np.max(slope, axis=1) if slope.shape[1] else np.zeros(slope.shape[0])
        self.slope_max = max(self.slope_max, float(np.max(largest)))
        counts['beyond_von_karman_samples'] += int(np.count_nonzero(largest > VON_KARMAN_SLOPE))
        self.validity = nonlinear_validity(stepper.slope)
        self.last = (int(stamps_ns[-1]), float(theta[-1]), float(speeds[-1]))


def follow_rows(follower, stamps_ns, estimate):
    """
    Step ``follower`` through an offline estimate's accepted rows; their outputs [m].

    Parameters
    ----------
    follower : NonlinearFollower
        Carries the state from one block of rows to the next.
    stamps_ns : ndarray of int, shape (K,)
        The rows' stamps.
    estimate : dict
        :func:`.offline.estimate_offline`'s arrays for the rows: 'lever_tip', 'coupler_mid'
        (NaN where the linear estimator gave nothing), 'crank_angle', 'crank_speed'.

    Returns
    -------
    outputs : ndarray, shape (K, channels)
        NaN where the linear estimator gave nothing.
    accepted : ndarray of bool, shape (K,)

    """
    angles, speeds = estimate['crank_angle'], estimate['crank_speed']
    accepted = accepted_rows(estimate)
    outputs = np.full((len(accepted), follower.tables.outputs), np.nan)
    outputs[accepted] = follower.follow(np.asarray(stamps_ns)[accepted], angles[accepted],
                                        speeds[accepted])
    return outputs, accepted


def accepted_rows(estimate):
    """Return the rows the follower steps: those the linear estimate published (bool)."""
    return (np.all(np.isfinite(estimate['lever_tip']), axis=1)
            & np.all(np.isfinite(estimate['coupler_mid']), axis=1)
            & np.isfinite(estimate['crank_angle']) & np.isfinite(estimate['crank_speed']))


def follow_summary(follower, low, high, damping):
    """
    Return a run's ``nonlinear`` JSON entry: peak-to-peak deflections [um] and counts.

    ``low``, ``high``: the smallest and largest output per channel [m] (infinite: none);
    ``damping``: how the model is damped (said as it was chosen).
    """
    seen = bool(np.all(np.isfinite(high)))
    span = (1e6 * (np.asarray(high) - np.asarray(low))).tolist() if seen else [math.nan] * 4
    return {**follower.counts, 'lever_tip_peak_to_peak_um': span[0:2],
            'coupler_mid_peak_to_peak_um': span[2:4],
            'link_slope_max_rad': follower.slope_max, 'size': follower.tables.size,
            'links': follower.tables.links, 'damping': damping}


__all__ = ['CHOICES', 'choose_nonlinear', 'nonlinear_validity', 'NonlinearFollower',
           'follow_rows', 'accepted_rows', 'follow_summary']
