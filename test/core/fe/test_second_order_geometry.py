"""
Second-order geometry (core/fe/second_order_geometry.py), independent checks.

* the FE bending integral against closed forms (half-sine, parabola on part of a link);
* the loop closure against the exact intersection of two circles (third-order agreement).
"""

import math

from flexlink_ros.core.fe import second_order_geometry as so_geometry
from flexlink_ros.core.kinematics import solve_kinematics
from flexlink_ros.core.mechanism_file import load_mechanism
import numpy as np
import pytest


@pytest.fixture(scope='module')
def mech():
    return load_mechanism('cho1992')


def nodal(length, elements, v, slope):
    """Link vector (u, v, phi per node) sampling v(x) and v'(x) at the nodes; u = 0."""
    x = np.linspace(0.0, length, elements + 1)
    out = np.zeros((elements + 1, 3))
    out[:, 1], out[:, 2] = v(x), slope(x)
    return out.ravel()


# -- closed forms ---------------------------------------------------------------------------

def test_half_sine_converges_to_the_closed_form():
    """1/2 int v'^2 of v = a sin(pi x / L) is pi^2 a^2 / (4 L); Hermite cubics converge h^4."""
    length, amp = 0.262, 1e-3
    exact = math.pi ** 2 * amp ** 2 / (4.0 * length)
    errors = []
    for elements in (2, 4, 8, 16):
        g = so_geometry.unit_geometric_stiffness(length / elements, elements)
        u = nodal(length, elements, lambda x: amp * np.sin(np.pi * x / length),
                  lambda x: amp * np.pi / length * np.cos(np.pi * x / length))
        errors.append(abs(so_geometry.bending_integral(u, g) / exact - 1.0))
    assert errors[-1] < 1e-5    # measured: 1.5e-2, 1.0e-3, 6.6e-5, 4.1e-6
    orders = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    assert np.all(orders > 3.5), orders


def test_chord_shortening_removes_the_rigid_rotation():
    """A rigid rotation b and translation added: delta unchanged, S grows by (b L)^2 / (2 L)."""
    length, amp, elements, tilt = 0.24, 2e-3, 8, 3e-3
    g = so_geometry.unit_geometric_stiffness(length / elements, elements)
    bent = nodal(length, elements, lambda x: amp * np.sin(np.pi * x / length),
                 lambda x: amp * np.pi / length * np.cos(np.pi * x / length))
    moved = bent + nodal(length, elements, lambda x: 4e-4 + tilt * x,
                         lambda x: tilt + 0.0 * x)
    delta = so_geometry.chord_shortening(bent, g, length)
    assert so_geometry.chord_shortening(moved, g, length) == pytest.approx(delta, rel=1e-12)
    assert so_geometry.bending_integral(moved, g) == pytest.approx(
        delta + (tilt * length) ** 2 / (2.0 * length), rel=1e-12)
    # a straight, rotated link is not shortened
    straight = nodal(length, elements, lambda x: tilt * x, lambda x: tilt + 0.0 * x)
    assert abs(so_geometry.chord_shortening(straight, g, length)) < 1e-12 * delta


@pytest.mark.parametrize('elements', [3, 4, 5])
def test_partial_integral_is_exact_for_a_parabola(elements):
    """With v = a x^2 (a cubic) G over [0, X] (X inside an element or on a node) is exact."""
    length, amp = 0.262, 0.05
    u = nodal(length, elements, lambda x: amp * x ** 2, lambda x: 2.0 * amp * x)
    for upto in (0.5 * length, 0.3 * length, length):
        g = so_geometry.unit_geometric_stiffness(length / elements, elements, upto)
        assert so_geometry.bending_integral(u, g) == pytest.approx(
            2.0 * amp ** 2 * upto ** 3 / 3.0, rel=1e-12)
    with pytest.raises(ValueError):
        so_geometry.unit_geometric_stiffness(length / elements, elements, 1.1 * length)


# -- loop closure against exact geometry ----------------------------------------------------

def circle_intersection(c1, r1, c2, r2, near):
    """Return the intersection of two circles (complex centres) nearest to ``near``."""
    d = abs(c2 - c1)
    along = (d * d + r1 * r1 - r2 * r2) / (2.0 * d)
    half = math.sqrt(r1 * r1 - along * along)
    unit = (c2 - c1) / d
    points = [c1 + unit * (along + 1j * sign * half) for sign in (1.0, -1.0)]
    return min(points, key=lambda p: abs(p - near))


def loop_errors(mech, theta, scale, with_rotation=True):
    """|exact B - (B0 + b1 + dB)| for linear motions ~scale and shortenings ~scale^2."""
    state = solve_kinematics(mech, np.array([theta]))
    a0, b0, o4 = (state.joints[j][0] for j in ('A', 'B', 'O4'))
    ek, ec, el = np.exp(1j * state.angle[:, 0])
    lk, lc, ll = (mech.links[k].length for k in range(3))
    rng = np.random.default_rng(7)
    a1 = scale * lk * complex(*rng.standard_normal(2))          # linear motion of A
    s_c, s_l = scale * lc * rng.standard_normal(2)               # linear stretches
    # b1 from the linearised constraints e_c.(b1 - a1) = s_c, e_l.b1 = s_l
    b1 = complex(so_geometry.loop_closure_second_order(
        np.array([ec]), np.array([el]), np.array([-(s_c + (np.conj(ec) * a1).real)]),
        np.array([-s_l]))[0])
    d_c, d_l, d_k = scale ** 2 * np.array([lc, ll, lk]) * (1.0 + rng.random(3))
    a2 = -d_k * ek                         # crank pin on its (clamped) crank's frame
    exact = circle_intersection(a0 + a1 + a2, lc + s_c - d_c, o4, ll + s_l - d_l, b0)
    rot_c = ((np.conj(1j * ec) * (b1 - a1)).real) ** 2 / (2.0 * lc) if with_rotation else 0.0
    rot_l = ((np.conj(1j * el) * b1).real) ** 2 / (2.0 * ll) if with_rotation else 0.0
    d_b = so_geometry.loop_closure_second_order(np.array([ec]), np.array([el]),
                                                np.array([d_c + rot_c]), np.array([d_l + rot_l]),
                                                np.array([a2]))[0]
    return abs(exact - (b0 + b1 + d_b)), abs(exact - (b0 + b1))


@pytest.mark.parametrize('theta', [0.3, 1.9, 3.5, 5.2])
def test_loop_closure_is_third_order_against_the_circles(mech, theta):
    """Eq. (3) with S = delta + chord rotation: the residual shrinks 8x per halved scale."""
    errs = [loop_errors(mech, theta, scale) for scale in (2e-3, 1e-3, 5e-4)]
    second = np.array([e[0] for e in errs])
    first = np.array([e[1] for e in errs])
    assert np.all(second < 0.02 * first)
    orders = np.log2(second[:-1] / second[1:])
    assert np.all(orders > 2.7), orders
    # without the chord-rotation term (the simpler delta form) the residual is second order
    bare = np.array([loop_errors(mech, theta, s, with_rotation=False)[0]
                     for s in (2e-3, 1e-3, 5e-4)])
    assert np.all(np.log2(bare[:-1] / bare[1:]) < 2.3)
    assert np.all(bare > 10.0 * second)


def test_output_coefficients_match_the_loop_closure(mech):
    theta = np.linspace(0.0, 2.0 * np.pi, 7)
    kappa = so_geometry.output_coefficients(mech, theta)
    angle = solve_kinematics(mech, theta).angle
    ec, el = np.exp(1j * angle[1]), np.exp(1j * angle[2])
    tip = kappa[:, 0, :] + 1j * kappa[:, 1, :]
    # a unit S_coupler moves B so that e_c.dB = -1 and e_l.dB = 0
    assert np.allclose((np.conj(ec) * tip[:, 1]).real, -1.0)
    assert np.allclose((np.conj(el) * tip[:, 1]).real, 0.0, atol=1e-12)
    # S_coupler(L/2) moves the mid-point straight back along the coupler
    mid_half = kappa[:, 2, 3] + 1j * kappa[:, 3, 3]
    assert np.allclose(mid_half, -ec)
