"""Frozen eigen-analysis of the flexible four-bar (Cho 1992, Sec. 4.1-4.2)."""

import dataclasses
import pathlib

from flexlink_ros.core.fe import linkage
from flexlink_ros.core.fe.linkage import FlexibleLinkage
from flexlink_ros.core.fe.modes import frozen_mode_sweep, modal_damping, solve_frozen_modes
from flexlink_ros.core.mechanism_file import load_mechanism
from flexlink_ros.core.options import ModelOptions
import numpy as np
import pytest

CONFIG = pathlib.Path(__file__).resolve().parents[3] / 'config'
NO_KG = {'geometric_stiffness': False}


@pytest.fixture(scope='module')
def cho():
    return load_mechanism(CONFIG / 'cho1992.yaml')


def _pinned_frequency_hz(mech, link):
    spec = mech.links[link]
    return (np.pi / spec.length) ** 2 * np.sqrt(
        mech.youngs_modulus * spec.second_moment / (mech.density * spec.area)) / (2 * np.pi)


def test_modes_are_mass_normalised_and_damping_is_modal(cho):
    model = FlexibleLinkage(cho, ModelOptions.full_model(bearings='flexible', **NO_KG))
    system = model.assemble(np.radians([27.0, 123.0]))
    modes = solve_frozen_modes(system)
    eye = np.broadcast_to(np.eye(model.size), system.mass.shape)
    phi = modes.shapes
    np.testing.assert_allclose(np.swapaxes(phi, 1, 2) @ system.mass @ phi, eye, atol=1e-9)
    np.testing.assert_allclose(np.swapaxes(phi, 1, 2) @ system.stiffness @ phi,
                               eye * modes.eigenvalues[:, None, :],
                               atol=1e-9 * modes.eigenvalues.max())
    damping = modal_damping(system.mass, modes.eigenvalues, phi, 0.05)
    np.testing.assert_allclose(np.swapaxes(phi, 1, 2) @ damping @ phi,
                               eye * (0.1 * modes.omega[:, None, :]),
                               atol=1e-9 * modes.omega.max())
    np.testing.assert_allclose(modes.kinetic_share.sum(-1), 1.0)
    np.testing.assert_allclose(modes.strain_share.sum(-1), 1.0)


def test_rigid_crank_modes_are_pinned_coupler_and_lever(cho):
    """
    Rigid crank, exact pins: the lowest modes are pinned-pinned link modes.

    Rigid crank, exact pins: the lowest modes are the coupler's and the lever's first
    pinned-pinned bending modes (B hardly moves), the paper's 'near 34 Hz and 41 Hz'.
    """
    model = FlexibleLinkage(cho, ModelOptions.full_model(rigid_crank=True, **NO_KG))
    modes = frozen_mode_sweep(model, np.radians(np.arange(0.0, 360.0, 30.0)), count=2)
    np.testing.assert_allclose(modes.frequencies_hz[:, 0], _pinned_frequency_hz(cho, 1),
                               rtol=1e-3)
    np.testing.assert_allclose(modes.frequencies_hz[:, 1], _pinned_frequency_hz(cho, 2),
                               rtol=1e-3)
    assert np.all(modes.dominant_link == [1, 2])
    assert 33.0 < modes.frequencies_hz[:, 0].min() and modes.frequencies_hz[:, 1].max() < 42.0


def test_crank_mode_varies_over_the_cycle(cho):
    """Fig. 7: modes 1-2 nearly constant, mode 3 (crank) varies strongly; no K_G, no speed."""
    model = FlexibleLinkage(cho, ModelOptions.full_model(**NO_KG))
    modes = frozen_mode_sweep(model, np.radians(np.arange(0.0, 360.0, 10.0)), count=3)
    f = modes.frequencies_hz
    spread = (f.max(0) - f.min(0)) / f.mean(0)
    assert spread[0] < 0.05 and spread[1] < 0.05 and spread[2] > 0.3
    assert np.mean(modes.dominant_link[:, 2] == 0) > 0.75   # crank bending at most angles


def test_frequencies_without_geometric_stiffness_do_not_depend_on_speed(cho):
    model = FlexibleLinkage(cho, ModelOptions.full_model(**NO_KG))
    system = model.assemble(np.radians([27.0, 200.0]))
    still = solve_frozen_modes(system, 3)
    fast = solve_frozen_modes(system, 3, speed=45.0, accel=100.0)
    np.testing.assert_array_equal(still.eigenvalues, fast.eigenvalues)
    # the optional centrifugal term softens (the -w_L^2 M part dominates)
    soft = solve_frozen_modes(system, 3, speed=45.0, centrifugal=True)
    assert np.all(soft.eigenvalues[:, :2] < still.eigenvalues[:, :2])


def test_flexible_bearings_lower_frequencies(cho):
    theta = np.radians(np.arange(0.0, 360.0, 45.0))
    pins = frozen_mode_sweep(FlexibleLinkage(cho, ModelOptions.full_model(**NO_KG)), theta, 3)
    springs = frozen_mode_sweep(
        FlexibleLinkage(cho, ModelOptions.full_model(bearings='flexible', **NO_KG)), theta, 3)
    assert np.all(springs.eigenvalues < pins.eigenvalues)


def test_count_is_checked(cho):
    system = FlexibleLinkage(cho, ModelOptions.full_model(**NO_KG)).assemble(0.0)
    with pytest.raises(ValueError, match='count'):
        solve_frozen_modes(system, 0)
    with pytest.raises(ValueError, match='count'):
        solve_frozen_modes(system, system.size + 1)


def test_more_elements_converge(cho):
    """Frequencies of the frozen linkage converge with elements per link (cubic elements)."""
    theta = np.radians([60.0])
    freqs = []
    for elements in (2, 4, 8, 16):
        mech = dataclasses.replace(cho, elements_per_link=elements)
        model = FlexibleLinkage(mech, ModelOptions.full_model(**NO_KG))
        freqs.append(frozen_mode_sweep(model, theta, 3).frequencies_hz[0])
    freqs = np.array(freqs)
    errors = np.abs(freqs[:-1] - freqs[-1])
    assert np.all(errors[1] < errors[0]) and np.all(errors[2] < errors[1])
    assert np.all(errors[-1] / freqs[-1] < 1e-4)


def test_geometric_stiffness_pieces_with_constant_tension(cho, monkeypatch):
    """
    K_G assembly with a stand-in axial force: constant tension P on the coupler only.

    A pinned-pinned beam under tension P has w^2 = w0^2 (1 + P L^2 / (pi^2 EI)) exactly; the
    pieces (gravity, a, w^2) must combine linearly as P = P1 + a Pa + w^2 Pw2.
    """
    pieces = {'1': 4.0, 'a': 0.01, 'w2': 0.002}

    def axial_force(mechanism, state, link, x):
        gravity = pieces['1'] if mechanism.gravity != (0.0, 0.0) else 0.0
        value = gravity + pieces['a'] * state.alpha[0] + pieces['w2'] * state.omega[0] ** 2
        return np.outer(value, np.ones(len(x))) * (link == 1)

    monkeypatch.setattr(linkage, 'axial_force', axial_force)
    mech = dataclasses.replace(cho, elements_per_link=8)
    model = FlexibleLinkage(mech, ModelOptions.full_model(rigid_crank=True))
    system = model.assemble(np.radians([27.0, 200.0]))
    spec = cho.links[1]
    euler = np.pi ** 2 * cho.youngs_modulus * spec.second_moment / spec.length ** 2
    w0 = solve_frozen_modes(dataclasses.replace(system, geometric={
        k: 0 * v for k, v in system.geometric.items()}), 1).omega[:, 0]
    for speed, accel in ((0.0, 0.0), (40.0, 0.0), (30.0, 500.0)):
        tension = pieces['1'] + accel * pieces['a'] + speed ** 2 * pieces['w2']
        omega = solve_frozen_modes(system, 1, speed, accel).omega[:, 0]
        np.testing.assert_allclose(omega ** 2, w0 ** 2 * (1 + tension / euler), rtol=2e-4)
