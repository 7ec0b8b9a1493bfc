"""Periodic steady state of the flexible four-bar: full order (Eq. 30) and mode superposition."""

import dataclasses
import pathlib

from flexlink_ros.core.fe import stiffness_damping as sd
from flexlink_ros.core.fe.linkage import FlexibleLinkage
from flexlink_ros.core.fe.modes import modal_damping
from flexlink_ros.core.fe.simulate import frozen_eigen, periodic_response, step_convergence
from flexlink_ros.core.mechanism_file import load_mechanism
from flexlink_ros.core.options import ModelOptions
import numpy as np
import pytest
import scipy.integrate

CONFIG = pathlib.Path(__file__).resolve().parents[3] / 'config'
NO_KG = {'geometric_stiffness': False}
RPM = 2.0 * np.pi / 60.0


@pytest.fixture(scope='module')
def cho():
    return load_mechanism(CONFIG / 'cho1992.yaml')


def _small(cho, elements=2):
    return dataclasses.replace(cho, elements_per_link=elements)


def test_periodic_state_matches_independent_integration(cho):
    """
    The shooting state matches an independent explicit integration.

    One revolution from the shooting state by scipy's explicit DOP853 (rtol 1e-8) on the
    matrices assembled at every requested time returns the same outputs and ends where it
    started (periodicity). The links are made 100 times less slender (E / 1e4, I * 1e4: same
    bending stiffness, axial modes 100 times lower) and the bearings 4 times softer so that an
    explicit method can afford one revolution.
    """
    soft = dataclasses.replace(
        _small(cho, 1), youngs_modulus=cho.youngs_modulus / 1e4,
        bearing_stiffness=cho.bearing_stiffness / 4,
        links=tuple(dataclasses.replace(link, second_moment=link.second_moment * 1e4)
                    for link in cho.links))
    options = ModelOptions.full_model(rigid_crank=True, bearings='flexible', **NO_KG)
    model = FlexibleLinkage(soft, options)
    speed = 391 * RPM
    response = periodic_response(model, speed, steps=720, points=24, stages=3)
    n = model.size

    def rhs(t, y):
        system = model.assemble(speed * t)
        mass, gyro, stiffness, load = system.evaluate(speed)
        values, shapes = frozen_eigen(system, speed)
        damping = gyro[0] + modal_damping(system.mass, values, shapes, soft.damping_ratio)[0]
        acc = np.linalg.solve(mass[0], load[0] - damping @ y[n:] - stiffness[0] @ y[:n])
        return np.concatenate([y[n:], acc])

    period = 2.0 * np.pi / speed
    y0 = np.concatenate([response.displacement[0], response.velocity[0]])
    times = period * np.arange(25) / 24
    sol = scipy.integrate.solve_ivp(rhs, (0.0, period), y0, method='DOP853', t_eval=times,
                                    rtol=1e-8, atol=1e-12)
    outputs = np.einsum('kon,nk->ko', model.output_operator(speed * times), sol.y[:n])
    scale = np.abs(response.outputs).max()
    np.testing.assert_allclose(outputs[:-1], response.outputs, atol=1e-8 * scale)
    np.testing.assert_allclose(outputs[-1], outputs[0], atol=1e-8 * scale)


@pytest.mark.parametrize('stages, order', [(2, 3.0), (3, 5.0)])
def test_time_step_convergence_order(cho, stages, order):
    model = FlexibleLinkage(_small(cho), ModelOptions.full_model(rigid_crank=True, **NO_KG))
    check = step_convergence(model, 391 * RPM, steps=(120, 240, 480), reference_steps=1920,
                             points=24, stages=stages)
    assert check['observed_order'][-1] == pytest.approx(order, abs=0.3), check
    assert check['max_error_m'][-1] < 1e-4 * check['scale_m']


@pytest.mark.parametrize('options', [ModelOptions.full_model(**NO_KG),
                                     ModelOptions.full_model(rigid_crank=True, bearings='flexible',
                                                             **NO_KG)])
def test_modal_response_with_all_modes_equals_full_order(cho, options):
    model = FlexibleLinkage(_small(cho), options)
    full = periodic_response(model, 269 * RPM, steps=240, points=24)
    modal = periodic_response(model, 269 * RPM, method='modal', modes=model.size, steps=240,
                              points=24)
    scale = np.abs(full.outputs).max()
    np.testing.assert_allclose(modal.outputs, full.outputs, atol=1e-10 * scale)
    np.testing.assert_allclose(modal.displacement, full.displacement,
                               atol=1e-10 * np.abs(full.displacement).max())


def test_static_correction_recovers_truncated_axial_response(cho):
    """
    The static correction restores what truncated modes miss.

    Rigid bearings: with 3 modes the lever tip (axial) deflection is missed; the
    residual-flexibility correction restores it, and the coupler mid-point too.
    """
    model = FlexibleLinkage(_small(cho), ModelOptions.full_model(rigid_crank=True, **NO_KG))
    kwargs = {'steps': 240, 'points': 24}
    full = periodic_response(model, 391 * RPM, **kwargs)
    plain = periodic_response(model, 391 * RPM, method='modal', modes=3, **kwargs)
    fixed = periodic_response(model, 391 * RPM, method='modal', modes=3,
                              static_correction=True, **kwargs)
    error_plain = np.abs(plain.outputs - full.outputs).max(axis=0)
    error_fixed = np.abs(fixed.outputs - full.outputs).max(axis=0)
    assert np.all(error_fixed < 0.1 * error_plain)
    assert error_fixed.max() < 1e-3 * np.abs(full.outputs).max()


def test_slow_rotation_is_quasi_static(cho):
    """At 1 rad/s inertia is negligible: U = (K + K_G + K_c)^-1 R at every angle."""
    model = FlexibleLinkage(_small(cho), ModelOptions.full_model(**NO_KG))
    response = periodic_response(model, 1.0, steps=240, points=12)
    system = model.assemble(response.crank_angle)
    _, _, stiffness, load = system.evaluate(1.0)
    static = np.linalg.solve(stiffness, load[..., None])[..., 0]
    np.testing.assert_allclose(response.displacement, static,
                               atol=1e-3 * np.abs(static).max())


def test_rigid_bearings_keep_lever_tip_deflection_tiny(cho):
    """
    Paper, Fig.

    20: with rigid bearings and a rigid crank the lever tip moves only by
    axial strain, far less than the coupler mid-point; flexible bearings move it much more.
    """
    options = dict(rigid_crank=True, **NO_KG)
    pins = periodic_response(FlexibleLinkage(cho, ModelOptions.full_model(**options)), 391 * RPM,
                             steps=240, points=24).peak_to_peak
    springs = periodic_response(FlexibleLinkage(cho, ModelOptions.full_model(bearings='flexible',
                                                                             **options)),
                                391 * RPM, steps=240, points=24).peak_to_peak
    assert pins[:2].max() < 1e-2 * pins[2:].max()
    assert springs[:2].max() > 100 * pins[:2].max()


def test_bad_arguments(cho):
    model = FlexibleLinkage(_small(cho, 1), ModelOptions.full_model(rigid_crank=True, **NO_KG))
    with pytest.raises(ValueError, match='method'):
        periodic_response(model, 10.0, method='fourier')
    with pytest.raises(ValueError, match='modes'):
        periodic_response(model, 10.0, method='modal')
    with pytest.raises(ValueError, match='multiple'):
        periodic_response(model, 10.0, steps=100, points=30)
    with pytest.raises(ValueError, match='speed'):
        periodic_response(model, 0.0)


BETA = 1e-4


def _beta_model(cho, bearings='flexible', elements=3, beta=0.0):
    options = ModelOptions.full_model(rigid_crank=True, bearings=bearings, gravity=False,
                                      stiffness_damping=beta)
    return FlexibleLinkage(_small(cho, elements), options)


@pytest.mark.parametrize('bearings', ['rigid', 'flexible'])
def test_beta_free_response_decays_at_beta_omega_squared_over_two(cho, bearings):
    """
    Floquet multipliers (the unloaded one-revolution map) of the lowest modes with beta only.

    Each frozen mode's amplitude decays at ``beta omega_i^2 / 2`` (zeta_i = beta omega_i / 2),
    so at a slow crank (adiabatic, Coriolis negligible) ``-ln |mu_i|`` is
    ``beta / 2`` times the integral of omega_i^2 over the revolution. Without beta (zeta = 0)
    the multipliers have modulus 1: the decay is beta's.
    """
    model = _beta_model(cho, bearings)
    speed, steps = 20.0 * RPM, 1440
    damped = periodic_response(model, speed, steps=steps, points=24, stages=3, zeta=0.0,
                               beta=BETA)
    angles = 2.0 * np.pi * np.arange(steps) / steps
    values, _ = frozen_eigen(model.assemble(angles), speed)
    expected = 0.5 * BETA * values[:, :2].mean(axis=0) * (2.0 * np.pi / speed)
    measured = -np.log(np.abs(damped.floquet_multipliers[[0, 2]]))   # complex pairs
    assert np.allclose(measured, expected, rtol=0.01)
    assert expected[0] > 3.0   # a real decay (a factor e^-3 or more per revolution)
    undamped = periodic_response(model, speed, steps=steps, points=24, stages=3, zeta=0.0,
                                 beta=0.0)
    assert np.abs(undamped.floquet_multipliers[:4]) == pytest.approx(1.0, abs=0.01)


def test_beta_from_options_matches_the_objective_stage_matrices(cho):
    """beta=None reads model.options.stiffness_damping; equal to passing C_beta, D_beta in."""
    from_options = _beta_model(cho, beta=BETA)
    speed = 269.0 * RPM
    run = periodic_response(from_options, speed, steps=240, points=24, zeta=0.0)
    assert run.info['stiffness_damping_s'] == BETA
    plain = _beta_model(cho)
    given = periodic_response(
        plain, speed, steps=240, points=24,
        matrices=lambda angles: sd.system_matrices(plain, angles, speed, BETA))
    assert np.allclose(run.outputs, given.outputs, rtol=0.0,
                       atol=1e-9 * np.abs(given.outputs).max())
    undamped = periodic_response(plain, speed, steps=240, points=24, zeta=0.0)
    assert undamped.info['stiffness_damping_s'] == 0.0
    # beta changes the response (a real damping, not a rounding)
    assert np.abs(undamped.outputs - run.outputs).max() > 0.01 * np.abs(run.outputs).max()
    with pytest.raises(ValueError, match='beta'):
        periodic_response(plain, speed, steps=240, points=24, beta=-1e-4)


def test_beta_modal_response_with_all_modes_equals_full_order(cho):
    model = _beta_model(cho, beta=BETA)
    speed = 269.0 * RPM
    full = periodic_response(model, speed, steps=240, points=24, zeta=0.0)
    modal = periodic_response(model, speed, 'modal', modes=model.size, steps=240, points=24,
                              zeta=0.0)
    assert np.allclose(modal.outputs, full.outputs, rtol=0.0,
                       atol=1e-8 * np.abs(full.outputs).max())
