"""
The offline estimate of a recorded sample stream, segment by segment as the node would.

:func:`estimate_offline` plans the rows as :meth:`StreamingEstimator.update` decides (restarts,
repeats, outliers) and replays each segment in one go (the same numbers as streaming);
:func:`criteria_batch` adds the criteria; :class:`BackgroundEstimate` runs it in a thread.
"""

import math
import threading
import time

import numpy as np

from .gate import DEFAULT_RESET_GAP_S, InputGate, plan_rows
from .nonlinearity import NonlinearityIndicator
from .offline import replay
from .sample import error_indicator_rows, SampleFlag
from .step import REACTION_FLOOR_FRACTION
from .streaming import DEFAULT_ACCEL_LIMIT, DEFAULT_NEAR_ZERO_FRACTION
from .tables import step_tables
from .warm_start import WarmStartLimiter
from ...names import JOINT_NAMES, OUTPUT_POINTS

# Rows planned at a time (plan_rows) ahead of the segment being replayed; after a restart the
# window starts small and doubles (little work lost if it stops again).
PLAN_WINDOW = 4096
FIRST_PLAN_WINDOW = 64
# The per-sample arrays of an estimate (besides 'flags').
_ESTIMATE_KEYS = OUTPUT_POINTS + ('crank_angle', 'crank_speed', 'modal', 'reaction_n',
                                  'gamma_dot', 'criterion', 'nonlinearity', 'error_indicator')


def criteria_batch(model, angles, speeds, accels,
                   near_zero_fraction=DEFAULT_NEAR_ZERO_FRACTION, blocks=None):
    """
    Compute joint reactions, direction rates and Earles-Wu criteria at many crank states.

    The same tabulated quantities as StreamingEstimator._criteria, vectorised.

    Parameters
    ----------
    model : ReducedModel
        The model (its joint-reaction tables).
    angles, speeds, accels : ndarray, shape (m,)
        Crank state as the model sees it (speed and acceleration clipped).
    near_zero_fraction : float
        A reaction below this fraction of its cycle RMS is flagged near zero.
    blocks : dict, optional
        'force', 'force_dot' (m, joints, 2) and 'rms2' (m, joints) at these states, if
        already evaluated (core.estimator.replay returns them); else the table is evaluated.

    Returns
    -------
    reaction_n, gamma_dot, criterion : ndarray, shape (m, 4)
    near_zero : ndarray of bool, shape (m, 4)
    available : bool
        False if the model has no joint-reaction data (all zeros then).

    """
    count = len(angles)
    zeros = np.zeros((count, len(JOINT_NAMES)))
    if not np.any(model.force_moments):
        return zeros, zeros, zeros, zeros.astype(bool), False
    if blocks is None:
        rows = model.evaluate(angles, speeds, accels)
        blocks = {name: model.layout.block(rows, name)
                  for name in ('force', 'force_dot', 'rms2')}
    force, rate, rms2 = blocks['force'], blocks['force_dot'], blocks['rms2']
    r2 = np.sum(force ** 2, axis=2)
    # Below REACTION_FLOOR_FRACTION of the cycle RMS the reaction is clamped (finite criterion).
    clamped = np.maximum(r2, REACTION_FLOOR_FRACTION ** 2 * rms2)
    positive = clamped > 0.0
    safe = np.where(positive, clamped, 1.0)
    gamma_dot = np.where(positive, (force[..., 0] * rate[..., 1]
                                    - force[..., 1] * rate[..., 0]) / safe, 0.0)
    criterion = np.where(positive, np.abs(gamma_dot) / np.sqrt(safe), 0.0)
    reaction = np.where(positive, np.sqrt(r2), 0.0)
    return reaction, gamma_dot, criterion, r2 < near_zero_fraction ** 2 * rms2, True


def segments(stamps_ns, angles, reset_gap_s=DEFAULT_RESET_GAP_S):
    """
    Split a sample stream where the streaming estimator would restart on its stamps.

    Stamps and angles only, without the input gate's outliers (estimate_offline plans its
    rows with core.estimator.plan_rows, which has both).

    Returns
    -------
    starts : list of int
        First index of each segment.
    repeated : ndarray of bool, shape (m,)
        Exact repeats of the previous sample (same stamp and wrapped angle).

    """
    stamps_ns = np.asarray(stamps_ns, dtype=np.int64)
    steps = np.diff(stamps_ns)
    wrapped = np.mod(angles, 2.0 * math.pi)
    repeated = np.concatenate([[False], (steps == 0) & (np.abs(np.diff(wrapped)) < 1e-12)])
    # Each kept sample against the previous kept one (repeats are skipped, as the node does).
    kept = np.flatnonzero(~repeated)
    dt = np.diff(stamps_ns[kept]) * 1e-9
    starts = [0] + kept[1:][(dt <= 0.0) | (dt > reset_gap_s)].tolist()
    return starts, repeated


def allocate_estimate(model, count):
    """
    Allocate the arrays :func:`estimate_offline` fills (zeros; 'flags' per sample).

    Parameters
    ----------
    model : ReducedModel
        The model (its basis size).
    count : int
        Number of samples.

    Returns
    -------
    dict of ndarray

    """
    result = {key: np.zeros((count, 2)) for key in OUTPUT_POINTS}
    for key in ('reaction_n', 'gamma_dot', 'criterion'):
        result[key] = np.zeros((count, len(JOINT_NAMES)))
    for key in ('crank_angle', 'crank_speed', 'nonlinearity', 'error_indicator'):
        result[key] = np.zeros(count)
    result['modal'] = np.zeros((count, model.size))
    result['flags'] = np.zeros(count, dtype=np.int64)
    return result


def estimate_offline(model, stamps_ns, angles, speeds, warm_start=True, result=None,
                     progress=None):
    """
    Estimate deflections and criteria of every sample, segment by segment as the node would.

    The rows are planned as StreamingEstimator.update decides (core.estimator.plan_rows:
    restarts, repeats, outliers); each segment is replayed in one go. Outlier rows and rows
    whose estimate left the model's deflection bound are NaN (flagged OUTLIER and
    OUT_OF_BOUND); after an out-of-bound row the rest is planned again, as the node restarts.

    Parameters
    ----------
    model : ReducedModel
        The model.
    stamps_ns : ndarray of int, shape (m,)
        Sample stamps [ns].
    angles : ndarray, shape (m,)
        Crank angles [rad].
    speeds : ndarray, shape (m,)
        Measured speeds; NaN where a message had none (the segment then differentiates).
    warm_start : bool
        Start each segment from the periodic state (else from the static deflection).
    result : dict or None
        The arrays to fill (:func:`allocate_estimate`); new ones if None.
    progress : callable or None
        ``progress(n)`` whenever the first n samples are final (the writer of the outputs
        follows it while the rest is computed).

    Returns
    -------
    dict of ndarray
        'lever_tip', 'coupler_mid' (m, 2) [m]; 'reaction_n', 'gamma_dot', 'criterion' (m, 4);
        'crank_angle', 'crank_speed', 'nonlinearity' (validity indicator), 'error_indicator'
        (m,); 'modal' (m, r); 'flags' (m,); 'criteria_available' (bool); 'segments',
        'outliers', 'out_of_bound'.

    """
    count = len(stamps_ns)
    if result is None:
        result = allocate_estimate(model, count)
    run = _OfflineRun(model, np.asarray(stamps_ns, dtype=np.int64), np.asarray(angles, float),
                      np.asarray(speeds, float), warm_start, result, progress)
    position = 0
    while position < count:
        position = run.next_segment(position)
    run.finish_until(count)
    flags = result['flags']
    result.update(criteria_available=run.available, segments=run.segments,
                  outliers=int(np.count_nonzero(flags & SampleFlag.OUTLIER)),
                  out_of_bound=int(np.count_nonzero(flags & SampleFlag.OUT_OF_BOUND)))
    return result


class _OfflineRun:
    """The state of :func:`estimate_offline`: segments, repeats to copy, rows final so far."""

    def __init__(self, model, stamps_ns, angles, speeds, warm_start, result, progress):
        self.model, self.stamps_ns, self.angles, self.speeds = model, stamps_ns, angles, speeds
        self.warm_start, self.result, self.progress = warm_start, result, progress
        self.count, self.nonlinearity = stamps_ns.size, NonlinearityIndicator(model)
        self.available = bool(np.any(model.force_moments))
        self.tables = step_tables(model)    # built once, not per segment
        self.orbit = None   # carried across segments, as one streaming estimator carries it
        # Warm starts rate-limited on the recording's clock (its latest stamp so far): the
        # same numbers on any machine, and a storm of restarts costs no more than the node's.
        self.clock_s = -math.inf
        self.limiter = WarmStartLimiter(clock=lambda: self.clock_s)
        self.repeats = []           # (row, row it repeats), in order
        self.copied = 0             # repeats copied so far
        self.kinds = np.zeros(self.count, dtype=np.int8)    # InputGate kinds, as planned
        self.restart_plan(0)
        self.segments = 0
        self.final = 0
        self.chosen = self.stop = self.resume = None
        self.measured = True
        self.done = 0
        self.last_accepted = -1

    def restart_plan(self, position):
        """Plan the rows from ``position`` afresh (the first sample, or after out of bound)."""
        self.gate = InputGate(self.model.speed_max, DEFAULT_ACCEL_LIMIT)
        self.planned = position
        self.window = FIRST_PLAN_WINDOW

    def plan_window(self):
        """Plan a window more rows (core.estimator.plan_rows, the gate carried on)."""
        stop = min(self.planned + min(self.window, PLAN_WINDOW), self.count)
        self.window *= 2
        window = slice(self.planned, stop)
        self.kinds[window], _ = plan_rows(
            self.stamps_ns[window], self.angles[window], self.speeds[window], self.gate)
        self.planned = stop

    def next_start(self, position):
        """Find the first START row at or after ``position`` in the planned rows, or None."""
        starts = np.flatnonzero(self.kinds[position:self.planned] == InputGate.START)
        return position + int(starts[0]) if starts.size else None

    def next_segment(self, position):
        """
        Replay the segment that starts at or after ``position``; where the next one may start.

        Planned and replayed a window at a time (one replay() call resumed per window): an
        out-of-bound row wastes at most a window of planning and stepping, so a recording
        that goes out of bound often costs time linear in its length.
        """
        first = self.next_start(position)
        while first is None and self.planned < self.count:
            self.plan_window()
            first = self.next_start(position)
        first = self.count if first is None else first
        self.mark(np.arange(position, first), SampleFlag.OUTLIER)   # no start before: outliers
        if first == self.count:
            return self.count
        while self.planned < min(first + 3, self.count):
            self.plan_window()      # replay()'s first call takes the deferred warm start
        self.segments += 1
        self.result['flags'][first] |= int(SampleFlag.RESET)
        self.last_accepted, self.resume = first, None
        start, search = first, first + 1
        while True:
            found = self.next_start(search)
            stop = self.planned if found is None else found
            stopped = self.piece(start, stop)
            if stopped is not None:
                # The node restarts at the next sample: plan the rest again from there.
                self.restart_plan(stopped + 1)
                self.result['flags'][stopped + 1:stop] = 0
                del self.repeats[self.copied:]
                return stopped + 1
            if found is not None or stop == self.count:
                return stop
            self.plan_window()
            start = search = stop

    def piece(self, start, stop):
        """Rows start...stop of the current segment: outliers, repeats, steps; None or a stop."""
        rows = np.arange(start, stop)
        kinds = self.kinds[start:stop]
        self.mark(rows[kinds == InputGate.OUTLIER], SampleFlag.OUTLIER)
        accepted = (kinds == InputGate.STEP) | (kinds == InputGate.START)
        # Each repeat copies the last accepted row before it.
        source = np.maximum.accumulate(np.where(accepted, rows, self.last_accepted))
        repeated = np.flatnonzero(kinds == InputGate.REPEATED)
        self.repeats += zip(rows[repeated].tolist(), source[repeated].tolist())
        chosen = rows[accepted]
        if chosen.size == 0:
            self.finish_until(stop)
            return None
        self.last_accepted = int(chosen[-1])
        return self.segment(chosen, stop)

    def mark(self, rows, flag):
        """Rows with no estimate (NaN), flagged."""
        for key in _ESTIMATE_KEYS:
            self.result[key][rows] = math.nan
        self.result['flags'][rows] = int(flag)

    def segment(self, chosen, stop):
        """Replay (or resume) the segment over rows ``chosen``; the row out of bound, or None."""
        self.chosen, self.stop, self.done = chosen, stop, 0
        seg_speeds = self.speeds[chosen]
        if self.resume is None:
            # Measured speeds if every sample of the segment's first window has one.
            self.measured = not np.any(np.isnan(seg_speeds))
        measured = seg_speeds if self.measured else None
        self.clock_s = max(self.clock_s, self.stamps_ns[chosen[0]] * 1e-9)
        out = replay(self.model, self.stamps_ns[chosen], self.angles[chosen],
                     measured, warm_start=self.warm_start, orbit=self.orbit,
                     on_rows=self.on_rows, tables=self.tables,
                     warm_start_limiter=self.limiter, resume=self.resume)
        self.orbit, self.resume = out['orbit'], out['resume']
        if out['stopped'] is None:
            return None
        row = int(chosen[out['stopped']])
        self.mark([row], SampleFlag.OUT_OF_BOUND)
        self.finish_until(row + 1)
        return row

    def on_rows(self, out, upto):
        """Take the rows of the current segment replay() has finished since the last call."""
        if upto <= self.done:
            return
        rows = slice(self.done, upto)
        model = self.model
        model_speed = np.clip(out['crank_speed'][rows], -model.speed_max, model.speed_max)
        model_accel = np.clip(out['crank_accel'][rows], -DEFAULT_ACCEL_LIMIT,
                              DEFAULT_ACCEL_LIMIT)
        blocks = {name: out[name][rows] for name in ('force', 'force_dot', 'rms2')}
        reaction, gamma_dot, criterion, _, self.available = criteria_batch(
            model, out['crank_angle'][rows], model_speed, model_accel, blocks=blocks)
        target = self.chosen[rows]
        nonlinearity = self.nonlinearity.batch(out['crank_angle'][rows], model_speed, model_accel,
                                               out['modal'][rows], out['velocity'][rows])
        error = error_indicator_rows(*(out[k][rows] for k in OUTPUT_POINTS + ('correction',)))
        for key in OUTPUT_POINTS + ('crank_angle', 'crank_speed', 'modal'):
            self.result[key][target] = out[key][rows]
        for key, values in (('nonlinearity', nonlinearity), ('error_indicator', error),
                            ('reaction_n', reaction), ('gamma_dot', gamma_dot),
                            ('criterion', criterion)):
            self.result[key][target] = values
        self.done = upto
        self.finish_until(self.stop if upto == self.chosen.size else int(self.chosen[upto]))

    def finish_until(self, final):
        """Copy the repeats before ``final`` (as StreamingEstimator.update) and report it."""
        result = self.result
        while self.copied < len(self.repeats) and self.repeats[self.copied][0] < final:
            row, source = self.repeats[self.copied]
            for key in _ESTIMATE_KEYS:
                result[key][row] = result[key][source]
            result['flags'][row] = int(SampleFlag.REPEATED)
            self.copied += 1
        self.final = max(self.final, final)
        if self.progress is not None:
            self.progress(self.final)


class BackgroundEstimate:
    """
    :func:`estimate_offline` in a thread, with the number of final samples for a reader.

    Parameters
    ----------
    run_estimate : callable
        ``run_estimate(result=..., progress=...)``: :func:`estimate_offline` with its
        model and samples bound.
    result : dict
        The arrays it fills (:func:`allocate_estimate`), readable as they become final.

    """

    def __init__(self, run_estimate, result):
        self.result, self.seconds, self._done, self._error = result, None, 0, None
        self._condition = threading.Condition()
        self._thread = threading.Thread(target=self._run, args=(run_estimate,),
                                        name='replay-estimate', daemon=True)
        self._thread.start()

    def _run(self, run_estimate):
        start = time.perf_counter()
        try:
            run_estimate(result=self.result, progress=self._progress)
        except BaseException as exc:   # handed to the waiting thread
            with self._condition:
                self._error = exc
                self._condition.notify_all()
        self.seconds = time.perf_counter() - start

    def _progress(self, count):
        with self._condition:
            self._done = count
            self._condition.notify_all()

    def wait_for(self, count):
        """Return once the first ``count`` samples are final; raise the estimate's error."""
        with self._condition:
            while self._done < count and self._error is None:
                self._condition.wait(0.5)
            if self._error is not None:
                raise self._error

    def join(self):
        """Wait for the estimate to end; raise its error."""
        self._thread.join()
        if self._error is not None:
            raise self._error
