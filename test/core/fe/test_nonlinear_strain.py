"""
The element-averaged von Karman force and tangent (core/fe/nonlinear_strain.py).

The linear law is the element stiffness A.3; the nonlinear force is the gradient of its strain
energy plus Kelvin-Voigt damping; both tangents equal finite differences; a large rigid
element rotation strains O(phi^4) and its rate dissipates O(phi^4 phi'^2), nothing at phi = 0.
"""

import dataclasses

from flexlink_ros.core.fe import nonlinear_strain as ns
from flexlink_ros.core.fe.beam import beam_stiffness
from flexlink_ros.core.fe.linkage import FlexibleLinkage
from flexlink_ros.core.mechanism_file import load_mechanism
from flexlink_ros.core.options import ModelOptions
import numpy as np
import pytest

BETA = 1e-4


@pytest.fixture(scope='module')
def model():
    mech = dataclasses.replace(load_mechanism('cho1992'), elements_per_link=3)
    return FlexibleLinkage(mech, ModelOptions.full_model(rigid_crank=False))


@pytest.fixture(scope='module')
def elements(model):
    return ns.model_elements(model)


def _state(elements, scale=2e-3, seed=1):
    """Element coordinates and rates of a bent, stretched state (lengths ~ scale)."""
    rng = np.random.default_rng(seed)
    q = scale * rng.standard_normal((len(elements), 6))
    q[:, [2, 5]] *= 20.0                       # slopes of order 0.04 rad
    q[:, [0, 3]] *= 0.05                       # axial displacements far smaller
    return q, 50.0 * scale * rng.standard_normal((len(elements), 6))


def test_elements_reassemble_the_link_stiffness(model, elements):
    assert len(elements) == 9 and set(elements.link) == {0, 1, 2}
    for link in model.links:
        mats = model.link_matrices[link]
        rows = elements.rows(link)
        assembled = np.zeros_like(mats.stiffness)
        for index, row in zip(np.flatnonzero(elements.link == link), rows):
            full = elements.bending[index] + (elements.axial_stiffness[index]
                                              / elements.length[index]
                                              * np.outer(ns.AXIAL, ns.AXIAL))
            assembled[np.ix_(row, row)] += full
        np.testing.assert_allclose(assembled, mats.stiffness, rtol=1e-13, atol=1e-6)


def test_linear_law_is_the_element_stiffness(model, elements):
    q, rate = _state(elements)
    force, axial = ns.element_force(elements, q, rate, BETA, nonlinear=False)
    spec, le = model.mechanism.links[1], model.link_matrices[1].element_length
    k_e = beam_stiffness(model.mechanism.youngs_modulus, spec.area, spec.second_moment, le)
    coupler = np.flatnonzero(elements.link == 1)
    np.testing.assert_allclose(force[coupler], (q[coupler] + BETA * rate[coupler]) @ k_e.T,
                               rtol=1e-12, atol=1e-9)
    stretch = (q[:, 3] - q[:, 0] + BETA * (rate[:, 3] - rate[:, 0])) / elements.length
    np.testing.assert_allclose(axial, elements.axial_stiffness * stretch, rtol=1e-12)


def test_force_is_the_gradient_of_the_strain_energy(elements):
    q, rate = _state(elements)
    force, _ = ns.element_force(elements, q, rate, 0.0)
    step = 1e-8
    gradient = np.zeros_like(q)
    # energy is a sum over elements: perturb one element at a time to split the sum
    for e in range(len(elements)):
        for a in range(6):
            dq = np.zeros_like(q)
            dq[e, a] = step
            gradient[e, a] = 0.5 * (ns.strain_energy(elements, q + dq)
                                    - ns.strain_energy(elements, q - dq)) / step
    np.testing.assert_allclose(gradient, force, rtol=1e-6, atol=1e-6 * np.abs(force).max())
    linear, _ = ns.element_force(elements, q, rate, 0.0, nonlinear=False)
    assert np.abs(force - linear).max() > 1e-3 * np.abs(force).max()   # a real difference


@pytest.mark.parametrize('nonlinear', [True, False])
def test_tangents_equal_finite_differences(elements, nonlinear):
    q, rate = _state(elements)
    stiffness, damping = ns.element_tangent(elements, q, rate, BETA, nonlinear)
    for which, tangent in (('q', stiffness), ('rate', damping)):
        fd = np.zeros_like(tangent)
        for b in range(6):
            step = 1e-6 * np.abs((q if which == 'q' else rate)[:, b]).max()
            delta = np.zeros_like(q)
            delta[:, b] = step
            args_plus = (q + delta, rate) if which == 'q' else (q, rate + delta)
            args_minus = (q - delta, rate) if which == 'q' else (q, rate - delta)
            plus, _ = ns.element_force(elements, *args_plus, BETA, nonlinear)
            minus, _ = ns.element_force(elements, *args_minus, BETA, nonlinear)
            fd[:, :, b] = (plus - minus) / (2.0 * step)
        scale = np.abs(tangent).max()
        np.testing.assert_allclose(fd, tangent, rtol=0, atol=1e-8 * scale)
        if nonlinear and which == 'q':
            # the N G and beta G q' terms are present: not the linear tangent
            linear, _ = ns.element_tangent(elements, q, rate, BETA, nonlinear=False)
            assert np.abs(tangent - linear).max() > 1e-5 * scale


def _rigid_rotation(length, phi):
    """Element coordinates of a rigid rotation by phi about its first node, and d/dphi."""
    q = np.array([0.0, 0.0, phi, length * (np.cos(phi) - 1.0), length * np.sin(phi), phi])
    dq = np.array([0.0, 0.0, 1.0, -length * np.sin(phi), length * np.cos(phi), 1.0])
    return q, dq


def test_rigid_rotation_strains_to_fourth_order(elements):
    length = elements.length[0]
    ratios, linear = [], []
    for phi in (0.05, 0.1, 0.2, 0.4):
        q, _ = _rigid_rotation(length, phi)
        strain = ns.element_strain(elements, np.broadcast_to(q, (len(elements), 6)))[0]
        ratios.append(strain / phi ** 4)
        linear.append(ns.element_strain(elements, q[None], nonlinear=False)[0] / phi ** 2)
    # eps = cos phi - 1 + sin^2 phi / 2 + O(phi^6) = -phi^4 / 8 + ...
    assert ratios[0] == pytest.approx(-1.0 / 8.0, rel=2e-3)
    assert ratios[-1] == pytest.approx(-1.0 / 8.0, rel=0.05)
    np.testing.assert_allclose(linear, -0.5, rtol=0.03)   # the linear strain: -phi^2 / 2


def test_rigid_rotation_rate_dissipates_nothing_at_first_order(elements):
    length, rate = elements.length[0], 3.0
    power = {}
    for phi in (0.0, 0.05, 0.1, 0.2):
        q, dq = _rigid_rotation(length, phi)
        qs = np.broadcast_to(q, (len(elements), 6))
        rates = np.broadcast_to(rate * dq, (len(elements), 6))
        damped, _ = ns.element_force(elements, qs, rates, BETA)
        elastic, _ = ns.element_force(elements, qs, rates, 0.0)
        power[phi] = float(np.sum((damped - elastic)[0] * rates[0]))
        linear_damped, _ = ns.element_force(elements, qs, rates, BETA, nonlinear=False)
        linear_elastic, _ = ns.element_force(elements, qs, rates, 0.0, nonlinear=False)
        power[('linear', phi)] = float(np.sum((linear_damped - linear_elastic)[0] * rates[0]))
    scale = BETA * elements.axial_stiffness[0] * length * rate ** 2
    assert abs(power[0.0]) < 1e-12 * scale
    # O(phi^4) at least (bending phi^4, axial phi^6): halving phi divides it by 16 or more
    assert 0.0 < power[0.1] / power[0.2] <= 1.0 / 16.0
    assert 0.0 < power[0.05] / power[0.1] <= 1.0 / 16.0
    # the linear strain's axial damping: beta E A l sin^2 phi phi'^2
    assert power[('linear', 0.2)] == pytest.approx(scale * np.sin(0.2) ** 2, rel=0.02)
    assert power[0.2] < 1e-3 * power[('linear', 0.2)]


def test_projections_match_explicit_sums(elements):
    rng = np.random.default_rng(3)
    gather = rng.standard_normal((2, len(elements), 6, 5))
    right = rng.standard_normal((2, len(elements), 6, 5))
    force = rng.standard_normal((2, len(elements), 6))
    tangent = rng.standard_normal((2, len(elements), 6, 6))
    np.testing.assert_allclose(ns.project_force(gather, force),
                               np.einsum('seai,sea->si', gather, force), rtol=1e-12)
    np.testing.assert_allclose(ns.project_tangent(gather, tangent, right),
                               np.einsum('seai,seab,sebj->sij', gather, tangent, right),
                               rtol=1e-12, atol=1e-12)
