"""
Dynamic second-order pass (core/fe/second_order_dynamic.py).

Its element loads against closed forms, its quasi-static limit against the loop closure of
core/fe/second_order_geometry.py (Eqs. 3-4), the pass at a low crank speed against the
quasi-static second order, and the interpolation of the linear state. Against the Exudyn peer:
test/studies/test_validation.py.
"""

import dataclasses
import math

from flexlink_ros.core.fe import beam
from flexlink_ros.core.fe import second_order_dynamic as dyn
from flexlink_ros.core.fe.linkage import FlexibleLinkage
from flexlink_ros.core.fe.second_order_full import corrected_response, second_order_outputs
from flexlink_ros.core.fe.simulate import periodic_response
from flexlink_ros.core.fe.stiffness_damping import system_matrices
from flexlink_ros.core.mechanism_file import load_mechanism
from flexlink_ros.core.options import ModelOptions
import numpy as np
import pytest

ELEMENTS = 4


def _linkage(bearings='rigid', gravity=True, rigid_crank=True):
    mech = dataclasses.replace(load_mechanism('cho1992'), elements_per_link=ELEMENTS)
    options = ModelOptions.full_model(rigid_crank=rigid_crank, bearings=bearings,
                                      geometric_stiffness=True, gravity=gravity)
    return FlexibleLinkage(mech, options)


def test_element_loads_of_a_rigidly_rotated_element():
    # v = c x: s = c^2 l / 2, the eigenstrain pulls the ends together by EA c^2 / 2, and
    # G u = c int h' dx = c (0, -1, 0, 0, 1, 0) meets the elastic axial force N_e
    length, slope, axial, tension = 0.05, 2e-3, 3.0e6, 4.0
    local = np.array([[0.0, 0.0, slope, 0.0, slope * length, slope]])
    loads = dyn.element_second_order_loads(local, length, 1, axial, np.array([[tension]]))
    pull = 0.5 * axial * slope ** 2 * np.array([1.0, 0, 0, -1.0, 0, 0])
    geometric = -tension * slope * np.array([0, -1.0, 0, 0, 1.0, 0])
    np.testing.assert_allclose(loads[0], pull + geometric, rtol=1e-12, atol=1e-15)
    unit = beam.beam_geometric_stiffness(1.0, length)
    np.testing.assert_allclose(unit @ local[0], slope * np.array([0, -1.0, 0, 0, 1.0, 0]),
                               atol=1e-15)


@pytest.mark.parametrize('spacing', [2 * math.pi / 24, -2 * math.pi / 24])
def test_periodic_interpolation_reproduces_a_trigonometric_polynomial(spacing):
    start = 0.3
    samples = start + spacing * np.arange(24)
    curve = lambda a: np.stack([np.cos(3 * a) + 0.5, np.sin(7 * a - 0.2)], axis=1)  # noqa
    angles = np.random.default_rng(1).uniform(-4.0, 9.0, 17)
    got = dyn.periodic_interpolation(curve(samples), angles, start, spacing)
    np.testing.assert_allclose(got, curve(angles), atol=1e-12)


@pytest.mark.parametrize('bearings, rigid_crank', [('rigid', True), ('flexible', True),
                                                   ('rigid', False)])
def test_quasi_static_eigenstrain_reproduces_the_loop_closure(bearings, rigid_crank):
    """K U2 = F2 (eigenstrain alone) gives Eqs. (3)-(4): the frame only rotates its links."""
    linkage = _linkage(bearings, gravity=False, rigid_crank=rigid_crank)
    theta = np.array([0.4, 1.9, 4.4])
    state = np.random.default_rng(7).normal(scale=1e-3, size=(theta.size, linkage.size))
    load = dyn.second_order_load(linkage, state, theta, 0.0, include_elastic_force=False)
    stiffness = linkage.assemble(theta).stiffness
    u2 = np.linalg.solve(stiffness, load[..., None])[..., 0]
    outputs = np.einsum('kon,kn->ko', linkage.output_operator(theta), u2)
    expected = second_order_outputs(linkage, state, theta)['outputs']
    assert np.abs(expected).max() > 1e-6
    np.testing.assert_allclose(outputs, expected, rtol=1e-6, atol=1e-6 * np.abs(expected).max())


@pytest.fixture(scope='module')
def slow():
    """Run a slow crank (30 rpm) with gravity: the sag dominates, inertia hardly matters."""
    linkage = _linkage('rigid', gravity=True)
    linear = periodic_response(linkage, 30 * math.pi / 30.0, method='full', steps=240,
                               points=60)
    return linkage, linear


def test_slow_pass_equals_the_quasi_static_second_order(slow):
    linkage, linear = slow
    quasi_static = corrected_response(linkage, linear)['second']
    result = dyn.dynamic_pass(linkage, linear, steps=240)
    scale = np.abs(quasi_static).max(axis=0)
    assert scale.min() > 1e-7
    # measured: 1e-5 (lever tip) and 0.3-0.6 % (coupler mid-point) of each channel's peak
    assert np.max(np.abs(result['second'] - quasi_static).max(axis=0) / scale) < 0.01
    np.testing.assert_allclose(result['total'], result['linear'] + result['second'])
    assert result['displacement'].shape == linear.displacement.shape


def test_pass_with_the_linear_pass_matrices(slow):
    """Beta damping (the linear pass's own matrices): the slow pass is quasi-static too."""
    linkage, _ = slow
    speed = math.pi
    matrices = lambda angles: system_matrices(linkage, angles, speed, 1e-4)  # noqa: E731
    linear = periodic_response(linkage, speed, method='full', steps=240, points=60,
                               matrices=matrices)
    quasi_static = corrected_response(linkage, linear)['second']
    damped = dyn.dynamic_pass(linkage, linear, steps=240, matrices=matrices)
    modal = dyn.dynamic_pass(linkage, linear, steps=240, zeta=0.02)
    scale = np.abs(quasi_static).max(axis=0)
    assert np.max(np.abs(damped['second'] - quasi_static).max(axis=0) / scale) < 0.01
    assert damped['info']['zeta'] is None and modal['info']['zeta'] == 0.02
    assert np.abs(damped['second'] - modal['second']).max() > 0.0


def test_pass_needs_the_full_order_state(slow):
    linkage, _ = slow
    modal = periodic_response(linkage, 3.0, method='modal', modes=4, steps=60, points=30)
    with pytest.raises(ValueError, match='full-order'):
        dyn.dynamic_pass(linkage, modal)
    coarse = periodic_response(linkage, 3.0, method='full', steps=60, points=12)
    with pytest.raises(ValueError, match='output points'):
        dyn.dynamic_pass(linkage, coarse)
