"""Mode events of a family of frozen modes (studies/flex_events.py): MAC, veerings, swaps."""

from flexlink_ros.studies import flex_events
import numpy as np
import pytest
import scipy.linalg


def _family(matrices):
    """Frequencies (sqrt of eigenvalues) and shapes of a family of symmetric matrices."""
    values, shapes = np.linalg.eigh(np.asarray(matrices))
    return np.sqrt(values), shapes


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
