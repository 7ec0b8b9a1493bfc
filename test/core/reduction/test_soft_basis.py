"""The soft basis: modes per node, their periodic alignment, FFT derivatives, the gap check."""

import math

from flexlink_ros.core.reduction import soft_basis
from flexlink_ros.errors import FlexlinkError
import numpy as np
import pytest

NODES = 64


def _rotation(angle, size, i, j):
    rotation = np.eye(size)
    c, s = math.cos(angle), math.sin(angle)
    rotation[[i, i, j, j], [i, j, i, j]] = c, -s, s, c
    return rotation


def _turning_family(spectrum, turns):
    """K(theta) = R diag(spectrum) R^T, R turning coordinate planes (0, 2) and (1, 3)."""
    thetas = 2 * math.pi * np.arange(NODES) / NODES
    size = len(spectrum)
    stiffness = np.empty((NODES, size, size))
    for k, theta in enumerate(thetas):
        rotation = (_rotation(turns * theta, size, 0, 2)
                    @ _rotation(0.3 * math.sin(theta), size, 1, 3))
        stiffness[k] = rotation @ np.diag(spectrum) @ rotation.T
    return thetas, np.broadcast_to(np.eye(size), stiffness.shape).copy(), stiffness


def test_aligned_frame_spans_the_lowest_modes_and_closes_smoothly():
    _, mass, stiffness = _turning_family([1.0, 2.0, 10.0, 11.0], turns=1)
    values, modes = soft_basis.lowest_modes(mass, stiffness, 2)
    np.testing.assert_allclose(values[:, :2], [[1.0, 2.0]] * NODES, rtol=1e-12)
    frame = soft_basis.align_modes(mass, modes)
    for k in range(NODES):
        projector = frame[k] @ frame[k].T
        np.testing.assert_allclose(projector, modes[k] @ modes[k].T, atol=1e-12)
        np.testing.assert_allclose(frame[k].T @ frame[k], np.eye(2), atol=1e-12)
    # smooth and periodic: every step between neighbours (the last to the first too) is small
    steps = np.linalg.norm(np.roll(frame, -1, axis=0) - frame, axis=(1, 2))
    assert steps.max() < 4.0 * 2 * math.pi / NODES
    assert steps.max() < 1.5 * np.median(steps)


def test_a_subspace_that_turns_over_is_refused():
    # the lowest mode turns by pi over a revolution: no periodic frame exists
    thetas = 2 * math.pi * np.arange(NODES) / NODES
    stiffness = np.array([_rotation(0.5 * t, 2, 0, 1) @ np.diag([1.0, 10.0])
                          @ _rotation(0.5 * t, 2, 0, 1).T for t in thetas])
    mass = np.broadcast_to(np.eye(2), stiffness.shape).copy()
    _, modes = soft_basis.lowest_modes(mass, stiffness, 1)
    with pytest.raises(FlexlinkError, match='turn over'):
        soft_basis.align_modes(mass, modes)


def test_fft_derivatives_of_a_trigonometric_polynomial():
    thetas = 2 * math.pi * np.arange(NODES) / NODES
    values = np.stack([np.sin(3 * thetas), np.cos(thetas) + 0.5 * np.sin(2 * thetas)], axis=1)
    first, second = soft_basis.angle_derivatives(values)
    np.testing.assert_allclose(first[:, 0], 3 * np.cos(3 * thetas), atol=1e-12)
    np.testing.assert_allclose(first[:, 1], -np.sin(thetas) + np.cos(2 * thetas), atol=1e-12)
    np.testing.assert_allclose(second[:, 0], -9 * np.sin(3 * thetas), atol=1e-11)
    np.testing.assert_allclose(second[:, 1], -np.cos(thetas) - 2 * np.sin(2 * thetas),
                               atol=1e-11)


def test_gap_choice_takes_the_smallest_usable_gap_and_refuses_others():
    # eigenvalue ratios 1.5, 13.3, 1.1: frequency ratios 1.22, 3.65 (usable), 1.05
    _, mass, stiffness = _turning_family([1.0, 1.5, 20.0, 22.0], turns=1)
    ratios = soft_basis.gap_ratios(mass, {'1': stiffness}, 10.0, 100.0)
    np.testing.assert_allclose(ratios, [1.5, 20.0 / 1.5, 1.1], rtol=1e-10)
    assert soft_basis.choose_soft_size(ratios) == 2
    assert soft_basis.choose_soft_size(ratios, requested=2) == 2
    with pytest.raises(FlexlinkError, match='after mode 1'):
        soft_basis.choose_soft_size(ratios, requested=1)
    with pytest.raises(FlexlinkError, match='no spectral gap'):
        soft_basis.choose_soft_size(np.array([1.5, 1.2, 1.1]))


def test_the_gap_is_checked_where_speed_and_acceleration_soften_the_stiffness():
    _, mass, stiffness = _turning_family([1.0, 1.5, 10.0, 11.0], turns=0)
    # the speed term softens mode 3 toward mode 2: the gap closes at speed_max only
    softening = np.broadcast_to(-np.diag([0.0, 0.0, 8.0, 8.0]) / 100.0, stiffness.shape)
    pieces = {'1': stiffness, 'w2': softening}
    at_rest = soft_basis.gap_ratios(mass, pieces, 1e-9, 0.0)
    fast = soft_basis.gap_ratios(mass, pieces, 10.0, 0.0)
    assert at_rest[1] == pytest.approx(10.0 / 1.5)
    assert fast[1] == pytest.approx(2.0 / 1.5)


def test_soft_basis_text_says_how_the_model_is_stepped():
    class Model:
        step_size = 16
        info = {'soft': {'used': True, 'size': 16, 'gap_ratio': 3.0778}}

    assert soft_basis.soft_basis_text(Model()) == 'stepped on 16 soft modes (gap 3.08x)'
    Model.info = {'soft': {'used': False, 'reason': 'off'}}
    assert soft_basis.soft_basis_text(Model()) == 'stepped in all of them (off)'
    Model.info = {}
    assert soft_basis.soft_basis_text(Model()) == 'stepped in all of them'
