"""The soft basis against the full order: the study's pieces at reduced size, and veering."""

import dataclasses

from flexlink_ros.core.mechanism_file import load_mechanism
from flexlink_ros.core.reduction import pipeline
from flexlink_ros.studies import soft_basis_study as study
import numpy as np
import pytest

RPM_391 = 391.0 * 2.0 * np.pi / 60.0


@pytest.fixture(scope='module')
def veering():
    """The flexible crank on rigid bearings (8 + 4, grid 64): soft (p = 7) and all 12."""
    mechanism = load_mechanism('cho1992')
    soft = pipeline.model_for_mechanism(mechanism, study.veering_options())
    return mechanism, soft, pipeline.with_soft_basis(dataclasses.replace(soft, soft=None), 0)


def test_the_two_lowest_modes_swap_order_twice_a_revolution_inside_the_soft_subspace(veering):
    _, soft, _ = veering
    assert (soft.step_size, soft.size) == (7, 12) and soft.info['soft']['gap_ratio'] > 6.0
    order = study.mode_order(soft, RPM_391, soft.step_size)
    lowest = order[:, 0]
    # node 0's lowest mode becomes the second lowest and back: two swaps a revolution
    assert set(lowest) == {0, 1} and np.count_nonzero(np.diff(lowest)) == 2
    assert np.array_equal(order[:, 1], 1 - lowest)      # the two trade places
    assert order.max() < soft.size and set(order[:, :2].ravel()) <= set(range(soft.step_size))
    # at rest they keep their order: the swap is the centrifugal stiffening's
    assert not np.any(study.mode_order(soft, 0.0, 2)[:, 0])


def test_the_soft_estimate_follows_the_full_order_through_the_veering(veering):
    mechanism, soft, full = veering
    options = study.veering_options()
    soft_error = study.steady_error(mechanism, soft, options, 391.0, steps=720)
    full_error = study.steady_error(mechanism, full, options, 391.0, steps=720)
    # measured (1440 reference steps): soft 0.20 / 0.91 %, all 12 coordinates 1.04 / 3.88 %
    assert soft_error['coupler_mid'] < 0.004 and soft_error['lever_tip'] < 0.012
    for key in study.OUTPUTS:
        assert soft_error[key] < full_error[key]


def test_ramp_signal_is_exact_and_holds_a_revolution_first():
    stamps, angles, speeds, ramp_start = study.ramp_signal(100.0, 600.0, 0.5, 1000.0)
    low, high = 100.0 * np.pi / 30.0, 600.0 * np.pi / 30.0
    assert ramp_start == pytest.approx(2.0 * np.pi / low)
    assert np.all(np.diff(stamps) == 1_000_000)
    assert speeds[0] == pytest.approx(low) and speeds[-1] == pytest.approx(high)
    # the angle is the integral of the speed (trapezoid exact for piecewise-linear speed)
    t = stamps * 1e-9
    integral = np.concatenate([[0.0], np.cumsum(0.5 * (speeds[1:] + speeds[:-1]) * np.diff(t))])
    assert np.allclose(angles, integral, atol=1e-9)
