"""Frozen-frequency sweeps of the flexible four-bar (studies/flex_frequencies.py)."""

import dataclasses

from flexlink_ros.core.fe.linkage import FlexibleLinkage
from flexlink_ros.core.mechanism_file import load_mechanism
from flexlink_ros.core.options import ModelOptions
from flexlink_ros.studies import flex_frequencies
import numpy as np
import pytest


@pytest.fixture(scope='module')
def small_mechanism():
    return dataclasses.replace(load_mechanism('cho1992'), elements_per_link=2)


def test_sweep_case_shapes_and_status(small_mechanism):
    # geometric stiffness is always built (the availability flag is gone), so the K_G cases
    # are always there
    system = FlexibleLinkage(small_mechanism,
                             ModelOptions.full_model(geometric_stiffness=True)).assemble(0.3)
    assert np.all(np.isfinite(system.geometric['w2']))
    cases = flex_frequencies.paper_frequency_cases()
    assert {'flex', 'rigid_crank', 'rigid_crank_bearings'} <= set(cases)
    assert any('_kg_' in key for key in cases)
    sweep = flex_frequencies.sweep_case(small_mechanism, cases['rigid_crank'],
                                        np.arange(0.0, 360.0, 30.0), 3)
    assert sweep.frequencies_hz.shape == (12, 3) and sweep.shapes.shape[2] == 3
    assert np.all(np.diff(sweep.frequencies_hz, axis=1) > 0)
    assert all(max(e.modes) < 3 for e in sweep.events)


def test_sharp_veering_between_samples_is_refined_to_a_small_nonzero_gap(small_mechanism):
    """Rigid crank with K_G at 45 rad/s: coupler and lever modes veer within a sample step."""
    system = FlexibleLinkage(small_mechanism,
                             ModelOptions.full_model(geometric_stiffness=True)).assemble(0.3)
    assert np.all(np.isfinite(system.geometric['w2']))
    case = flex_frequencies.paper_frequency_cases()['rigid_crank_kg_45']
    sweep = flex_frequencies.sweep_case(small_mechanism, case, np.arange(0.0, 360.0, 2.0), 3)
    assert sweep.events
    for event in sweep.events:
        assert event.modes == (0, 1)
        assert 0.0 < event.refined_gap <= event.gap
        offset = (event.refined_parameter - event.parameter + 180.0) % 360.0 - 180.0
        assert abs(offset) <= 3.0      # within a sample step of the detected event
    swaps = [e for e in sweep.events if e.kind == 'swap']
    assert swaps and all(e.refined_gap < 0.1 * e.gap for e in swaps)
