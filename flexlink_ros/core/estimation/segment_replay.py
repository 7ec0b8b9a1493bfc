"""
One segment of a recording estimated offline: :func:`replay`, the streaming step in batches.

A segment is a run of strictly increasing stamps without gaps or outliers (the offline
estimate, :mod:`.offline`, cuts a recording into them as the streaming node restarts). The
crank filter runs over the segment in one loop, then the compiled step advances through the
samples a chunk at a time: the same numbers as feeding :meth:`StreamingEstimator.update`
sample by sample. A caller may take each chunk's rows while the next chunk steps (the
compiled step runs without the GIL).
"""

import math

import numpy as np

from .crank_filter import DEFAULT_FIT_TIME_CONSTANT_S
from .native import RECORD_SIZE
from .sample import OUT_OF_BOUND
from .step import MAX_SUBSTEP_NS
from .streaming import DEFAULT_ACCEL_LIMIT, StreamingEstimator
from ...names import JOINT_NAMES, OUTPUT_NAMES

# Samples per batch of the compiled step (bounds its memory to a few MB).
REPLAY_CHUNK = 4096


def replay(model, stamps_ns, angles, speeds=None,
           fit_time_constant_s=DEFAULT_FIT_TIME_CONSTANT_S, warm_start=True,
           accel_limit=DEFAULT_ACCEL_LIMIT, compiled=True, orbit=None, on_rows=None,
           tables=None, warm_start_limiter=None, resume=None, beside_step=None):
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
        The reduced model.
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
    beside_step : callable or None
        ``beside_step(step)`` runs ``step()``, the compiled step of a chunk, and returns what
        it returns: a caller may do other work meanwhile (the rows of the chunk before it,
        given to ``on_rows``), as :mod:`.offline` does.

    Returns
    -------
    dict of str to ndarray
        'crank_angle', 'crank_speed', 'crank_accel' (m,); 'lever_tip', 'coupler_mid' (m, 2)
        [m]; 'correction' (m, 4): the residual correction alone [m] (the error indicator's
        numerator); 'modal', 'velocity' (m, r): q and q'; 'force', 'force_dot' (m, joints,
        2) and 'rms2' (m, joints): the tabulated joint reactions at the model's (clipped) crank
        state; 'orbit' for the next call; 'stopped': the index of the sample that went out of
        bound (the rows after it are not computed), or None; 'resume' for a call on the
        samples that follow.

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
        estimator.orbit = orbit
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
    _replay_rows(estimator, stamps_ns, angles, speeds, motion, result, (on_rows, beside_step),
                 previous_ns)
    result['orbit'] = estimator.orbit
    result['resume'] = (estimator, rate_filter, stamp0_ns, int(stamps_ns[-1]))
    return result


def _allocate(result, count, size):
    """Add the per-row outputs to a replay's ``result`` (NaN); return (modal, records)."""
    modal = np.full((count, size), math.nan)
    result['velocity'] = np.full((count, size), math.nan)
    records = np.full((count, RECORD_SIZE), math.nan)
    outputs, joints = len(OUTPUT_NAMES), len(JOINT_NAMES)
    joint = records[:, 2 * outputs:]
    result.update({'lever_tip': records[:, 0:2], 'coupler_mid': records[:, 2:4],
                   'correction': records[:, outputs:2 * outputs], 'modal': modal,
                   'force': joint[:, :2 * joints].reshape(count, joints, 2),
                   'force_dot': joint[:, 2 * joints:4 * joints].reshape(count, joints, 2),
                   'rms2': joint[:, 4 * joints:]})
    return modal, records


def _replay_rows(estimator, stamps_ns, angles, speeds, motion, result, hooks, previous_ns):
    """Run the steps of :func:`replay` into ``result`` (its 'stopped' set where one failed)."""
    on_rows, beside_step = hooks
    count = stamps_ns.size
    modal, records = _allocate(result, count, estimator.model.size)
    # The first samples (start and, without measured speeds, the deferred warm start) go
    # through update() itself; the steps continue from its state.
    prefix = min(3 if (estimator.warm_start and speeds is None) else 1, count)
    if previous_ns is not None:
        prefix = 0              # a resumed segment: the estimator has its state
    for n in range(prefix):
        sample = estimator.update(int(stamps_ns[n]), float(angles[n]),
                                  None if speeds is None else float(speeds[n]))
        if sample.flags & OUT_OF_BOUND:
            return _stop(result, n, on_rows)
        modal[n] = sample.modal
        result['velocity'][n] = estimator.state[modal.shape[1]:]
        records[n] = estimator.last_record
    # A non-finite filter output ends the steps before it (the stepper must not see it).
    finite = np.all(np.isfinite(motion[prefix:]), axis=1)
    last = prefix + (int(np.argmin(finite)) if not np.all(finite) else finite.size)
    rows = _row_table(estimator, stamps_ns, motion, slice(prefix, last), previous_ns)
    if on_rows is not None:
        on_rows(result, prefix)
    stopped = _step_chunks(estimator, rows, prefix, (modal, records, result['velocity']),
                           result, hooks)
    if stopped is not None:
        return _stop(result, stopped, on_rows)
    if last < count:
        return _stop(result, last, on_rows)
    return None


def _row_table(estimator, stamps_ns, motion, rows, previous_ns):
    """Return the step rows of samples ``rows`` as update() builds them (ROW_SIZE each)."""
    model = estimator.model
    wrapped, speed, accel, advance = motion.T
    model_speed = np.clip(speed, -model.speed_max, model.speed_max)
    model_accel = np.clip(accel, -estimator.accel_limit, estimator.accel_limit)
    # Step [s], sub-steps, crank state, advance.
    before = stamps_ns[0] if previous_ns is None else previous_ns
    dt_ns = np.diff(stamps_ns, prepend=before)[rows]
    return np.column_stack([dt_ns * 1e-9, -(-dt_ns // MAX_SUBSTEP_NS), wrapped[rows],
                            model_speed[rows], model_accel[rows], advance[rows]])


def _step_chunks(estimator, rows, prefix, outputs, result, hooks):
    """
    Step through ``rows`` in chunks of REPLAY_CHUNK; return the first row that failed, or None.

    ``outputs`` = (modal, records, velocity) of the replay, filled from row ``prefix`` on; a
    row fails when its step is singular or non-finite or its deflection is beyond the bound.
    """
    modal, records, velocity = outputs
    on_rows, beside_step = hooks
    beside_step = beside_step or (lambda step: step())
    r = estimator.model.size
    channels = len(OUTPUT_NAMES)
    states = np.empty((min(REPLAY_CHUNK, rows.shape[0]), 2 * r))
    for first in range(0, rows.shape[0], REPLAY_CHUNK):
        chunk = rows[first:first + REPLAY_CHUNK]
        done = slice(prefix + first, prefix + first + chunk.shape[0])
        states[:] = math.nan            # rows after a failed step stay NaN
        try:
            beside_step(lambda: estimator.step_rows(chunk, states[:chunk.shape[0]],
                                                    records[done]))
        except ValueError:              # singular or non-finite step: found below
            pass
        modal[done] = states[:chunk.shape[0], :r]
        velocity[done] = states[:chunk.shape[0], r:]
        good = np.all(np.isfinite(states[:chunk.shape[0]]), axis=1) & np.all(
            np.abs(records[done, :channels]) <= estimator.deflection_bound_m, axis=1)
        if not np.all(good):
            return done.start + int(np.argmin(good))
        if on_rows is not None:
            on_rows(result, done.stop)
    return None


def _stop(result, row, on_rows):
    """Mark ``row`` out of bound (NaN) in a replay's result; the rows before it are final."""
    for key in ('lever_tip', 'coupler_mid', 'modal', 'velocity', 'force', 'force_dot', 'rms2'):
        result[key][row:] = math.nan
    result['stopped'] = row
    if on_rows is not None:
        on_rows(result, row)
