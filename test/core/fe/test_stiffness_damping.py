"""Objective stiffness-proportional damping (core/fe/stiffness_damping.py)."""

import dataclasses
import math

from flexlink_ros.core.fe import stiffness_damping as sd
from flexlink_ros.core.fe.link import link_matrices
from flexlink_ros.core.fe.linkage import FlexibleLinkage
from flexlink_ros.core.mechanism_file import load_mechanism
from flexlink_ros.core.options import ModelOptions
import numpy as np
import pytest
import scipy.linalg

BETA = 1e-4


def _model(elements=4, bearings='rigid', rigid_crank=True, gravity=True, geometric=True):
    mech = dataclasses.replace(load_mechanism('cho1992'), elements_per_link=elements)
    options = ModelOptions.full_model(rigid_crank=rigid_crank, bearings=bearings,
                                      gravity=gravity, geometric_stiffness=geometric)
    return FlexibleLinkage(mech, options)


def _static(model, theta=1.0):
    system = model.assemble(np.array([theta]))
    return np.linalg.solve(system.frozen_stiffness(0.0)[0], system.load_at(0.0)[0])[None]


def _rotating_forces(model, theta, displacement, velocity, rate):
    """Element damping forces (objective, naive) with every link frame turning at ``rate``."""
    angle = model.kinematic_coefficients(np.array([theta]))[0]
    right = np.zeros_like(displacement)
    naive = np.zeros_like(displacement)
    for link in model.links:
        c, d = sd.link_damping_matrices(model, link, angle[link], rate, BETA)
        naive += np.einsum('kij,kj->ki', c, velocity)
        right += np.einsum('kij,kj->ki', c, velocity) + np.einsum('kij,kj->ki', d, displacement)
    return right, naive


@pytest.mark.parametrize('bearings', ['rigid', 'flexible'])
def test_rigid_rotation_of_deformed_linkage_dissipates_nothing(bearings):
    """u^L constant in every link frame: zero element force; naive beta K U' dissipates."""
    model = _model(4, bearings, rigid_crank=False)
    U = _static(model)
    rate = 25.0
    Ud = sd.rigid_rotation_velocity(model, U, rate)
    right, naive = _rotating_forces(model, 1.0, U, Ud, rate)
    scale = np.abs(naive).max()
    assert scale > 0.0
    assert np.abs(right).max() <= 1e-10 * scale
    assert abs(float(np.sum(Ud * right))) <= 1e-12 * float(np.sum(Ud * naive))
    assert float(np.sum(Ud * naive)) > 0.0
    # bearings (peer convention, ground-frame Cartesian damper): beta k rate^2 |Delta|^2
    bearing = sd.bearing_damping_matrix(model, BETA)
    power = float(Ud[0] @ bearing @ Ud[0])
    expected = rate ** 2 * BETA * float(U[0] @ model.bearing_stiffness @ U[0])
    assert power == pytest.approx(expected, rel=1e-12, abs=1e-30)


def test_naive_end_element_axial_force_closed_form():
    """Naive minus objective axial force in an end element is beta E A w v_e / l_e."""
    model = _model(4, 'flexible')
    U = _static(model)
    rate = 25.0
    Ud = sd.rigid_rotation_velocity(model, U, rate)
    angle = model.kinematic_coefficients(np.array([1.0]))[0]
    link = 1
    mats = model.link_matrices[link]
    spec = model.mechanism.links[link]
    naive = sd.link_local_rate(model, link, angle[link], 0.0, U, Ud)
    right = sd.link_local_rate(model, link, angle[link], rate, U, Ud)
    assert np.abs(right).max() < 1e-15
    axial = sd.element_resultants(model, link, naive, BETA)['axial'][0]
    local = np.einsum('kan,kn->ka', model.gather(link, angle[link]), U)[0]
    ea_le = model.mechanism.youngs_modulus * spec.area / mats.element_length
    # d(R^T U_g)/dt at fixed local u: naive rate = rate S u_end -> axial -rate v at each end
    last = 3 * mats.elements
    assert axial[-1] == pytest.approx(BETA * ea_le * (-rate * local[last + 1]), rel=1e-10)
    assert axial[0] == pytest.approx(BETA * ea_le * rate * local[1], rel=1e-10)
    assert np.allclose(axial[1:-1], 0.0)


def test_uniform_stretch_and_curvature_rates_give_closed_forms():
    """Uniform eps' -> N = beta E A eps'; uniform kappa' -> end moments beta E I kappa'."""
    model = _model(4, 'flexible')
    link, theta, rate = 1, 0.7, 12.0
    angle = model.kinematic_coefficients(np.array([theta]))[0][link]
    mats = model.link_matrices[link]
    spec = model.mechanism.links[link]
    E = model.mechanism.youngs_modulus
    x = mats.nodes
    eps_rate, kappa_rate = 3e-3, 0.05
    target = np.zeros(3 * (mats.elements + 1))
    target[0::3] = eps_rate * x
    target[1::3] = 0.5 * kappa_rate * x ** 2
    target[2::3] = kappa_rate * x
    # a deformed link that also turns at `rate`: U' = rigid-rotation part + T u'_target
    U = _static(model)
    t0 = model.gather(link, angle)
    Ud = sd.rigid_rotation_velocity(model, U, rate) + np.einsum('kan,ka->kn', t0, target[None])
    local = sd.link_local_rate(model, link, angle, rate, U, Ud)
    assert np.allclose(local[0], target, atol=1e-15)
    res = sd.element_resultants(model, link, local, BETA)
    assert np.allclose(res['axial'], BETA * E * spec.area * eps_rate, rtol=1e-12)
    nodal = res['nodal'][0]
    moment = BETA * E * spec.second_moment * kappa_rate
    assert np.allclose(nodal[:, 2], -moment, rtol=1e-9)
    assert np.allclose(nodal[:, 5], moment, rtol=1e-9)
    assert np.allclose(nodal[:, [1, 4]], 0.0, atol=1e-9 * moment / mats.element_length)


def test_pinned_pinned_beam_mode_decays_at_beta_omega_over_two():
    """Damped frozen single link: zeta_1 = beta omega_1 / 2, omega_1 = (pi/L)^2 sqrt(EI/rhoA)."""
    mech = load_mechanism('cho1992')
    spec = mech.links[1]
    E, rho = mech.youngs_modulus, mech.density
    mats = link_matrices(E, spec.area, spec.second_moment, rho, spec.length, 8)
    free = np.setdiff1d(np.arange(mats.stiffness.shape[0]), [0, 1, 3 * mats.elements + 1])
    M = mats.mass[np.ix_(free, free)]
    K = mats.stiffness[np.ix_(free, free)]
    n = len(free)
    Minv = np.linalg.inv(M)
    state = np.block([[np.zeros((n, n)), np.eye(n)], [-Minv @ K, -BETA * Minv @ K]])
    lam = np.linalg.eigvals(state)
    lam = lam[lam.imag > 0]
    first = lam[np.argmin(np.abs(lam))]
    omega = abs(first)
    zeta = -first.real / omega
    exact = (math.pi / spec.length) ** 2 * math.sqrt(E * spec.second_moment / (rho * spec.area))
    assert omega == pytest.approx(exact, rel=1e-4)
    assert zeta == pytest.approx(0.5 * BETA * omega, rel=1e-9)
    assert zeta == pytest.approx(0.5 * BETA * exact, rel=1e-4)


def test_assembled_frozen_linkage_modes_have_zeta_beta_omega_over_two():
    """At rest (no K_G) C_beta = beta K is classical: every mode zeta_i = beta omega_i / 2."""
    model = _model(3, 'flexible', rigid_crank=False, gravity=False, geometric=False)
    theta = np.array([0.4])
    mass, damping, stiffness, _ = sd.system_matrices(model, theta, 0.0, BETA)
    w2, phi = scipy.linalg.eigh(stiffness[0], mass[0])
    modal = phi.T @ damping[0] @ phi
    assert np.allclose(modal, np.diag(BETA * w2), atol=1e-9 * BETA * w2.max())


def test_damping_matrix_symmetric_psd_with_link_rigid_modes_in_null_space():
    model = _model(4, 'flexible')
    theta = np.array([0.3, 2.0])
    c_el, rotation = sd.element_damping_matrices(model, theta, BETA)
    system = model.assemble(theta)
    assert np.allclose(c_el, BETA * system.link_stiffness.sum(axis=1), rtol=1e-12, atol=1e-6)
    c_all, _ = sd.stiffness_damping_terms(model, theta, 10.0, BETA)
    assert np.allclose(c_all, BETA * system.stiffness, rtol=1e-12, atol=1e-6)
    assert np.allclose(c_el, np.swapaxes(c_el, 1, 2))
    for k in range(len(theta)):
        values = np.linalg.eigvalsh(c_el[k])
        assert values.min() >= -1e-12 * values.max()
    angle = model.kinematic_coefficients(theta)[0]
    for link in model.links:
        x = model.link_matrices[link].nodes
        rigid = np.zeros((3, 3 * len(x)))
        rigid[0, 0::3] = 1.0                       # axial translation
        rigid[1, 1::3] = 1.0                       # transverse translation
        rigid[2, 1::3], rigid[2, 2::3] = x, 1.0    # infinitesimal rotation about node 0
        t0 = model.gather(link, angle[link])
        c_link, d_link = sd.link_damping_matrices(model, link, angle[link], 7.0, BETA)
        for mode in rigid:
            U = np.einsum('kan,a->kn', t0, mode)   # T u_rigid (every local DOF is free here)
            assert np.allclose(np.einsum('kan,kn->ka', t0, U), mode)
            force = np.einsum('kij,kj->ki', c_link, U)
            assert np.abs(force).max() <= 1e-9 * np.abs(c_link).max() * np.abs(U).max()


def test_rotation_term_is_the_time_derivative_of_the_gather():
    """D_beta U = beta sum T K_L d(T^T U)/dt at fixed U, by central differences in time."""
    model = _model(4, 'flexible')
    theta, w, h = 1.3, 28.0, 1e-6
    U = np.random.default_rng(1).normal(size=(1, model.size)) * 1e-4
    _, d_beta = sd.stiffness_damping_terms(model, np.array([theta]), w, BETA)
    expected = np.zeros(model.size)
    for link in model.links:
        angles = model.kinematic_coefficients(np.array([theta - w * h, theta + w * h]))[0][link]
        local = np.einsum('kan,n->ka', model.gather(link, angles), U[0])
        rate = (local[1] - local[0]) / (2 * h)
        t0 = model.gather(link, model.kinematic_coefficients(np.array([theta]))[0][link])[0]
        expected += BETA * t0.T @ model.link_matrices[link].stiffness @ rate
    assert np.allclose(d_beta[0] @ U[0], expected, rtol=1e-6, atol=1e-8 * np.abs(expected).max())


def test_system_matrices_add_beta_terms_to_evaluate():
    model = _model(3, 'flexible')
    theta, w = np.array([0.2, 1.9]), 30.0
    mass, damping, stiffness, load = sd.system_matrices(model, theta, w, BETA)
    m0, c0, k0, r0 = model.assemble(theta).evaluate(w, 0.0)
    c_beta, d_beta = sd.stiffness_damping_terms(model, theta, w, BETA)
    assert np.array_equal(mass, m0) and np.array_equal(load, r0)
    assert np.allclose(damping, c0 + c_beta) and np.allclose(stiffness, k0 + d_beta)


def test_system_terms_are_the_link_shares_at_the_mechanism_rates_and_vanish_co_moving():
    """
    The assembled C_beta, D_beta (simulate's) are the link shares at w_L = g1_L w plus beta K_b.

    So the system force is the sum of the link forces, each zero for a deformed shape carried
    along rigidly with its link frame; with every frame turning at one rate (a rigid rotation
    of the deformed linkage: the only co-moving state of all links together) the whole
    system's element force and power are zero, the naive form's power is not.
    """
    model = _model(4, 'flexible', rigid_crank=False)
    theta, w = np.array([1.0]), 25.0
    c_sys, d_sys = sd.stiffness_damping_terms(model, theta, w, BETA)
    angle, g1, _, _ = model.kinematic_coefficients(theta)
    c_sum = sd.bearing_damping_matrix(model, BETA)[None].copy()
    d_sum = np.zeros_like(c_sys)
    for link in model.links:
        c, d = sd.link_damping_matrices(model, link, angle[link], g1[link] * w, BETA)
        c_sum, d_sum = c_sum + c, d_sum + d
    assert np.allclose(c_sys, c_sum, rtol=1e-12, atol=0.0)
    assert np.allclose(d_sys, d_sum, rtol=1e-12, atol=1e-12 * np.abs(d_sys).max())
    U = _static(model)
    Ud = sd.rigid_rotation_velocity(model, U, w)
    right, naive = _rotating_forces(model, theta[0], U, Ud, w)
    assert abs(float(np.sum(Ud * right))) <= 1e-12 * float(np.sum(Ud * naive))
