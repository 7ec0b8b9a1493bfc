"""
The linear model's validity over its speed range (core/estimation/validity_scan.py).

The ramp's verdict per speed band is checked against the steady state at constant speed (the
estimator warm-started at the periodic state, one revolution) at speeds where the two must
agree: well below the paper's resonance band (valid) and inside it (not valid). A model whose
speed range ends below the band is valid over all of it.
"""

import math

from flexlink_ros.core.estimation.offline import estimate_offline
from flexlink_ros.core.estimation.validity_scan import (crank_ramp, ranges_text,
                                                        validity_over_speeds)
from flexlink_ros.core.mechanism_file import load_mechanism
from flexlink_ros.core.options import ModelOptions
from flexlink_ros.core.reduction import mechanism_model
from flexlink_ros.core.validity import VALIDITY_THRESHOLD
import numpy as np
import pytest


def _model(speed_max):
    options = ModelOptions.linear(bearings='flexible', rigid_crank=True, elements_per_link=4,
                                  grid_size=64, speed_max=speed_max)
    return mechanism_model.model_for_mechanism(load_mechanism('cho1992'), options)


@pytest.fixture(scope='module')
def model():
    return _model(45.0)      # 430 rpm: through the paper's resonance band


def _steady_indicator(model, rpm, steps=360):
    """Largest validity indicator over one revolution of the periodic state at ``rpm``."""
    speed = rpm / 30.0 * math.pi
    time_s = np.arange(steps + 1) * (2.0 * math.pi / speed / steps)
    estimate = estimate_offline(model, np.round(time_s * 1e9).astype(np.int64),
                                np.mod(speed * time_s, 2.0 * math.pi), np.full(steps + 1, speed))
    return float(np.nanmax(estimate['nonlinearity']))


def test_the_ramp_runs_from_rest_to_the_largest_speed_at_constant_acceleration():
    stamps, angles, speeds = crank_ramp(40.0, seconds=2.0, rate_hz=100.0)
    assert stamps[0] == 0 and stamps[-1] == 2_000_000_000 and speeds[-1] == 40.0
    assert np.allclose(np.diff(speeds), 0.2)     # 20 rad/s^2 over 0.01 s
    unwrapped = np.unwrap(angles)
    assert unwrapped[-1] == pytest.approx(40.0)      # 1/2 a t^2 with a = 20 rad/s^2


def test_the_ramps_verdict_agrees_with_the_steady_state(model):
    scan = validity_over_speeds(model)
    assert scan['bands_rpm'][0] == (0.0, 10.0)
    assert scan['bands_rpm'][-1][1] == pytest.approx(45.0 * 30.0 / math.pi)
    assert scan['valid'] is False and scan['largest'] > VALIDITY_THRESHOLD
    for rpm, valid in ((150.0, True), (269.0, True), (405.0, False)):
        steady = _steady_indicator(model, rpm)
        band = next(i for i, (low, high) in enumerate(scan['bands_rpm']) if low <= rpm < high)
        ramp = scan['indicator_max'][band]
        assert (steady < VALIDITY_THRESHOLD) is valid, (rpm, steady)
        assert (ramp < VALIDITY_THRESHOLD) is valid, (rpm, ramp, steady)
        inside = any(low <= rpm < high for low, high in scan['not_valid_rpm'])
        assert inside is not valid
    assert ranges_text([(230.0, 250.0), (260.0, 430.0)]) == '230-250, 260-430 rpm'


def test_a_speed_range_below_the_resonances_is_valid_throughout():
    scan = validity_over_speeds(_model(15.0))      # 143 rpm
    assert scan['valid'] is True and scan['not_valid_rpm'] == []
    assert 0.0 < scan['largest'] < VALIDITY_THRESHOLD
