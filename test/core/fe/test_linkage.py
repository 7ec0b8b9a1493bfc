"""FE model of the flexible four-bar (Cho 1992, Eqs. 22-36): coupling terms, loads, beams."""

import dataclasses
import pathlib

from flexlink_ros.core.fe import beam
from flexlink_ros.core.fe.link import (element_geometric_stiffness, gauss_points, link_matrices,
                                       transverse_slopes)
from flexlink_ros.core.fe.linkage import FlexibleLinkage
from flexlink_ros.core.kinematics import solve_kinematics
from flexlink_ros.core.mechanism import load_mechanism
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


def test_joint_masses_are_conserved_and_split(cho):
    pins = FlexibleLinkage(cho, ModelOptions.full_model(**NO_KG))
    springs = FlexibleLinkage(cho, ModelOptions.full_model(bearings='flexible', **NO_KG))
    total = sum(cho.joint_masses.values())
    assert sum(sum(pins.end_masses(link)) for link in pins.links) == pytest.approx(total)
    # flexible bearings: the ground's shares at O2 and O4 stay on the ground
    grounded = (cho.joint_mass_split * cho.joint_masses['O2']
                + (1 - cho.joint_mass_split) * cho.joint_masses['O4'])
    assert sum(sum(springs.end_masses(link)) for link in springs.links) == pytest.approx(
        total - grounded)
    assert springs.end_masses(1)[1] == pytest.approx(cho.joint_mass_split * cho.joint_masses['B'])
    assert springs.end_masses(2)[1] == pytest.approx(
        (1 - cho.joint_mass_split) * cho.joint_masses['B'])


def test_gather_derivatives_match_finite_differences(cho):
    model = FlexibleLinkage(cho, ModelOptions.full_model(bearings='flexible', **NO_KG))
    angle, h = np.array([0.7]), 1e-5
    for link in model.links:
        t = [model.gather(link, angle + k * h) for k in (-1, 0, 1)]
        np.testing.assert_allclose(model.gather(link, angle, 1), (t[2] - t[0]) / (2 * h),
                                   atol=1e-9)
        np.testing.assert_allclose(model.gather(link, angle, 2),
                                   (t[2] - 2 * t[1] + t[0]) / h ** 2, atol=1e-5)


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


def test_output_operators(cho):
    model = FlexibleLinkage(cho, ModelOptions.full_model(bearings='flexible', **NO_KG))
    theta = np.radians([10.0, 250.0])
    out = model.output_operator(theta)
    # lever tip = the lever-side node of bearing B, already in the ground frame
    for k in range(2):
        np.testing.assert_allclose(out[k, 0, model.dof_index('B.lever.X')], 1.0)
        np.testing.assert_allclose(out[k, 1, model.dof_index('B.lever.Y')], 1.0)
        assert np.abs(out[k, :2]).sum() == pytest.approx(2.0, abs=1e-12)
    # coupler mid-point (between nodes 1 and 2 of 3 elements): v of the mid-span node of a
    # single bending DOF field, rotated to the ground frame
    U = np.zeros(model.size)
    U[model.dof_index('coupler.n1.v')] = 1.0
    U[model.dof_index('coupler.n2.v')] = 1.0
    angle = solve_kinematics(cho, theta).angle[1]
    np.testing.assert_allclose(out[:, 2] @ U, -np.sin(angle), atol=1e-14)
    np.testing.assert_allclose(out[:, 3] @ U, np.cos(angle), atol=1e-14)
    positions, shapes = model.shape_operator(theta, points_per_element=4)
    assert positions.shape == (2, 3, 13, 2) and shapes.shape == (2, 3, 13, 2, model.size)
    state = solve_kinematics(cho, theta)
    np.testing.assert_allclose(positions[:, 2, -1, 0] + 1j * positions[:, 2, -1, 1],
                               state.joints['B'])
    np.testing.assert_allclose(shapes[:, 2, -1], out[:, :2])
    np.testing.assert_allclose(shapes[:, 1, 6], out[:, 2:])


# -- single beams ---------------------------------------------------------------------------

E, RHO, AREA, SECOND, LENGTH = 2.19e11, 7718.0, 0.14406e-4, 1.153e-12, 0.262
CANTILEVER_BL = (1.875104068711961, 4.694091132974175, 7.854757438237613)


def _bending_frequencies(elements, keep, geometric=None, shift=0.0):
    mats = link_matrices(E, AREA, SECOND, RHO, LENGTH, elements)
    dofs = np.array([d for d in range(3 * (elements + 1)) if d % 3 and keep(d)])
    stiffness = mats.stiffness if geometric is None else mats.stiffness + geometric
    stiffness = stiffness - shift * mats.mass
    values = scipy.linalg.eigh(stiffness[np.ix_(dofs, dofs)], mats.mass[np.ix_(dofs, dofs)],
                               eigvals_only=True, subset_by_index=[0, 2])
    return np.sqrt(values)


def _scale():
    return np.sqrt(E * SECOND / (RHO * AREA * LENGTH ** 4))


@pytest.mark.parametrize('bc', ['cantilever', 'pinned-pinned'])
def test_beam_frequencies_converge_at_fourth_order(bc):
    """Euler-Bernoulli closed forms: (beta L)^2 sqrt(EI / (rho A L^4)); cubic Hermite: h^4."""
    if bc == 'cantilever':
        exact = np.array(CANTILEVER_BL) ** 2 * _scale()
        keep = lambda n: lambda d: d >= 3  # noqa: E731 - clamp node 0 (v, phi)
    else:
        exact = (np.pi * np.arange(1, 4)) ** 2 * _scale()
        keep = lambda n: lambda d: d not in (1, 3 * n + 1)  # noqa: E731 - v = 0 at both ends
    errors = []
    for n in (4, 8, 16):
        freqs = _bending_frequencies(n, keep(n))
        errors.append(np.abs(freqs / exact - 1))
    errors = np.array(errors)
    assert errors[-1].max() < 1e-4
    rates = np.log2(errors[:-1] / errors[1:])
    assert np.all(rates[-1] > 3.8) and np.all(rates[-1] < 4.2), rates   # asymptotic: 8 -> 16


# Wright, Smith, Thresher & Wang (1982), "Vibration modes of centrifugally stiffened beams",
# J. Appl. Mech. 49, 197-202 (zero hub radius), the values Yoo & Shin (1998), "Vibration
# analysis of rotating cantilever beams", J. Sound Vib. 212(5), 807-828, compare with:
# dimensionless flapwise frequencies w sqrt(rho A L^4 / EI) at speed ratios
# gamma = Omega sqrt(rho A L^4 / EI). In-plane (chordwise) with the stretching coupling ignored,
# w_c^2 = w_f^2 - Omega^2 (the -Omega^2 M term of Eq. 22): the Southwell form with S - 1.
# (Re-computed here by Chebyshev collocation to 1e-8: 3.68164744, 22.18101126 at gamma 1;
# 11.20232867, 33.64036449 at gamma 10.)
ROTATING_FLAPWISE = {1.0: (3.6816, 22.1810), 2.0: (4.1373, 22.6149), 3.0: (4.7973, 23.3203),
                     5.0: (6.4495, 25.4461), 10.0: (11.2023, 33.6404)}


@pytest.mark.parametrize('gamma', sorted(ROTATING_FLAPWISE))
def test_rotating_cantilever_matches_published_centrifugal_stiffening(gamma):
    elements = 24
    omega = gamma * _scale()
    mats = link_matrices(E, AREA, SECOND, RHO, LENGTH, elements)
    x = (mats.nodes[:-1, None] + gauss_points(mats.element_length)[0][None, :])
    tension = RHO * AREA * omega ** 2 * (LENGTH ** 2 - x ** 2) / 2.0   # rotation about the root
    kg = np.zeros_like(mats.stiffness)
    for e, element in enumerate(element_geometric_stiffness(tension, mats.element_length)):
        kg[3 * e:3 * e + 6, 3 * e:3 * e + 6] += element
    keep = lambda d: d >= 3  # noqa: E731
    flap = _bending_frequencies(elements, keep, kg) / _scale()
    chord = _bending_frequencies(elements, keep, kg, shift=omega ** 2) / _scale()
    published = np.array(ROTATING_FLAPWISE[gamma])
    np.testing.assert_allclose(flap[:2], published, rtol=2e-5, atol=6e-5)
    np.testing.assert_allclose(chord[:2], np.sqrt(published ** 2 - gamma ** 2), rtol=2e-5,
                               atol=6e-5)
    if gamma == 1.0:   # Southwell coefficient of mode 1 at low speed
        southwell = (flap[0] ** 2 - (CANTILEVER_BL[0] ** 2) ** 2) / gamma ** 2
        assert southwell == pytest.approx(1.1925, abs=1e-3)


def test_geometric_stiffness_with_constant_force_is_a4():
    forces = np.full(4, 37.5)
    np.testing.assert_allclose(element_geometric_stiffness(forces, 0.09),
                               beam.beam_geometric_stiffness(37.5, 0.09), rtol=1e-13, atol=1e-12)
    # a force linear in x integrates exactly (compare with 8-point quadrature)
    x8, w8 = np.polynomial.legendre.leggauss(8)
    length = 0.09
    x8, w8 = 0.5 * length * (x8 + 1), 0.5 * length * w8
    force = lambda x: 10.0 - 300.0 * x + 900.0 * x ** 2  # noqa: E731
    dense = np.einsum('g,g,gi,gj->ij', force(x8), w8, transverse_slopes(x8, length),
                      transverse_slopes(x8, length))
    xg, _ = gauss_points(length)
    np.testing.assert_allclose(element_geometric_stiffness(force(xg), length), dense,
                               rtol=1e-12, atol=1e-12 * np.abs(dense).max())


def test_bad_options_are_refused(cho):
    with pytest.raises(ValueError, match='bearings'):
        FlexibleLinkage(cho, ModelOptions.full_model(bearings='elastic'))
    with pytest.raises(ValueError, match='bearing_stiffness'):
        FlexibleLinkage(dataclasses.replace(cho, bearing_stiffness=None),
                        ModelOptions.full_model(bearings='flexible'))


# -- geometric stiffness from the rigid-body analysis (core/dynamics.py) ------------------

@pytest.mark.parametrize('case', CASES)
def test_rigid_body_axial_forces_equal_fe_quasi_static_element_forces(cho, case):
    """
    FE element axial forces of K U = R equal the rigid-body axial forces.

    The frozen structure (clamped crank or rigid crank) is statically determinate, so
    K U = R (no elastic inertia) gives element axial forces EA du/l equal to the mean over
    each element of the rigid-body axial force F(x) (dynamics.axial_force: distributed
    inertia, gravity and joint masses); linear elements are nodally exact for bars.
    """
    axial_force = pytest.importorskip('flexlink_ros.core.dynamics').axial_force
    mech = _mechanism(cho, case)
    model = FlexibleLinkage(mech, CASES[case])
    theta = np.radians([17.0, 141.0, 290.0])
    w, a = 41.0, -320.0
    system = model.assemble(theta)
    load = system.load_at(w, a)
    displacement = np.linalg.solve(system.stiffness, load[..., None])[..., 0]
    fe = model.element_axial_forces(displacement, theta)
    state = solve_kinematics(mech, theta, w, a)
    for link in model.links:
        mats = model.link_matrices[link]
        x = model.gauss_positions(link)
        _, weights = gauss_points(mats.element_length)
        exact = np.asarray(axial_force(mech, state, link, x.ravel())).reshape(
            (len(theta),) + x.shape)
        mean = exact @ weights / mats.element_length
        np.testing.assert_allclose(fe[link], mean, rtol=1e-8, atol=1e-9 * np.abs(mean).max())


@pytest.mark.parametrize('bearings', ['rigid', 'flexible'])
def test_quasi_static_axial_forces_under_gravity_equal_hand_statics(cho, bearings):
    """
    Rigid crank at rest under gravity: FE element forces equal hand statics.

    Rigid crank at rest: coupler and lever are pinned bars under their weight, joined at B
    (joint mass m_B). Each bar's transverse end force is half its transverse weight; the two
    axial end forces at B follow from the pin's equilibrium; the tension then varies linearly
    with the axial weight component. FE element forces (K U = R) equal its element means.
    """
    options = ModelOptions.full_model(rigid_crank=True, bearings=bearings, **NO_KG)
    model = FlexibleLinkage(cho, options)
    theta = np.radians([33.0, 250.0])
    system = model.assemble(theta)
    displacement = np.linalg.solve(system.stiffness, system.load_at(0.0)[..., None])[..., 0]
    fe = model.element_axial_forces(displacement, theta)
    angle = solve_kinematics(cho, theta).angle
    gravity = np.array(cho.gravity)
    for k in range(len(theta)):
        axes = {link: np.array([np.cos(angle[link, k]), np.sin(angle[link, k])])
                for link in (1, 2)}
        normals = {link: np.array([-axis[1], axis[0]]) for link, axis in axes.items()}
        weights = {link: cho.links[link].mass * gravity for link in (1, 2)}
        # forces of the pin B on the bars: axial a e + transverse -(W.n)/2 n, summing to m_B g
        rhs = cho.joint_masses['B'] * gravity - sum(-(weights[j] @ normals[j]) / 2 * normals[j]
                                                    for j in (1, 2))
        axial_end = np.linalg.solve(np.column_stack([axes[1], axes[2]]), rhs)
        for link, end_force in zip((1, 2), axial_end):
            length = cho.links[link].length
            centres = (np.arange(cho.elements_per_link) + 0.5) * length / cho.elements_per_link
            expected = end_force + (weights[link] @ axes[link]) * (length - centres) / length
            np.testing.assert_allclose(fe[link][k], expected, rtol=1e-9, atol=1e-12)
