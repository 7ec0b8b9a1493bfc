"""The estimator's per-sample result (core/estimation/sample.py): flags, records, NaN samples."""

import dataclasses
import math

from flexlink_ros.core.estimation import sample
from flexlink_ros.core.estimation.sample import error_indicator_rows, nan_sample, \
    sample_from_record, SampleFlag
import numpy as np
import pytest

CRITERIA = ((10.0, 20.0, 30.0, 40.0), (0.1, 0.2, 0.3, 0.4), (0.01, 0.01, 0.01, 0.01),
            (False, True, False, False))


def test_flags_are_distinct_bits_and_the_int_copies_match():
    values = [int(flag) for flag in SampleFlag if flag is not SampleFlag.NONE]
    assert all(v > 0 and v & (v - 1) == 0 for v in values)      # powers of two
    assert len(set(values)) == len(values)
    for flag in SampleFlag:
        if flag is not SampleFlag.NONE:
            assert getattr(sample, flag.name) == int(flag)
    combined = sample.RESET | sample.OUT_OF_BOUND
    assert combined & SampleFlag.RESET and combined & SampleFlag.OUT_OF_BOUND
    assert not combined & SampleFlag.WARM_START


def test_sample_from_record_splits_the_deflections_and_sizes_the_correction():
    deflection = [3e-4, -4e-4, 0.0, 1e-4]
    correction = [3e-5, 4e-5, 0.0, 0.0]           # |c| = 5e-5
    out = sample_from_record(12345.0, (1.0, 2.0, 3.0), deflection, correction, CRITERIA,
                             sample.RESET, 'reset', (0.5, -0.5))
    assert out.stamp_ns == 12345 and isinstance(out.stamp_ns, int)
    assert (out.crank_angle, out.crank_speed, out.crank_accel) == (1.0, 2.0, 3.0)
    assert out.lever_tip == (3e-4, -4e-4) and out.coupler_mid == (0.0, 1e-4)
    assert out.reaction_n == CRITERIA[0] and out.near_zero == CRITERIA[3]
    # |c| / |d| = 5e-5 / sqrt(26e-8)
    assert out.error_indicator == pytest.approx(5e-5 / math.sqrt(26e-8))
    assert out.flags == SampleFlag.RESET and out.message == 'reset'
    assert out.modal == (0.5, -0.5)


def test_error_indicator_is_relative_to_a_floor_for_tiny_deflections():
    out = sample_from_record(0, (0.0, 0.0, 0.0), [1e-9, 0.0, 0.0, 0.0], [2e-7, 0.0, 0.0, 0.0],
                             CRITERIA, 0, '', ())
    assert out.error_indicator == pytest.approx(2e-7 / sample.ERROR_INDICATOR_FLOOR_M)


def test_nan_sample_has_no_number_to_publish():
    out = nan_sample(7, (0.5, 30.0, 0.0), sample.OUT_OF_BOUND | sample.RESET, 'out of bound', 3)
    assert out.stamp_ns == 7 and out.crank_speed == 30.0
    for field in ('lever_tip', 'coupler_mid', 'reaction_n', 'gamma_dot', 'criterion', 'modal'):
        values = getattr(out, field)
        assert values and all(math.isnan(v) for v in values), field
    assert len(out.lever_tip) == 2 and len(out.criterion) == 4 and len(out.modal) == 3
    assert out.near_zero == (False,) * 4 and math.isnan(out.error_indicator)
    assert out.flags & SampleFlag.OUT_OF_BOUND and out.message == 'out of bound'


def test_samples_have_fixed_fields():
    out = nan_sample(0, (0.0, 0.0, 0.0), 0, '', 1)
    assert [f.name for f in dataclasses.fields(out)][:4] == [
        'stamp_ns', 'crank_angle', 'crank_speed', 'crank_accel']
    with pytest.raises(AttributeError):
        out.extra = 1          # slots: no stray attributes


def test_error_indicator_rows_are_the_samples_indicators_to_the_last_bit():
    rng = np.random.default_rng(7)
    deflection = rng.normal(size=(50, 4)) * np.logspace(-8, -3, 50)[:, None]   # floor too
    correction = rng.normal(size=(50, 4)) * 1e-6
    rows = error_indicator_rows(deflection[:, :2], deflection[:, 2:], correction)
    for row, d, c in zip(rows.tolist(), deflection.tolist(), correction.tolist()):
        crank, criteria = (0.0, 0.0, 0.0), ((0.0,) * 4,) * 3 + ((False,) * 4,)
        assert row == sample_from_record(0, crank, d, c, criteria, 0, '', (), math.nan
                                         ).error_indicator
