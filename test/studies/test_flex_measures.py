"""Measures of the flexible four-bar's response and shapes (studies/flex_measures.py)."""

import dataclasses

from flexlink_ros.core.fe.linkage import FlexibleLinkage
from flexlink_ros.core.fe.modes import solve_frozen_modes
from flexlink_ros.core.mechanism_file import load_mechanism
from flexlink_ros.core.options import ModelOptions
from flexlink_ros.studies import flex_measures
import numpy as np
import pytest


@pytest.fixture(scope='module')
def small_mechanism():
    return dataclasses.replace(load_mechanism('cho1992'), elements_per_link=2)


def test_harmonic_shares_and_signed_area():
    theta = 2.0 * np.pi * np.arange(64) / 64
    shares = flex_measures.harmonic_shares(0.7 + np.cos(theta) + 0.5 * np.sin(3.0 * theta))
    assert shares[1] == pytest.approx(0.8) and shares[3] == pytest.approx(0.2)
    assert shares.sum() == pytest.approx(1.0)
    x, y = np.cos(theta), np.sin(theta)
    assert flex_measures.signed_area(x, y) == pytest.approx(np.pi, rel=1e-2)
    assert flex_measures.signed_area(x[::-1], y[::-1]) == pytest.approx(-np.pi, rel=1e-2)


def test_pinned_coupler_mode_bends_like_a_simply_supported_beam(small_mechanism):
    model = FlexibleLinkage(small_mechanism, ModelOptions.full_model(rigid_crank=True,
                                                                     geometric_stiffness=False))
    theta = np.radians([40.0])
    frozen = solve_frozen_modes(model.assemble(theta), 2)
    coupler_mode = frozen.dominant_link[0].tolist().index(1)
    s, bending = flex_measures.bending_deflection(model, frozen.shapes[0][:, coupler_mode][None],
                                                  theta, 1)
    assert abs(bending[0, 0]) < 1e-12 and abs(bending[0, -1]) < 1e-12
    correlation = flex_measures.shape_correlation(bending, flex_measures.uniform_load_shape(s))[0]
    assert abs(correlation) > 0.99
    assert flex_measures.uniform_load_shape(0.5) == pytest.approx(1.0)
