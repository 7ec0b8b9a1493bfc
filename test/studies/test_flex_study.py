"""Studies of the flexible four-bar (studies/flex_*.py): mode events, truncation, measures."""

import dataclasses

from flexlink_ros.core.fe.linkage import FlexibleLinkage
from flexlink_ros.core.fe.modes import solve_frozen_modes
from flexlink_ros.core.fe.simulate import periodic_response
from flexlink_ros.core.mechanism_file import load_mechanism
from flexlink_ros.core.numerics import relative_rms, RPM
from flexlink_ros.core.options import ModelOptions
from flexlink_ros.studies import flex_events, flex_frequencies, flex_measures, flex_truncation
import numpy as np
import pytest
import scipy.linalg


def _family(matrices):
    """Frequencies (sqrt of eigenvalues) and shapes of a family of symmetric matrices."""
    values, shapes = np.linalg.eigh(np.asarray(matrices))
    return np.sqrt(values), shapes


@pytest.fixture(scope='module')
def small_mechanism():
    return dataclasses.replace(load_mechanism('cho1992'), elements_per_link=2)


def test_mac_is_one_for_scaled_shapes_and_zero_for_mass_orthogonal_ones():
    rng = np.random.default_rng(3)
    root = rng.normal(size=(5, 5))
    mass = root @ root.T + 5.0 * np.eye(5)
    # eigenvectors of the generalized problem are M-orthogonal
    _, shapes = scipy.linalg.eigh(np.diag(np.arange(1.0, 6.0)), mass)
    matrix = flex_events.mac(shapes, -3.0 * shapes, mass)
    assert np.allclose(matrix, np.eye(5), atol=1e-12)
    # weighting matters
    assert not np.allclose(flex_events.mac(shapes, shapes), np.eye(5), atol=1e-3)


def test_avoided_crossing_of_a_2x2_family_is_a_veering_at_the_smallest_gap():
    coupling = 0.05
    t = np.linspace(-1.0, 1.0, 41)
    freqs, shapes = _family([[[3.0 + x, coupling], [coupling, 3.0 - x]] for x in t])
    events = flex_events.detect_mode_events(t, freqs, shapes)
    assert len(events) == 1
    event = events[0]
    assert event.kind == 'veering' and event.modes == (0, 1)
    assert event.parameter == pytest.approx(0.0, abs=1e-12)
    # eigenvalue gap 2 c at t = 0; frequencies are their square roots
    assert event.gap == pytest.approx(np.sqrt(3.05) - np.sqrt(2.95), rel=1e-9)
    assert event.exchange > 0.8


def test_well_separated_family_with_a_gap_minimum_has_no_event():
    t = np.linspace(-1.0, 1.0, 41)
    freqs, shapes = _family([[[1.0, 0.3], [0.3, 4.0 + x * x]] for x in t])
    gap = freqs[:, 1] - freqs[:, 0]
    assert gap.argmin() == 20            # a local minimum exists, without shape exchange
    assert flex_events.detect_mode_events(t, freqs, shapes) == []


def test_exact_crossing_between_samples_is_a_swap():
    t = np.linspace(-1.0, 1.0, 40)       # zero lies between samples 19 and 20
    freqs, shapes = _family([[[2.0 + x, 0.0], [0.0, 2.0 - x]] for x in t])
    events = flex_events.detect_mode_events(t, freqs, shapes)
    assert [(e.kind, e.modes, e.index) for e in events] == [('swap', (0, 1), 19)]
    assert events[0].parameter == pytest.approx(0.0, abs=1e-12)


def test_periodic_sweep_finds_the_veering_across_the_wrap():
    angle = np.radians(np.arange(0.0, 360.0, 2.0))
    detune = np.sin(angle - np.radians(2.0))   # crosses zero at 2 and 182 degrees
    freqs, shapes = _family([[[3.0 + 0.5 * d, 0.02], [0.02, 3.0 - 0.5 * d]] for d in detune])
    events = flex_events.detect_mode_events(np.degrees(angle), freqs, shapes, periodic=True)
    assert sorted(round(e.parameter) for e in events) == [2, 182]
    assert {e.kind for e in events} == {'veering'}


def test_relative_rms_and_modes_needed():
    reference = np.column_stack([np.cos(np.linspace(0, 6, 50)), np.sin(np.linspace(0, 6, 50))])
    assert relative_rms(1.1 * reference, reference) == pytest.approx(0.1)
    counts = np.array([1, 2, 3, 4, 6])
    errors = np.array([0.5, 0.008, 0.02, 0.004, 1e-9])
    # N = 2 passes but 3 fails again
    assert flex_truncation.modes_needed(counts, errors, 0.01) == 4
    assert flex_truncation.modes_needed(counts, errors, 0.05) == 2
    assert flex_truncation.modes_needed(counts, errors, 1.0) == 1
    assert flex_truncation.modes_needed(counts, np.full(5, 0.5), 0.01) is None


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


def test_truncation_error_falls_with_modes_and_vanishes_with_all(small_mechanism):
    model = FlexibleLinkage(small_mechanism, ModelOptions.full_model(rigid_crank=True,
                                                                     geometric_stiffness=False))
    counts = [1, 2, 5, 9, model.size]
    study = flex_truncation.truncation_study(model, 391.0 * RPM, counts, steps=120, points=30)
    plain, static = study['plain'], study['static']
    assert np.all(np.diff(plain, axis=0) <= 1e-3 * plain[:-1])   # non-increasing in N
    assert np.all(plain[-1] < 1e-9) and np.all(static[-1] < 1e-9)
    assert np.all(static[0] < 0.1 * plain[0])   # the static correction pays at N = 1
    assert flex_truncation.modes_needed(study['modes'], static[:, 1], 0.01) == 1
    # the post-processed static correction is the one periodic_response applies
    run = periodic_response(model, 391.0 * RPM, 'modal', modes=2,
                            static_correction=True, steps=120, points=30)
    assert flex_truncation.output_errors(run.outputs, study['reference'].outputs) == pytest.approx(
        static[1], rel=1e-9)


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
