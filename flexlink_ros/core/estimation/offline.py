"""
The offline estimate: a recorded sample stream estimated as the streaming node would.

:func:`estimate_stream` plans the rows as :meth:`StreamingEstimator.update` decides (restarts,
repeats, outliers) and replays each segment in pieces, reading its input in chunks and handing
the rows on once final, so a recording of any length is estimated in bounded memory
(:class:`.row_window.RowWindow`); :func:`estimate_offline` does it for arrays in memory.
Each segment is a :func:`.segment_replay.replay`; the rows of one chunk are taken (criteria,
indicators, handed on) in a thread beside the compiled step of the next.
"""

import concurrent.futures
import math

import numpy as np

from .criteria_rows import criteria_batch
from .gate import DEFAULT_RESET_GAP_S, InputGate, plan_rows
from .nonlinearity import NonlinearityIndicator
from .row_window import RowWindow
from .sample import error_indicator_rows, SampleFlag
from .segment_replay import replay
from .streaming import DEFAULT_ACCEL_LIMIT
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


def segments(stamps_ns, angles, reset_gap_s=DEFAULT_RESET_GAP_S):
    """
    Split a sample stream where the streaming estimator would restart on its stamps.

    Stamps and angles only, without the input gate's outliers (estimate_offline plans its
    rows with core.estimation.gate.plan_rows, which has both).

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


def _window_columns(model):
    """Return the columns of a run's :class:`RowWindow`: input, plan and estimate."""
    columns = {'stamps_ns': ((), np.int64), 'angles': ((), float), 'speeds': ((), float),
               'kinds': ((), np.int8), 'flags': ((), np.int64)}
    columns.update({key: ((2,), float) for key in OUTPUT_POINTS})
    columns.update({key: ((len(JOINT_NAMES),), float)
                    for key in ('reaction_n', 'gamma_dot', 'criterion')})
    columns.update({key: ((), float)
                    for key in ('crank_angle', 'crank_speed', 'nonlinearity', 'error_indicator')})
    columns['modal'] = ((model.size,), float)
    return columns


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
    return {key: np.zeros((count,) + tuple(shape), dtype=dtype)
            for key, (shape, dtype) in _window_columns(model).items()
            if key in _ESTIMATE_KEYS + ('flags',)}


def estimate_offline(model, stamps_ns, angles, speeds, warm_start=True, result=None,
                     progress=None):
    """
    Estimate deflections and criteria of every sample, segment by segment as the node would.

    :func:`estimate_stream` over arrays in memory. Outlier rows and rows whose estimate left
    the model's deflection bound are NaN (flagged OUTLIER and OUT_OF_BOUND); after an
    out-of-bound row the rest is planned again, as the node restarts.

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
        ``progress(n)`` whenever the first n samples are final.

    Returns
    -------
    dict of ndarray
        'lever_tip', 'coupler_mid' (m, 2) [m]; 'reaction_n', 'gamma_dot', 'criterion' (m, 4);
        'crank_angle', 'crank_speed', 'nonlinearity' (validity indicator), 'error_indicator'
        (m,); 'modal' (m, r); 'flags' (m,); and :func:`estimate_stream`'s counts.

    """
    count = len(stamps_ns)
    if result is None:
        result = allocate_estimate(model, count)

    def emit(first, block):
        stop = first + len(block['flags'])
        for key, values in block.items():
            result[key][first:stop] = values
        if progress is not None:
            progress(stop)
    chunks = [(np.asarray(stamps_ns, dtype=np.int64), np.asarray(angles, dtype=float),
               np.asarray(speeds, dtype=float))] if count else []
    result.update(estimate_stream(model, chunks, emit, warm_start=warm_start))
    return result


def estimate_stream(model, chunks, emit, warm_start=True, align=1, block_rows=1, tables=None):
    """
    Estimate a stream of samples read in chunks, handing on the rows in order once final.

    The same numbers as one :func:`estimate_offline` over the whole stream, however it is
    chunked: the rows are planned a window at a time (restarts, repeats, outliers, as
    :meth:`StreamingEstimator.update` decides) and a window is planned only once all its rows
    are read, so the windows, and the pieces each segment is replayed in, do not depend on
    the chunks. Memory: the rows not yet handed on (fewer than ``block_rows + align``), the
    plan's look-ahead (2 ``PLAN_WINDOW``) and one chunk.

    Parameters
    ----------
    model : ReducedModel
        The model.
    chunks : iterable of (stamps_ns, angles, speeds)
        The samples in order: int64 stamps [ns], angles [rad], speeds (NaN where none).
    emit : callable
        ``emit(first, block)``: rows ``first...`` are final; ``block`` maps the estimate's
        keys (:func:`estimate_offline`, with 'flags') to copies of their rows.
    warm_start : bool
        Start each segment from the periodic state (else from the static deflection).
    align : int
        Blocks end at a multiple of ``align`` rows (but the last).
    block_rows : int
        Hand rows on once at least this many are final (and at the end).
    tables : object or None
        :func:`step_tables` of ``model`` when the caller has them (built here if None).

    Returns
    -------
    dict
        'samples', 'segments', 'outliers', 'out_of_bound' (counts), 'criteria_available'
        (False: the model has no joint-reaction data, criteria are zeros) and 'window_rows'
        (the most rows held at once).

    """
    blocks = (max(int(align), 1), max(int(block_rows), 1))
    run = _OfflineRun(model, iter(chunks), warm_start, emit, blocks, tables)
    with concurrent.futures.ThreadPoolExecutor(1, 'estimate-rows') as run.beside:
        position = 0
        while position < run.ensure(position + 1):
            position = run.next_segment(position)
        run.finish_until(run.window.end)
        run.hand_on(run.final)
    return {'samples': run.final, 'criteria_available': run.available,
            'segments': run.segments, 'window_rows': run.window_rows, **run.counts}


class _OfflineRun:
    """The state of :func:`estimate_stream`: segments, repeats to copy, rows final so far."""

    def __init__(self, model, chunks, warm_start, emit, blocks, tables=None):
        self.model, self.chunks, self.warm_start, self.emit = model, chunks, warm_start, emit
        self.align, self.block_rows = blocks
        self.window = RowWindow(_window_columns(model))
        self.exhausted, self.window_rows = False, 0
        self.stamps_ns, self.angles, self.speeds, self.kinds = (
            self.window[key] for key in ('stamps_ns', 'angles', 'speeds', 'kinds'))
        self.result = {key: self.window[key] for key in _ESTIMATE_KEYS + ('flags',)}
        self.nonlinearity = NonlinearityIndicator(model)
        self.available = bool(np.any(model.force_moments))
        # Built once, not per segment.
        self.tables = step_tables(model) if tables is None else tables
        self.orbit = None   # carried across segments, as one streaming estimator carries it
        # Warm starts rate-limited on the recording's clock (its latest stamp so far): the
        # same numbers on any machine, and a storm of restarts costs no more than the node's.
        self.clock_s = -math.inf
        self.limiter = WarmStartLimiter(clock=lambda: self.clock_s)
        self.repeats = []           # (row, row it repeats), in order
        self.copied = 0             # repeats copied so far
        self.restart_plan(0)
        self.segments = 0
        self.final = self.handed = 0
        self.counts = {'outliers': 0, 'out_of_bound': 0}
        self.chosen = self.stop = self.resume = None
        self.measured = True
        self.done = 0
        self.last_accepted = -1
        self.taken = None           # rows stepped, their estimate to take (take_rows)
        self.beside = None          # the thread that takes them while the next rows step

    def ensure(self, rows):
        """Read chunks until the window reaches row ``rows`` or the input ends; its end."""
        while self.window.end < rows and not self.exhausted:
            chunk = next(self.chunks, None)
            if chunk is None:
                self.exhausted = True
            elif len(chunk[0]):
                self.forget_handed()
                self.window.append(dict(zip(('stamps_ns', 'angles', 'speeds'), chunk)))
                self.window_rows = max(self.window_rows, self.window.end - self.window.base)
        return self.window.end

    def forget_handed(self):
        """Drop the rows handed on, but the one later repeats may still copy."""
        del self.repeats[:self.copied]
        self.copied = 0
        cut = self.handed
        # Every repeat still to copy from before the cut copies the last accepted row before
        # it (no accepted row lies between): one row at most is held aside.
        sources = [source for _, source in self.repeats if source < cut]
        if 0 <= self.last_accepted < cut:
            sources.append(self.last_accepted)
        self.window.drop_before(cut, hold=max(sources) if sources else None)

    def restart_plan(self, position):
        """Plan the rows from ``position`` afresh (the first sample, or after out of bound)."""
        self.gate = InputGate(self.model.speed_max, DEFAULT_ACCEL_LIMIT)
        self.planned = position
        self.plan_size = FIRST_PLAN_WINDOW

    def plan_window(self):
        """Plan a window more rows (core.estimation.gate.plan_rows, the gate carried on)."""
        wanted = self.planned + min(self.plan_size, PLAN_WINDOW)
        stop = min(wanted, self.ensure(wanted))
        self.plan_size *= 2
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
        while first is None and self.planned < self.ensure(self.planned + 1):
            # No start before: outliers (final now, so a long run of them is not held).
            self.mark(np.arange(position, self.planned), SampleFlag.OUTLIER)
            self.finish_until(self.planned)
            position = self.planned
            self.plan_window()
            first = self.next_start(position)
        if first is None:
            self.mark(np.arange(position, self.planned), SampleFlag.OUTLIER)
            return self.planned
        self.mark(np.arange(position, first), SampleFlag.OUTLIER)
        while self.planned < min(first + 3, self.ensure(first + 3)):
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
            if found is not None or stop >= self.ensure(stop + 1):
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
        self.clock_s = max(self.clock_s, self.stamps_ns[int(chosen[0])] * 1e-9)
        out = replay(self.model, self.stamps_ns[chosen], self.angles[chosen],
                     measured, warm_start=self.warm_start, orbit=self.orbit,
                     on_rows=self.on_rows, tables=self.tables,
                     warm_start_limiter=self.limiter, resume=self.resume,
                     beside_step=self.beside_step)
        self.orbit, self.resume = out['orbit'], out['resume']
        if out['stopped'] is None:
            return None
        row = int(chosen[out['stopped']])
        self.mark([row], SampleFlag.OUT_OF_BOUND)
        self.finish_until(row + 1)
        return row

    def on_rows(self, out, upto):
        """
        Note the rows of the current segment replay() has finished since the last call.

        They are taken (:meth:`take_rows`) while the next rows step, or before anything else
        reads or hands on rows.
        """
        if upto <= self.done:
            return
        self.take_rows()
        self.taken = (out, self.done, upto, self.chosen, self.stop)
        self.done = upto

    def beside_step(self, step):
        """Run ``step`` (the compiled step, without the GIL) while the rows before it are taken."""
        if self.taken is None:
            return step()
        future = self.beside.submit(self.take_rows)
        try:
            return step()
        finally:
            future.result()

    def take_rows(self):
        """Take the rows noted by :meth:`on_rows`: criteria, indicators, then hand them on."""
        if self.taken is None:
            return
        (out, done, upto, chosen, stop), self.taken = self.taken, None
        rows = slice(done, upto)
        model = self.model
        model_speed = np.clip(out['crank_speed'][rows], -model.speed_max, model.speed_max)
        model_accel = np.clip(out['crank_accel'][rows], -DEFAULT_ACCEL_LIMIT,
                              DEFAULT_ACCEL_LIMIT)
        blocks = {name: out[name][rows] for name in ('force', 'force_dot', 'rms2')}
        reaction, gamma_dot, criterion, _, self.available = criteria_batch(
            model, out['crank_angle'][rows], model_speed, model_accel, blocks=blocks)
        target = chosen[rows]
        nonlinearity = self.nonlinearity.batch(out['crank_angle'][rows], model_speed, model_accel,
                                               out['modal'][rows], out['velocity'][rows])
        error = error_indicator_rows(*(out[k][rows] for k in OUTPUT_POINTS + ('correction',)))
        for key in OUTPUT_POINTS + ('crank_angle', 'crank_speed', 'modal'):
            self.result[key][target] = out[key][rows]
        for key, values in (('nonlinearity', nonlinearity), ('error_indicator', error),
                            ('reaction_n', reaction), ('gamma_dot', gamma_dot),
                            ('criterion', criterion)):
            self.result[key][target] = values
        self.finish_until(stop if upto == chosen.size else int(chosen[upto]))

    def finish_until(self, final):
        """Copy the repeats before ``final`` (as StreamingEstimator.update); hand rows on."""
        self.take_rows()
        while self.copied < len(self.repeats) and self.repeats[self.copied][0] < final:
            row, source = self.repeats[self.copied]
            self.window.copy_row(source, row, _ESTIMATE_KEYS)
            self.result['flags'][row] = int(SampleFlag.REPEATED)
            self.copied += 1
        self.final = max(self.final, final)
        upto = self.final - self.final % self.align
        if upto - self.handed >= self.block_rows:
            self.hand_on(upto)

    def hand_on(self, upto):
        """Give rows handed...upto (final) to ``emit``."""
        self.take_rows()
        if upto <= self.handed:
            return
        block = self.window.rows(self.handed, upto, _ESTIMATE_KEYS + ('flags',))
        flags = block['flags']
        self.counts['outliers'] += int(np.count_nonzero(flags & SampleFlag.OUTLIER))
        self.counts['out_of_bound'] += int(np.count_nonzero(flags & SampleFlag.OUT_OF_BOUND))
        first, self.handed = self.handed, upto
        self.emit(first, block)
