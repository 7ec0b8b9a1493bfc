"""
Reduced dynamic second-order load (core/reduction/second_order_dynamic_tables.py).

On a constant basis V the tables' load equals V^T of the full-order pass's load
(core/fe/second_order_dynamic.second_order_load) of the state V q, and the rigid-body axial
force they tabulate is linear in w^2 and the crank acceleration.
"""

import dataclasses
import math

from flexlink_ros.core.fe.linkage import FlexibleLinkage
from flexlink_ros.core.fe.second_order_dynamic import second_order_load
from flexlink_ros.core.mechanism_file import load_mechanism
from flexlink_ros.core.options import ModelOptions
from flexlink_ros.core.reduction import second_order_dynamic_tables as dyn
from flexlink_ros.core.validity import rigid_element_axial_forces
import numpy as np
import pytest

GRID = 32


@pytest.fixture(scope='module')
def setup():
    mech = dataclasses.replace(load_mechanism('cho1992'), elements_per_link=3)
    linkage = FlexibleLinkage(mech, ModelOptions.linear(bearings='rigid', elements_per_link=3))
    rng = np.random.default_rng(3)
    basis = rng.standard_normal((linkage.size, 5)) * 1e-2
    return linkage, basis, dyn.DynamicLoad(dyn.build_tables(linkage, basis, GRID))


@pytest.mark.parametrize('include_elastic_force', [True, False])
def test_load_is_the_projected_full_order_load_at_grid_angles(setup, include_elastic_force):
    linkage, basis, load = setup
    speed = 391 * math.pi / 30
    theta = 2.0 * math.pi * np.array([3, 17, 30]) / GRID
    q = np.random.default_rng(4).standard_normal((theta.size, basis.shape[1])) * 1e-2
    full = second_order_load(linkage, q @ basis.T, theta, speed,
                             include_elastic_force=include_elastic_force) @ basis
    mine = np.array([load.load(q[k], theta[k], speed, 0.0)[0 if include_elastic_force else 1]
                     for k in range(theta.size)])
    assert np.abs(full).max() > 0.0
    np.testing.assert_allclose(mine, full, rtol=0, atol=1e-9 * np.abs(full).max())


def test_rigid_axial_force_is_linear_in_speed_squared_and_acceleration(setup):
    linkage = setup[0]
    theta = np.array([0.4, 2.2])
    coef = dyn.rigid_force_coefficients(linkage, theta)
    speed, accel = 30.0, 250.0
    direct = rigid_element_axial_forces(linkage, theta, speed, accel)
    expected = np.concatenate([direct[link] for link in linkage.links], axis=1)
    combined = coef[:, 0] + speed ** 2 * coef[:, 1] + accel * coef[:, 2]
    np.testing.assert_allclose(combined, expected, rtol=1e-9, atol=1e-9 * np.abs(expected).max())


def test_static_reference_replaces_the_rigid_axial_force(setup):
    # With the static state equal to the state itself the elastic axial force is zero: only
    # the eigenstrain remains (the load equals its eigenstrain part).
    linkage, basis, load = setup
    q = np.random.default_rng(5).standard_normal(basis.shape[1]) * 1e-2
    total, eigen = load.load(q, 1.0, 40.0, 0.0, static_q=q)
    np.testing.assert_allclose(total, eigen, rtol=1e-12)
    assert not np.allclose(load.load(q, 1.0, 40.0, 0.0)[0], eigen)
