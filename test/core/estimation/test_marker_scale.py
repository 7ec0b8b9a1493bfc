"""marker_scale: the markers' default exaggeration shows the expected peak deflection."""

import pathlib

from flexlink_ros.core.estimation import tables as step_tables_module
from flexlink_ros.core.estimation.marker_scale import (default_exaggeration,
                                                       load_quasi_static_peaks, machine_speed,
                                                       MARKER_SHARE, MAX_EXAGGERATION,
                                                       PEAKS_CACHE_NAME, round_exaggeration)
from flexlink_ros.core.estimation.streaming import StreamingEstimator
from flexlink_ros.core.estimation.tables import step_tables
from flexlink_ros.core.fe.linkage import FlexibleLinkage
from flexlink_ros.core.fe.simulate import periodic_response
from flexlink_ros.core.mechanism_file import load_mechanism
from flexlink_ros.core.options import SPEED_MARGIN
from flexlink_ros.core.reduction.mechanism_model import model_for_mechanism
from flexlink_ros.ros.parameters import default_model_options
import numpy as np
import pytest

SOFT = str(pathlib.Path(__file__).resolve().parents[2] / 'data' / 'soft_linkage.yaml')


@pytest.mark.parametrize('peak, length, expected', [
    (30e-6, 0.25, 500.0),      # a steel linkage's 30 um: 0.05 * 0.25 / 30e-6 = 417 -> 500
    (11.2e-3, 0.262, 2.0),     # Cho 1992 at 620 rpm: 1.17 -> 2
    (0.05, 0.2, 1.0),          # already larger than 5 %: drawn as it is
    (1e-3, 0.2, 10.0),         # exactly 10: not 20
    (0.0, 0.2, MAX_EXAGGERATION), (float('nan'), 0.2, MAX_EXAGGERATION),
    (1e-15, 0.2, MAX_EXAGGERATION),
])
def test_the_smallest_round_factor_showing_the_peak_as_5_percent(peak, length, expected):
    assert round_exaggeration(peak, length) == expected
    if 1.0 < expected < MAX_EXAGGERATION:
        assert expected * peak >= MARKER_SHARE * length * (1 - 1e-9)
        assert expected * peak < 2.5 * MARKER_SHARE * length     # the next step down is short


def test_a_soft_linkage_gets_a_larger_factor_than_cho1992(tmp_path):
    """The expected peak from the model: drawn as 5-12.5 % of the coupler in both."""
    found = {}
    for name in ('cho1992', SOFT):
        options = default_model_options(grid_size=32)
        model = model_for_mechanism(load_mechanism(name), options, cache_dir=tmp_path)
        factor, peak, length = default_exaggeration(StreamingEstimator(model))
        assert MARKER_SHARE <= factor * peak / length < 2.5 * MARKER_SHARE
        found[name] = factor
    assert found[SOFT] > found['cho1992'] > 1.0


SLOW = str(pathlib.Path(__file__).resolve().parents[2] / 'data' / 'slow_heavy_steel.yaml')


def test_a_slow_machine_is_drawn_at_its_own_speed_not_at_the_range_floor(tmp_path):
    """
    A 60 rpm linkage: its model serves 0-620 rpm (the range's floor), 100 times its bending.

    The factor must show the deflection of the machine's own speed (the full-order response
    at 60 rpm) as about 5 % of the coupler, not the quasi-static peak at 620 rpm.
    """
    mechanism = load_mechanism(SLOW)
    options = default_model_options(grid_size=32)
    assert options.speed_max > 5.0 * SPEED_MARGIN * mechanism.crank_speed
    model = model_for_mechanism(mechanism, options, cache_dir=tmp_path)
    factor, peak, length = default_exaggeration(StreamingEstimator(model), mechanism)
    response = periodic_response(FlexibleLinkage(mechanism, options), mechanism.crank_speed,
                                 points=60, steps=360)
    drawn = factor * float(np.max(np.abs(response.outputs))) / length
    assert MARKER_SHARE / SPEED_MARGIN ** 2 <= drawn < 2.5 * MARKER_SHARE, (factor, peak)


def test_the_peaks_are_computed_once_and_then_read_from_beside_the_model(tmp_path, monkeypatch):
    mechanism = load_mechanism(SOFT)
    options = default_model_options(grid_size=32)
    model = model_for_mechanism(mechanism, options, cache_dir=tmp_path)
    computed = []
    compute = step_tables_module.quasi_static_peak

    def counted(*args):
        computed.append(args[-1])
        return compute(*args)

    monkeypatch.setattr(step_tables_module, 'quasi_static_peak', counted)
    speeds = sorted({model.speed_max, machine_speed(mechanism, model.speed_max)})
    first = step_tables(model)
    load_quasi_static_peaks(model, first, mechanism, options, tmp_path, True)
    assert computed == speeds and len(list(tmp_path.glob(f'*-{PEAKS_CACHE_NAME}.npz'))) == 1
    again = step_tables(model)
    load_quasi_static_peaks(model, again, mechanism, options, tmp_path, True)
    values = [again.quasi_static_peak(model, top) for top in speeds]
    assert computed == speeds      # nothing computed the second time
    assert values == [first.quasi_static_peak(model, top) for top in speeds]
    assert again.deflection_bound(model, 3.0) == first.deflection_bound(model, 3.0)
    # Without the cache: computed every time.
    load_quasi_static_peaks(model, step_tables(model), mechanism, options, tmp_path, False)
    assert computed == speeds * 2
