"""FE model of the flexible four-bar (Cho 1992, Eqs. 22-36): coupling terms, loads, matrices."""

import dataclasses
import pathlib

from flexlink_ros.core.fe import beam
from flexlink_ros.core.fe.link import gauss_points
from flexlink_ros.core.fe.linkage import FlexibleLinkage
from flexlink_ros.core.kinematics import solve_kinematics
from flexlink_ros.core.mechanism_file import load_mechanism
from flexlink_ros.core.options import ModelOptions
import numpy as np
import pytest
import scipy.linalg

CONFIG = pathlib.Path(__file__).resolve().parents[3] / 'config'

NO_KG = {'geometric_stiffness': False}
CASES = {
    'all flexible, pins': ModelOptions.full_model(**NO_KG),
    'flexible bearings, shaft spring': ModelOptions.full_model(bearings='flexible', **NO_KG),
    'rigid crank, flexible bearings': ModelOptions.full_model(rigid_crank=True,
                                                              bearings='flexible', **NO_KG),
    'rigid crank, pins': ModelOptions.full_model(rigid_crank=True, **NO_KG),
}


@pytest.fixture(scope='module')
def cho():
    return load_mechanism(CONFIG / 'cho1992.yaml')


def _mechanism(cho, case):
    # Spring shaft in one case so that every kind of DOF (and k_t) is exercised.
    if 'shaft' in case:
        return dataclasses.replace(cho, shaft_stiffness=35.0, elements_per_link=2)
    return cho


# -- second-order Taylor jets in time: (value, d/dt, d2/dt2) on the leading axis ----------

def _jet_mul(a, b, op):
    return np.stack([op(a[0], b[0]), op(a[1], b[0]) + op(a[0], b[1]),
                     op(a[2], b[0]) + 2 * op(a[1], b[1]) + op(a[0], b[2])])


def _angle_jets(angle, omega, alpha):
    c, s = np.cos(angle), np.sin(angle)
    cos = np.array([c, -s * omega, -c * omega ** 2 - s * alpha])
    sin = np.array([s, c * omega, -s * omega ** 2 + c * alpha])
    return cos, sin


@pytest.mark.parametrize('case', CASES)
def test_coupling_terms_equal_inertia_of_exact_elastic_acceleration(cho, case):
    """
    M U'' + C_c U' + K_c U = sum_L T int rho H^T R^T (a_abs - a_rigid) (+ joint masses).

    The absolute position of a material point is r_rigid(x, t) + R(th_L(t)) H(x) u^L(t) with
    u^L = T^T(th_L) U(t); its elastic acceleration is differentiated exactly by second-order
    Taylor jets (product rule), with th_L, w_L, a_L from the exact kinematics and T^T written
    as P0 + cos(th_L) Pc + sin(th_L) Ps (no use of the derivative formulas being tested).
    """
    mech = _mechanism(cho, case)
    model = FlexibleLinkage(mech, CASES[case])
    rng = np.random.default_rng(7)
    theta, w, a = 2.0 * np.pi * rng.random(), 40.0 * rng.standard_normal(), 900.0
    U = rng.standard_normal((3, model.size)) * np.array([[1e-3], [0.3], [50.0]])
    system = model.assemble(theta)
    mass, damping, _, _ = system.evaluate(w, a)
    lhs = mass[0] @ U[2] + damping[0] @ U[1] + system.coupling_at(w, a)[0] @ U[0]

    state = solve_kinematics(mech, theta, w, a)
    rhs = np.zeros(model.size)
    for link in model.links:
        mats = model.link_matrices[link]
        p0 = 0.5 * (model.gather(link, 0.0)[0] + model.gather(link, np.pi)[0])
        pc = 0.5 * (model.gather(link, 0.0)[0] - model.gather(link, np.pi)[0])
        ps = model.gather(link, 0.5 * np.pi)[0] - p0
        cos, sin = _angle_jets(state.angle[link, 0], state.omega[link, 0], state.alpha[link, 0])
        gather = (np.array([p0, 0 * p0, 0 * p0]) + cos[:, None, None] * pc
                  + sin[:, None, None] * ps)
        local = _jet_mul(gather, U, lambda m, v: m @ v)                 # u^L jet (3, nl)
        rot = np.stack([np.stack([cos, -sin], -1), np.stack([sin, cos], -1)], -2)  # (3, 2, 2)
        spec = mech.links[link]
        xg, wg = gauss_points(mats.element_length)
        force = np.zeros(local.shape[1])
        for e in range(mats.elements):
            dofs = slice(3 * e, 3 * e + 6)
            h = beam.shape_functions(xg, mats.element_length)           # (g, 2, 6)
            disp = np.einsum('gij,tj->tgi', h, local[:, dofs])          # local-frame jets
            acc = _jet_mul(rot[:, None], disp, lambda r, d: np.einsum('...ij,...j->...i', r, d))[2]
            acc_local = np.einsum('ji,gj->gi', rot[0], acc)              # R^T a
            force[dofs] += mech.density * spec.area * np.einsum('g,gki,gk->i', wg, h, acc_local)
        for node, point_mass in zip((0, mats.elements), model.end_masses(link)):
            dofs = slice(3 * node, 3 * node + 2)
            acc = _jet_mul(rot, local[:, dofs], lambda r, d: r @ d)[2]
            force[dofs] += point_mass * rot[0].T @ acc
        rhs += gather[0].T @ force
    np.testing.assert_allclose(lhs, rhs, rtol=1e-11, atol=1e-11 * np.abs(rhs).max())


@pytest.mark.parametrize('case', CASES)
def test_load_vector_is_consistent_load_of_rigid_accelerations_and_gravity(cho, case):
    """R(w, a) = sum_L T int rho H^T R^T (g - a_rigid(x)) dx + joint masses (Eq. 33, exact)."""
    mech = _mechanism(cho, case)
    model = FlexibleLinkage(mech, CASES[case])
    theta, w, a = 1.234, 33.0, -250.0
    load = model.assemble(theta).load_at(w, a)[0]
    state = solve_kinematics(mech, theta, w, a)
    gravity = complex(*mech.gravity)
    expected = np.zeros(model.size)
    for link in model.links:
        mats = model.link_matrices[link]
        rotate = np.exp(-1j * state.angle[link, 0])
        xg, wg = gauss_points(mats.element_length)
        force = np.zeros(3 * (mats.elements + 1))
        for e in range(mats.elements):
            x = mats.nodes[e] + xg
            acc = np.array([state.point(link, xi)[2][0] for xi in x])
            body = (gravity - acc) * rotate
            h = beam.shape_functions(xg, mats.element_length)
            force[3 * e:3 * e + 6] += (mech.density * mech.links[link].area
                                       * np.einsum('g,gki,gk->i', wg, h,
                                                   np.stack([body.real, body.imag], -1)))
        for node, point_mass in zip((0, mats.elements), model.end_masses(link)):
            acc = state.point(link, mats.nodes[node])[2][0]
            body = (gravity - acc) * rotate
            force[3 * node:3 * node + 2] += point_mass * np.array([body.real, body.imag])
        expected += model.gather(link, state.angle[link])[0].T @ force
    np.testing.assert_allclose(load, expected, rtol=1e-12, atol=1e-12 * np.abs(expected).max())


def test_structure_matrices(cho):
    for case, options in CASES.items():
        model = FlexibleLinkage(_mechanism(cho, case), options)
        system = model.assemble(np.radians([0.0, 90.0, 200.0]))
        for matrix in (system.mass, system.stiffness):
            np.testing.assert_allclose(matrix, np.swapaxes(matrix, 1, 2), atol=1e-12)
            assert np.linalg.eigvalsh(matrix).min() > 0.0, case   # frozen structure is stable
        # C_c = 2 T M T'^T + 2 w_L T M_s T^T is dM/dt plus a skew (gyroscopic) part:
        # C1 + C1^T = 2 dM/dtheta (Lagrange's d/dt (M U')), checked by central differences
        gyro, h = system.gyroscopic, 1e-6
        plus = FlexibleLinkage(model.mechanism, options).assemble(np.radians([0.0, 90.0, 200.0])
                                                                  + h).mass
        minus = FlexibleLinkage(model.mechanism, options).assemble(
            np.radians([0.0, 90.0, 200.0]) - h).mass
        np.testing.assert_allclose(gyro + np.swapaxes(gyro, 1, 2), (plus - minus) / h,
                                   atol=1e-7 * np.abs(gyro).max())


def test_stiff_bearings_approach_exact_pins(cho):
    theta = np.radians(27.0)

    def lowest(mech, options):
        system = FlexibleLinkage(mech, options).assemble(theta)
        return np.sqrt(scipy.linalg.eigh(system.stiffness[0], system.mass[0],
                                         eigvals_only=True, subset_by_index=[0, 3]))

    pins = lowest(cho, ModelOptions.full_model(**NO_KG))
    stiff = lowest(dataclasses.replace(cho, bearing_stiffness=cho.bearing_stiffness * 1e5),
                   ModelOptions.full_model(bearings='flexible', **NO_KG))
    soft = lowest(cho, ModelOptions.full_model(bearings='flexible', **NO_KG))
    np.testing.assert_allclose(stiff, pins, rtol=2e-4)
    assert np.all(soft < pins)          # bearing compliance lowers every frequency


def test_bad_options_are_refused(cho):
    with pytest.raises(ValueError, match='bearings'):
        FlexibleLinkage(cho, ModelOptions.full_model(bearings='elastic'))
    with pytest.raises(ValueError, match='bearing_stiffness'):
        FlexibleLinkage(dataclasses.replace(cho, bearing_stiffness=None),
                        ModelOptions.full_model(bearings='flexible'))
