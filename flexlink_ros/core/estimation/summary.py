"""
A recording's estimate summarised per crank revolution or per minute: the fleet table's rows.

:func:`period_ids` cuts the samples into periods (a revolution ends where the crank angle
passes a multiple of 2 pi; a minute at each whole minute of stamps since the first sample; a
new segment of the estimate, after a gap or a backward stamp, always starts a new period);
:func:`summarize_periods` gives each period's peak-to-peak deflections, worst Earles-Wu
criterion per joint and the crank angle where, validity and counts, as columns; and
:func:`recording_totals` the whole recording's peak-to-peak and quality maxima (the numbers
``flexlink replay`` reports), from the same per-period extremes.
"""

import math

import numpy as np

from .sample import CLIPPED_SPEED, OUT_OF_BOUND, OUTLIER, REPEATED, RESET
from ..validity import VALIDITY_THRESHOLD
from ...names import JOINT_NAMES, OUTPUT_NAMES, OUTPUT_POINTS, QUALITY_NAMES

PERIODS = ('revolution', 'minute')
MINUTE_NS = 60_000_000_000
TWO_PI = 2.0 * math.pi


def sample_durations(stamps_ns, starts):
    """
    Time each sample stands for [s]: the step to the next one within its segment.

    The last sample of a segment gets the median step of the recording; backward or zero
    steps count 0.

    Parameters
    ----------
    stamps_ns : ndarray of int, shape (m,)
        Sample stamps [ns].
    starts : ndarray of bool, shape (m,)
        First sample of each segment.

    Returns
    -------
    ndarray, shape (m,)

    """
    count = len(stamps_ns)
    steps = np.diff(np.asarray(stamps_ns, dtype=np.int64)) * 1e-9
    durations = np.empty(count)
    durations[:-1] = np.maximum(steps, 0.0) if count else steps
    last = np.append(starts[1:], True) if count else starts
    positive = steps[steps > 0.0]
    durations[last] = float(np.median(positive)) if positive.size else 0.0
    return durations


def _monotone_turns(angles, starts):
    """Whole turns of the unwrapped crank angle, held at its extreme along each segment."""
    turns = np.zeros(len(angles), dtype=np.int64)
    bounds = np.append(np.flatnonzero(starts), len(angles))
    for first, stop in zip(bounds[:-1], bounds[1:]):
        unwrapped = np.unwrap(angles[first:stop])
        whole = np.floor(unwrapped / TWO_PI).astype(np.int64)
        # Held monotone in the direction of travel: jitter about a turn's angle adds no period.
        forward = unwrapped[-1] >= unwrapped[0]
        turns[first:stop] = (np.maximum if forward else np.minimum).accumulate(whole)
    return turns


def period_ids(stamps_ns, angles, estimated, flags, per='revolution'):
    """
    Give each sample its period's number: 0, 1, ... in sample order, each a run of samples.

    Parameters
    ----------
    stamps_ns : ndarray of int, shape (m,)
        Sample stamps [ns].
    angles : ndarray, shape (m,)
        Crank angles [rad] (any wrapping).
    estimated : ndarray of bool, shape (m,)
        Samples with an estimate; the others (outliers, out of bound) join the period of the
        estimated sample before them (their angle is not trusted).
    flags : ndarray of int, shape (m,)
        The estimate's sample flags (RESET starts a segment).
    per : str
        'revolution' or 'minute'.

    Returns
    -------
    ndarray of int, shape (m,)

    """
    if per not in PERIODS:
        raise ValueError(f'per must be one of {PERIODS}, got {per!r}')
    count = len(stamps_ns)
    if not count:
        return np.zeros(0, dtype=np.int64)
    rows = np.flatnonzero(estimated)
    if not rows.size:
        return np.zeros(count, dtype=np.int64)
    starts = (np.asarray(flags)[rows] & RESET) != 0
    starts[0] = True
    if per == 'revolution':
        keys = _monotone_turns(np.asarray(angles, float)[rows], starts)
    else:
        keys = (np.asarray(stamps_ns, np.int64)[rows] - int(stamps_ns[rows[0]])) // MINUTE_NS
    new = starts.copy()
    new[1:] |= keys[1:] != keys[:-1]
    ids = np.cumsum(new) - 1
    # Every sample takes the id of the last estimated sample at or before it (the first one's
    # before it).
    holder = np.maximum(np.searchsorted(rows, np.arange(count), side='right') - 1, 0)
    return ids[holder]


def _group_extremes(values, starts):
    """Per-group minimum and maximum along axis 0, NaN ignored (NaN for an all-NaN group)."""
    return np.fmin.reduceat(values, starts, axis=0), np.fmax.reduceat(values, starts, axis=0)


def _group_argmax(values, ids, starts):
    """Row of each group's largest finite value (-1 where the group has none)."""
    keyed = np.where(np.isfinite(values), values, -np.inf)
    order = np.lexsort((keyed, ids))
    last = order[np.append(starts[1:], len(ids)) - 1]
    return np.where(np.isfinite(keyed[last]), last, -1)


def summarize_periods(stamps_ns, estimate, ids, validity_threshold=VALIDITY_THRESHOLD):
    """
    Summarise each period of an estimate: the fleet table's numeric columns.

    Parameters
    ----------
    stamps_ns : ndarray of int, shape (m,)
        Sample stamps [ns].
    estimate : dict
        :func:`core.estimation.offline.estimate_offline`'s result for those samples.
    ids : ndarray of int, shape (m,)
        :func:`period_ids` of the samples.
    validity_threshold : float
        A sample whose nonlinearity indicator exceeds this is outside the validity range.

    Returns
    -------
    dict of ndarray
        One value per period: 'index', 'start_stamp_ns', 'end_stamp_ns', 'samples',
        'estimated', '<point>_d<x|y>_p2p_um' [um] and their '_min_m' / '_max_m' [m],
        'criterion_max_<joint>' [rad/(s N)], 'criterion_angle_<joint>_rad' (crank angle in
        [0, 2 pi) where), '<quality>_max', 'invalid_s', 'clipped_speed_s' [s], 'outliers',
        'out_of_bound', 'repeated'.

    """
    stamps_ns = np.asarray(stamps_ns, dtype=np.int64)
    if not len(stamps_ns):
        return {}
    flags = estimate['flags']
    starts = np.flatnonzero(np.diff(ids, prepend=-1))
    ends = np.append(starts[1:], len(ids)) - 1
    columns = {'index': ids[starts], 'start_stamp_ns': stamps_ns[starts],
               'end_stamp_ns': stamps_ns[ends], 'samples': ends - starts + 1}
    finite = (np.all(np.isfinite(estimate['lever_tip']), axis=1)
              & np.all(np.isfinite(estimate['coupler_mid']), axis=1))
    columns['estimated'] = np.add.reduceat(finite.astype(np.int64), starts)
    deflections = np.hstack([estimate[key] for key in OUTPUT_POINTS])
    low, high = _group_extremes(np.where(finite[:, None], deflections, np.nan), starts)
    for k, name in enumerate(OUTPUT_NAMES):
        columns[f'{name}_min_m'], columns[f'{name}_max_m'] = low[:, k], high[:, k]
        columns[f'{name}_p2p_um'] = 1e6 * (high[:, k] - low[:, k])
    angle = np.mod(estimate['crank_angle'], TWO_PI)
    for k, joint in enumerate(JOINT_NAMES):
        values = np.where(finite, estimate['criterion'][:, k], np.nan)
        where = _group_argmax(values, ids, starts)
        columns[f'criterion_max_{joint}'] = np.where(where >= 0, values[where], np.nan)
        columns[f'criterion_angle_{joint}_rad'] = np.where(where >= 0, angle[where], np.nan)
    for name in QUALITY_NAMES:
        columns[f'{name}_max'] = _group_extremes(
            np.where(finite, estimate[name], np.nan), starts)[1]
    durations = sample_durations(stamps_ns, (flags & RESET) != 0)
    outside = finite & (np.nan_to_num(estimate['nonlinearity']) > validity_threshold)
    columns['invalid_s'] = np.add.reduceat(np.where(outside, durations, 0.0), starts)
    clipped = (flags & CLIPPED_SPEED) != 0
    columns['clipped_speed_s'] = np.add.reduceat(np.where(clipped, durations, 0.0), starts)
    for name, flag in (('outliers', OUTLIER), ('out_of_bound', OUT_OF_BOUND),
                       ('repeated', REPEATED)):
        columns[name] = np.add.reduceat(((flags & flag) != 0).astype(np.int64), starts)
    return columns


def recording_totals(columns):
    """
    Return the whole recording's peak-to-peak deflections and quality, from its periods.

    The numbers ``flexlink replay`` reports: 'lever_tip_peak_to_peak_um' and
    'coupler_mid_peak_to_peak_um' ([dx, dy] um, NaN without an estimated sample) and 'quality'
    ('messages', '<quality>_max' or None).

    Parameters
    ----------
    columns : dict of ndarray
        :func:`summarize_periods`'s result.

    Returns
    -------
    dict

    """
    totals = {}
    for point in OUTPUT_POINTS:
        spans = []
        for axis in ('dx', 'dy'):
            low = columns.get(f'{point}_{axis}_min_m', np.zeros(0))
            high = columns.get(f'{point}_{axis}_max_m', np.zeros(0))
            finite = np.isfinite(low)
            spans.append(1e6 * (float(np.max(high[finite])) - float(np.min(low[finite])))
                         if np.any(finite) else math.nan)
        totals[f'{point}_peak_to_peak_um'] = spans
    quality = {'messages': int(np.sum(columns.get('estimated', 0)))}
    for name in QUALITY_NAMES:
        values = columns.get(f'{name}_max', np.zeros(0))
        values = values[np.isfinite(values)]
        quality[f'{name}_max'] = float(values.max()) if values.size else None
    totals['quality'] = quality
    return totals
