"""The fleet table's periods and their numbers, on estimates with known answers."""

import math

from flexlink_ros.core.estimation.sample import CLIPPED_SPEED, OUTLIER, RESET
from flexlink_ros.core.estimation.summary import period_ids, recording_totals, \
    sample_durations, summarize_periods
import numpy as np
import pytest

MS = 1_000_000
T0 = 1_700_000_000_000_000_000


def wrapped(angles):
    return np.mod(angles + math.pi, 2 * math.pi) - math.pi


def synthetic_estimate(count, rng):
    """Return an estimate's arrays: random deflections and criteria, all estimated."""
    return {'lever_tip': rng.normal(size=(count, 2)) * 1e-5,
            'coupler_mid': rng.normal(size=(count, 2)) * 1e-5,
            'criterion': rng.uniform(0.0, 100.0, size=(count, 4)),
            'crank_angle': np.zeros(count), 'nonlinearity': np.zeros(count),
            'error_indicator': rng.uniform(0.0, 1e-3, count),
            'flags': np.zeros(count, dtype=np.int64)}


def test_revolutions_start_where_the_angle_passes_a_whole_turn():
    stamps = T0 + np.arange(1000) * MS
    angles = 0.3 + 0.02 * np.arange(1000)           # 20 rad/s from 0.3 rad
    flags = np.zeros(1000, dtype=np.int64)
    flags[0] = RESET
    ids = period_ids(stamps, wrapped(angles), np.ones(1000, bool), flags)
    expected = np.floor(angles / (2 * math.pi)).astype(int)
    assert ids.tolist() == expected.tolist()
    # Backwards, with encoder jitter at each turn: still one period per turn.
    jitter = 1e-3 * np.where(np.arange(1000) % 2, 1.0, -1.0)
    backward = -angles + jitter
    ids = period_ids(stamps, wrapped(backward), np.ones(1000, bool), flags)
    turns = np.minimum.accumulate(np.floor(backward / (2 * math.pi)).astype(int))
    assert ids.tolist() == (turns[0] - turns).tolist()
    assert np.all(np.diff(ids) >= 0) and ids[-1] == turns[0] - turns[-1]


def test_a_new_segment_and_samples_without_an_estimate():
    stamps = T0 + np.arange(300) * MS
    angles = 0.01 * np.arange(300)                  # within one turn
    flags = np.zeros(300, dtype=np.int64)
    flags[[0, 200]] = RESET                         # the estimate restarted at 200
    estimated = np.ones(300, bool)
    estimated[[0, 1, 150]] = False                  # outliers: their angle is not trusted
    angles[150] = 100.0
    ids = period_ids(stamps, angles, estimated, flags)
    assert ids[:200].tolist() == [0] * 200 and ids[200:].tolist() == [1] * 100


def test_minutes_count_from_the_first_stamp():
    stamps = T0 + np.arange(0, 150_000, 500) * MS    # 150 s at 2 Hz
    flags = np.zeros(stamps.size, dtype=np.int64)
    ids = period_ids(stamps, np.zeros(stamps.size), np.ones(stamps.size, bool), flags,
                     per='minute')
    assert ids.tolist() == ((stamps - T0) // (60_000 * MS)).tolist()
    with pytest.raises(ValueError, match='per must be one of'):
        period_ids(stamps, stamps, stamps, flags, per='hour')


def test_durations_stop_at_a_segment_end():
    stamps = T0 + np.array([0, 1, 2, 3, 900, 901, 903]) * MS
    starts = np.array([1, 0, 0, 0, 1, 0, 0], bool)
    assert sample_durations(stamps, starts) == pytest.approx(
        [1e-3, 1e-3, 1e-3, 1e-3, 1e-3, 2e-3, 1e-3])


def test_each_period_its_extremes_worst_criterion_and_time_outside():
    rng = np.random.default_rng(5)
    count = 400
    estimate = synthetic_estimate(count, rng)
    estimate['crank_angle'] = np.linspace(0.0, 12.0, count)
    estimate['nonlinearity'][50:60] = 0.8          # 10 samples of 1 ms above 0.5
    estimate['flags'][0] = RESET
    estimate['flags'][70:75] |= CLIPPED_SPEED
    for key in ('lever_tip', 'coupler_mid', 'criterion', 'nonlinearity', 'error_indicator',
                'crank_angle'):
        estimate[key][300] = math.nan               # an outlier: no estimate
    estimate['flags'][300] = OUTLIER
    estimate['criterion'][120, 3] = 1e4            # the worst of the first period at O4
    stamps = T0 + np.arange(count) * MS
    ids = np.repeat([0, 1, 2, 3], 100)
    columns = summarize_periods(stamps, estimate, ids)
    assert columns['index'].tolist() == [0, 1, 2, 3]
    assert columns['samples'].tolist() == [100] * 4
    assert columns['estimated'].tolist() == [100, 100, 100, 99]
    assert columns['start_stamp_ns'].tolist() == stamps[::100].tolist()
    assert columns['end_stamp_ns'].tolist() == stamps[99::100].tolist()
    for k in range(4):
        rows = slice(100 * k, 100 * k + 100)
        values = estimate['lever_tip'][rows, 1]
        assert columns['lever_tip_dy_p2p_um'][k] == pytest.approx(
            1e6 * (np.nanmax(values) - np.nanmin(values)))
    assert columns['criterion_max_O4'][1] == 1e4
    assert columns['criterion_angle_O4_rad'][1] == pytest.approx(
        math.fmod(estimate['crank_angle'][120], 2 * math.pi))
    assert columns['invalid_s'].tolist() == pytest.approx([10e-3, 0.0, 0.0, 0.0])
    assert columns['clipped_speed_s'].tolist() == pytest.approx([5e-3, 0.0, 0.0, 0.0])
    assert columns['outliers'].tolist() == [0, 0, 0, 1]
    totals = recording_totals(columns)
    finite = np.isfinite(estimate['coupler_mid'][:, 0])
    for axis in range(2):
        values = estimate['coupler_mid'][finite, axis]
        assert totals['coupler_mid_peak_to_peak_um'][axis] == pytest.approx(
            1e6 * (values.max() - values.min()))
    assert totals['quality'] == {
        'messages': 399, 'nonlinearity_max': 0.8,
        'error_indicator_max': float(np.nanmax(estimate['error_indicator']))}


def test_a_period_without_estimates_has_no_numbers():
    rng = np.random.default_rng(2)
    estimate = synthetic_estimate(20, rng)
    for key in ('lever_tip', 'coupler_mid'):
        estimate[key][10:] = math.nan
    columns = summarize_periods(T0 + np.arange(20) * MS, estimate, np.repeat([0, 1], 10))
    assert columns['estimated'].tolist() == [10, 0]
    assert math.isnan(columns['coupler_mid_dx_p2p_um'][1])
    assert math.isnan(columns['criterion_max_A'][1])
    assert math.isnan(columns['criterion_angle_A_rad'][1])
    assert summarize_periods(np.zeros(0, dtype=np.int64), estimate, np.zeros(0, int)) == {}
    empty = recording_totals({})
    assert all(math.isnan(v) for v in empty['lever_tip_peak_to_peak_um'])
    assert empty['quality'] == {'messages': 0, 'error_indicator_max': None,
                                'nonlinearity_max': None}
