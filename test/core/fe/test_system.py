"""
One link's share of each system equation (core/fe/system.py) on a free two-element link.

The link's DOFs are its own: every node carries ground-frame translations (X, Y) and its
rotation phi, so the gather is a rotation per node (built here, not by core.fe.dofs) and
rigid-body motions of the link are simple system vectors.
"""

import math

from flexlink_ros.core.fe import system
from flexlink_ros.core.fe.link import GAUSS_POINTS, link_matrices
import numpy as np
import pytest

E, AREA, SECOND_MOMENT, RHO, LENGTH = 2.0e11, 3.0e-4, 1.0e-9, 7800.0, 0.3
END_MASSES = (0.05, 0.1)
MASS = RHO * AREA * LENGTH + sum(END_MASSES)      # 0.852 kg
ELEMENTS = 2
NODES = ELEMENTS + 1
SIZE = 3 * NODES
ANGLES = np.array([0.0, 0.7, 2.5, -1.9])           # link angles theta_L [rad]


def _link(rho=RHO, end_masses=END_MASSES):
    return link_matrices(E, AREA, SECOND_MOMENT, rho, LENGTH, ELEMENTS, end_masses)


def _rotation_gather(angle):
    """T^T: local (u, v) = R^T (X, Y) at every node, phi as it is; shape (N, 3 (e+1), n)."""
    out = np.zeros((angle.size, SIZE, SIZE))
    for k, a in enumerate(angle):
        rt = np.array([[math.cos(a), math.sin(a)], [-math.sin(a), math.cos(a)]])
        for node in range(NODES):
            out[k, 3 * node:3 * node + 2, 3 * node:3 * node + 2] = rt
            out[k, 3 * node + 2, 3 * node + 2] = 1.0
    return out


def _gathers(angle, h=1e-4):
    """T^T and its first two derivatives in theta_L by central differences."""
    t0 = _rotation_gather(angle)
    plus, minus = _rotation_gather(angle + h), _rotation_gather(angle - h)
    return t0, (plus - minus) / (2.0 * h), (plus - 2.0 * t0 + minus) / (h * h)


def _translation(dx, dy):
    vector = np.zeros(SIZE)
    vector[0::3], vector[1::3] = dx, dy
    return vector


def _rotation(angle):
    """Small rigid rotation (unit rate) about node 0 of a link along ``angle``."""
    vector = np.zeros(SIZE)
    for node in range(NODES):
        x = node * LENGTH / ELEMENTS
        vector[3 * node], vector[3 * node + 1] = -x * math.sin(angle), x * math.cos(angle)
        vector[3 * node + 2] = 1.0
    return vector


def test_system_mass_is_symmetric_positive_definite_and_carries_the_links_mass():
    mass = system.system_mass(_rotation_gather(ANGLES), _link())
    assert mass.shape == (ANGLES.size, SIZE, SIZE)
    assert np.allclose(mass, np.swapaxes(mass, 1, 2), rtol=0, atol=1e-15)
    assert np.all(np.linalg.eigvalsh(mass) > 0.0)
    for r in (_translation(1.0, 0.0), _translation(0.0, 1.0), _translation(0.6, 0.8)):
        # a rigid translation moves the whole mass, whatever the link's direction
        assert np.allclose(r @ mass @ r, MASS, rtol=1e-12)


def test_system_stiffness_has_the_rigid_motions_in_its_null_space():
    stiffness = system.system_stiffness(_rotation_gather(ANGLES), _link())
    assert np.allclose(stiffness, np.swapaxes(stiffness, 1, 2))
    scale = np.abs(stiffness).max()
    for k, angle in enumerate(ANGLES):
        for r in (_translation(1.0, 0.0), _translation(0.0, 1.0), _rotation(angle)):
            assert np.abs(stiffness[k] @ r).max() < 1e-9 * scale
    # and it is not zero: a uniform stretch by 1 m stores the bar's energy E A / L
    stretch = np.zeros(SIZE)
    fraction = np.arange(NODES) / ELEMENTS
    stretch[0::3], stretch[1::3] = fraction * math.cos(ANGLES[0]), fraction * math.sin(ANGLES[0])
    assert stretch @ stiffness[0] @ stretch == pytest.approx(E * AREA / LENGTH, rel=1e-9)


def test_gyroscopic_part_is_skew_symmetric_and_centrifugal_part_softens():
    """In the link's own frame (T = I, T' = 0): C1 = 2 g1 M_s, Kw2 = -g1^2 M (g2 = 0)."""
    link = _link()
    identity = np.broadcast_to(np.eye(SIZE), (1, SIZE, SIZE))
    zero = np.zeros_like(identity)
    p1, p2 = np.full((1, 1, 1), 1.7), np.zeros((1, 1, 1))
    transport = system.transport_matrix(identity, zero, link)
    damping = system.convective_damping(p1, transport)[0]
    assert np.abs(damping).max() > 0.0
    assert np.allclose(damping, -damping.T, rtol=0, atol=1e-15)
    mass = system.system_mass(identity, link)
    coupling = system.convective_stiffness(identity, zero, zero, link, p1, p2, transport, mass)
    assert np.allclose(coupling['a'][0], -coupling['a'][0].T, rtol=0, atol=1e-15)
    softening = coupling['w2'][0]
    assert np.allclose(softening, softening.T) and np.all(np.linalg.eigvalsh(softening) < 0.0)
    # the ground-frame gather keeps the skew part skew
    t0 = _rotation_gather(ANGLES)
    skew = system.transport_matrix(t0, np.zeros_like(t0), link)
    assert np.allclose(skew, -np.swapaxes(skew, 1, 2), rtol=0, atol=1e-15)


def test_point_masses_on_ground_frame_nodes_feel_no_apparent_forces():
    """Massless beam, point masses at the ends: C1, Ka and Kw2 vanish in the ground frame."""
    link = _link(rho=0.0, end_masses=(0.3, 0.5))
    t0, t1, t2 = _gathers(ANGLES)
    p1 = np.array([1.0, -0.4, 2.0, 0.3])[:, None, None]
    p2 = np.array([0.5, 1.5, -2.0, 0.0])[:, None, None]
    mass = system.system_mass(t0, link)
    transport = system.transport_matrix(t0, t1, link)
    assert np.abs(system.convective_damping(p1, transport)).max() < 1e-6
    coupling = system.convective_stiffness(t0, t1, t2, link, p1, p2, transport, mass)
    assert np.abs(coupling['a']).max() < 1e-6 and np.abs(coupling['w2']).max() < 1e-6
    # while the mass they carry is there
    assert np.allclose(_translation(1.0, 0.0) @ mass @ _translation(1.0, 0.0), 0.8)


def test_gravity_load_is_the_weight_and_rigid_accelerations_load_by_dalembert():
    link = _link()
    t0 = _rotation_gather(ANGLES)
    zero = np.zeros((ANGLES.size, NODES), dtype=complex)
    load = system.system_load(t0, link, ANGLES, complex(0.0, -9.81),
                              {'a': np.full_like(zero, 2.0 + 3.0j), 'w2': zero})
    assert set(load) == set(system.PIECES)
    weight = load['1']
    assert np.allclose(weight[:, 1::3].sum(axis=1), -9.81 * MASS, rtol=1e-12)
    assert np.allclose(weight[:, 0::3].sum(axis=1), 0.0, atol=1e-12)
    assert np.allclose(load['w2'], 0.0)
    # a uniform rigid acceleration (2, 3) m/s^2 of every node: load -m (2, 3)
    assert np.allclose(load['a'][:, 0::3].sum(axis=1), -2.0 * MASS, rtol=1e-12)
    assert np.allclose(load['a'][:, 1::3].sum(axis=1), -3.0 * MASS, rtol=1e-12)


def test_geometric_stiffness_is_symmetric_linear_and_a4_for_constant_tension():
    link = _link()
    identity = np.broadcast_to(np.eye(SIZE), (1, SIZE, SIZE))
    rng = np.random.default_rng(5)
    f1, f2 = rng.normal(size=(2, 1, ELEMENTS, GAUSS_POINTS)) * 100.0
    pieces = system.geometric_stiffness(identity, link, {'1': f1, 'a': f2, 'w2': f1 - 3.0 * f2})
    for value in pieces.values():
        assert np.allclose(value, np.swapaxes(value, 1, 2), rtol=0, atol=1e-12)
    assert np.allclose(pieces['w2'], pieces['1'] - 3.0 * pieces['a'], rtol=0, atol=1e-10)
    # constant tension F on each element: the textbook A.4 matrix on (v1, phi1, v2, phi2)
    force, le = 250.0, LENGTH / ELEMENTS
    constant = np.full((1, ELEMENTS, GAUSS_POINTS), force)
    kg = system.geometric_stiffness(identity, link, dict.fromkeys(system.PIECES, constant))['1'][0]
    a4 = force / (30.0 * le) * np.array([[36.0, 3 * le, -36.0, 3 * le],
                                         [3 * le, 4 * le * le, -3 * le, -le * le],
                                         [-36.0, -3 * le, 36.0, -3 * le],
                                         [3 * le, -le * le, -3 * le, 4 * le * le]])
    first = [1, 2, 4, 5]
    expected = np.zeros((SIZE, SIZE))
    for e in range(ELEMENTS):
        rows = [3 * e + i for i in first]
        expected[np.ix_(rows, rows)] += a4
    assert np.allclose(kg, expected, rtol=1e-12, atol=1e-9)
    assert np.all(kg[0::3] == 0.0)        # axial DOFs u take no geometric stiffness
