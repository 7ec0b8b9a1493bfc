"""
The co-rotational element force and tangent (core/fe/corotational_strain.py).

To first order it is the element stiffness A.3; it is the gradient of its strain energy plus
Kelvin-Voigt damping; both tangents equal finite differences; a rigid turn of an element by
any angle strains nothing and, at any rate, dissipates nothing (the von Karman strain:
-phi^4/8 and O(phi^4 phi'^2)).
"""

import dataclasses

from flexlink_ros.core.fe import corotational_strain as cr
from flexlink_ros.core.fe import nonlinear_strain as ns
from flexlink_ros.core.fe.linkage import FlexibleLinkage
from flexlink_ros.core.mechanism_file import load_mechanism
from flexlink_ros.core.options import ModelOptions
import numpy as np
import pytest

BETA = 1e-4


@pytest.fixture(scope='module')
def elements():
    mech = dataclasses.replace(load_mechanism('cho1992'), elements_per_link=3)
    return ns.model_elements(FlexibleLinkage(mech, ModelOptions.full_model(rigid_crank=False)))


def _state(elements, scale=2e-3, seed=1):
    """Element coordinates and rates of a bent, stretched state (slopes of order 0.04 rad)."""
    rng = np.random.default_rng(seed)
    q = scale * rng.standard_normal((len(elements), 6))
    q[:, [2, 5]] *= 20.0
    q[:, [0, 3]] *= 0.05
    return q, 50.0 * scale * rng.standard_normal((len(elements), 6))


def _rigid_turn(length, phi):
    """Element coordinates of a rigid turn by phi about the first node, and d/dphi."""
    q = np.array([0.0, 0.0, phi, length * (np.cos(phi) - 1.0), length * np.sin(phi), phi])
    dq = np.array([0.0, 0.0, 1.0, -length * np.sin(phi), length * np.cos(phi), 1.0])
    return q, dq


def test_small_motion_force_is_the_linear_element_force(elements):
    q, rate = _state(elements, scale=1e-8)
    force, axial = cr.element_force(elements, q, rate, BETA)
    linear, linear_axial = ns.element_force(elements, q, rate, BETA, nonlinear=False)
    np.testing.assert_allclose(force, linear, rtol=0, atol=1e-6 * np.abs(linear).max())
    np.testing.assert_allclose(axial, linear_axial, rtol=0, atol=1e-4 * np.abs(linear_axial).max())


def test_second_order_strain_is_the_von_karman_strain(elements):
    q, _ = _state(elements, scale=1e-4)
    corotational = cr.element_strain(elements, q)
    von_karman = ns.element_strain(elements, q)
    shortening = von_karman - ns.element_strain(elements, q, nonlinear=False)
    # the two differ at fourth order: far below the second-order shortening itself
    assert np.abs(corotational - von_karman).max() < 1e-3 * np.abs(shortening).max()


def test_force_is_the_gradient_of_the_strain_energy(elements):
    q, rate = _state(elements)
    force, _ = cr.element_force(elements, q, rate, 0.0)
    step = 1e-7
    gradient = np.zeros_like(q)
    for e in range(len(elements)):
        for a in range(6):
            dq = np.zeros_like(q)
            dq[e, a] = step
            gradient[e, a] = 0.5 * (cr.strain_energy(elements, q + dq)
                                    - cr.strain_energy(elements, q - dq)) / step
    np.testing.assert_allclose(force, gradient, rtol=1e-5, atol=1e-6 * np.abs(force).max())


@pytest.mark.parametrize('turn', [0.0, 0.3])
def test_tangents_equal_finite_differences(elements, turn):
    q, rate = _state(elements)
    q[:, [2, 5]] += turn                      # a large rotation against the link frame too
    stiffness, damping = cr.element_tangent(elements, q, rate, BETA)
    step = 1e-7
    for which, tangent in ((0, stiffness), (1, damping)):
        numeric = np.zeros_like(tangent)
        for b in range(6):
            delta = np.zeros_like(q)
            delta[:, b] = step
            args_plus = (q + delta, rate) if which == 0 else (q, rate + delta)
            args_minus = (q - delta, rate) if which == 0 else (q, rate - delta)
            plus, _ = cr.element_force(elements, *args_plus, BETA)
            minus, _ = cr.element_force(elements, *args_minus, BETA)
            numeric[..., b] = 0.5 * (plus - minus) / step
        np.testing.assert_allclose(tangent, numeric, rtol=1e-5,
                                   atol=1e-6 * np.abs(tangent).max())


def test_rigid_turn_strains_and_dissipates_nothing(elements):
    length, rate = elements.length[0], 3.0
    scale = BETA * elements.axial_stiffness[0] * length * rate ** 2
    for phi in (0.0, 0.2, 1.0, 2.5):
        q, dq = _rigid_turn(length, phi)
        qs = np.broadcast_to(q, (len(elements), 6))
        rates = np.broadcast_to(rate * dq, (len(elements), 6))
        assert abs(cr.element_strain(elements, qs)[0]) < 1e-15
        damped, _ = cr.element_force(elements, qs, rates, BETA)
        elastic, _ = cr.element_force(elements, qs, rates, 0.0)
        assert np.abs(elastic[0]).max() < 1e-9 * elements.axial_stiffness[0]
        assert abs(np.sum((damped - elastic)[0] * rates[0])) < 1e-12 * scale
    # the von Karman strain of the same turn is not zero
    q, _ = _rigid_turn(length, 0.2)
    assert ns.element_strain(elements, q[None])[0] < -1e-4
