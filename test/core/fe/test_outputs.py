"""Output operators and element axial forces of the FE model (core/fe/outputs.py)."""

import dataclasses
import pathlib

from flexlink_ros.core.fe.link import gauss_points
from flexlink_ros.core.fe.linkage import FlexibleLinkage
from flexlink_ros.core.kinematics import solve_kinematics
from flexlink_ros.core.mechanism_file import load_mechanism
from flexlink_ros.core.options import ModelOptions
import numpy as np
import pytest

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
