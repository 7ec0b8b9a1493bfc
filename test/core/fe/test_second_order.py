"""
Second-order outputs (core/fe/second_order_*.py, issue 14 item 1), independent checks.

* the FE bending integral against closed forms (half-sine, parabola on part of a link);
* the loop closure against the exact intersection of two circles (third-order agreement);
* the quasi-static formulas against the geometrically exact Exudyn peer's static sag;
* the quadratic form on a reduced basis against the full-order computation on V q;
* linear + second order against the peer at 269 rpm (4 elements per link).
"""

import dataclasses
import math

from flexlink_ros.core.fe import linkage as assembly
from flexlink_ros.core.fe import second_order_full as so_full
from flexlink_ros.core.fe import second_order_geometry as so_geometry
from flexlink_ros.core.fe import second_order_reduced as so_reduced
from flexlink_ros.core.kinematics import solve_kinematics
from flexlink_ros.core.mechanism import load_mechanism
from flexlink_ros.core.reduction import model as reduced
from flexlink_ros.studies import peer_exudyn as peer
import numpy as np
import pytest

needs_exudyn = pytest.mark.skipif(
    not peer.exudyn_available(),
    reason=f'exudyn is not installed (pip install {peer.EXUDYN_REQUIREMENT})')

ELEMENTS = 4


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
    # without the chord-rotation term (the delta form) the residual is second order
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


# -- reduced basis ----------------------------------------------------------------------------

@pytest.mark.parametrize('options', [
    reduced.ModelOptions(grid_size=8, bearings='rigid', elements_per_link=ELEMENTS),
    reduced.ModelOptions(grid_size=8, bearings='flexible', rigid_crank=False,
                         elements_per_link=3, modes=24, static=2)], ids=['rigid', 'flexible'])
def test_quadratic_form_equals_the_full_order_on_v_q(mech, options):
    samples = reduced.frozen_samples_for(mech, options)
    basis, _ = reduced.build_basis(samples, options.modes, options.static,
                                   np.linspace(0.0, 60.0, 2))
    linkage = assembly.FlexibleLinkage(reduced.fe_mechanism(mech, options),
                                       options)
    theta = np.linspace(0.0, 2.0 * np.pi, 9, endpoint=False) + 0.2
    q = np.random.default_rng(3).standard_normal((theta.size, basis.shape[1])) * 1e-4
    full = so_full.second_order_outputs(linkage, q @ basis.T, theta)['outputs']
    tables = so_reduced.quadratic_tables(linkage, basis, theta)
    scale = np.abs(full).max()
    assert scale > 0.0
    np.testing.assert_allclose(so_reduced.reduced_second_order(tables, q), full, rtol=0,
                               atol=1e-13 * scale)
    assert np.allclose(tables['Q'], np.swapaxes(tables['Q'], -1, -2))
    factored = so_reduced.factored_forms(linkage, basis)
    np.testing.assert_allclose(so_reduced.factored_second_order(factored, mech, theta, q), full,
                               rtol=0, atol=1e-13 * scale)
    cost = so_reduced.step_cost(factored, basis.shape[1])
    assert cost['factored'] < cost['tables']


# -- against the nonlinear peer ---------------------------------------------------------------

@needs_exudyn
@pytest.mark.parametrize('theta', [0.5, 2.0])
def test_static_sag_second_order_matches_the_peer(mech, theta):
    """
    Quasi-static second-order sag matches the geometrically exact peer.

    Quasi-static: under 2 and 4 g the peer's lever tip and coupler mid-point minus the linear
    sag are the second-order parts of Eqs. (3)-(4); what is left is third order (halves with g).
    """
    misfit = {}
    for factor in (2.0, 4.0):
        heavy = dataclasses.replace(mech, gravity=(0.0, -9.81 * factor))
        exact = peer.peer_static(heavy, theta, elements_per_link=ELEMENTS)
        linkage = peer.linear_model(heavy, elements_per_link=ELEMENTS, gravity=True)
        angle = np.array([theta])
        system = linkage.assemble(angle)
        u = np.linalg.solve(system.frozen_stiffness(0.0)[0], system.load_at(0.0)[0])[None]
        linear = linkage.output_operator(angle)[0] @ u[0]
        second = so_full.second_order_outputs(linkage, u, angle)['outputs'][0]
        rest = np.array([exact[k] for k in peer.OUTPUT_KEYS]) - linear
        tip, mid = complex(*(rest[:2] - second[:2])), complex(*(rest[2:] - second[2:]))
        misfit[factor] = (abs(tip) / abs(complex(*second[:2])),
                          abs(mid) / abs(complex(*second[2:])))
    # measured at 2 g: 0.012-0.013 % (tip), 2.2-2.8 % (mid); at 4 g: 0.04 %, 4.3-5.6 %
    assert misfit[2.0][0] < 0.01 and misfit[2.0][1] < 0.04, misfit
    assert misfit[2.0][1] < 0.65 * misfit[4.0][1], misfit


@needs_exudyn
def test_269rpm_linear_plus_second_order_matches_the_peer(mech):
    """Rigid crank and bearings, no gravity, 4 elements: lever tip 10 %, mid-point 3 % p2p."""
    from flexlink_ros.core.fe.simulate import periodic_response
    response = peer.peer_response(mech, 269.0, elements_per_link=ELEMENTS, gravity=False)
    linkage = peer.linear_model(mech, elements_per_link=ELEMENTS, gravity=False)
    linear = periodic_response(linkage, 269.0 * math.pi / 30.0, method='full', points=360)
    corrected = so_full.corrected_response(linkage, linear)
    assert np.allclose(corrected['total'], corrected['linear'] + corrected['second'])
    before = peer.compare(response, dict(crank_angle=linear.crank_angle,
                                         **dict(zip(peer.OUTPUT_KEYS, linear.outputs.T))))
    after = peer.compare(response, dict(crank_angle=linear.crank_angle,
                                        **dict(zip(peer.OUTPUT_KEYS, corrected['total'].T))))
    for key in ('lever_tip_dx', 'lever_tip_dy'):
        assert before[key]['p2p_error'] < -0.8, (key, before[key])       # linear: -89/-98 %
        assert abs(after[key]['p2p_error']) < 0.10, (key, after[key])   # measured -2/-4 %
    for key in ('coupler_mid_dx', 'coupler_mid_dy'):
        assert abs(after[key]['p2p_error']) < 0.03, (key, after[key])   # measured +0.7 %
        assert after[key]['rms_error'] < 0.03, (key, after[key])
    # joint B moves inward along both links: the chords only shorten
    assert np.all(corrected['detail']['chord'][:, 1:] >= 0.0)


@pytest.mark.skipif(not (__import__('shutil').which('cc') or __import__('shutil').which('gcc')),
                    reason='no C compiler')
def test_compiled_factored_kernel_agrees_and_is_timed(mech):
    """
    The C kernel of the factored form agrees and is fast.

    The C kernel of studies/second_order_bench.py equals factored_second_order (checked
    inside time_factored) and takes well under the issue's 2 us per sample (r = 26: 0.7 us).
    """
    from flexlink_ros.studies import second_order_bench
    ns = second_order_bench.time_factored(mech, 'flexible', False, 26, samples=2000, repeat=5)
    assert 0.0 < ns < 20000.0


def test_reduced_model_second_order_follows_the_full_order(mech):
    """
    The default reduced basis streams the second order of the full order.

    The default reduced basis (r = 6, rigid bearings) as the estimator streams it: linear +
    second order within 1 % of the full order's p2p (measured 0.1-0.2 % at 8 elements).
    """
    from flexlink_ros.core.fe.simulate import periodic_response
    from flexlink_ros.studies import second_order_study
    angles, streamed, size = second_order_study.reduced_response(
        mech, 269.0, True, ELEMENTS, points=120, grid=64)
    assert size == 6
    linkage = peer.linear_model(mech, elements_per_link=ELEMENTS, gravity=True)
    full = so_full.corrected_response(
        linkage, periodic_response(linkage, 269.0 * math.pi / 30.0, method='full',
                                   points=120))
    assert np.allclose(full['crank_angle'], angles)
    span = np.ptp(full['total'], axis=0)
    assert np.all(np.ptp(streamed - full['total'], axis=0) < 0.01 * span)
    assert np.ptp(full['second'][:, 0]) > 5.0 * np.ptp(full['linear'][:, 0])
