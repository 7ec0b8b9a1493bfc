"""Newton-Euler dynamics against balances, energy, hand statics and finite differences."""

import dataclasses

from flexlink_ros.core.dynamics import (axial_force, mechanical_energy, reaction_pieces,
                                        solve_dynamics)
from flexlink_ros.core.kinematics import solve_kinematics
from flexlink_ros.core.mechanism import Spring
from flexlink_ros.core.mechanism_file import load_mechanism
from flexlink_ros.names import JOINT_NAMES
import numpy as np
import pytest


@pytest.fixture(scope='module')
def rich():
    """Cho 1992 with gravity, unequal joint-mass split and a pre-loaded coupler-lever spring."""
    cho = load_mechanism('cho1992')
    return dataclasses.replace(cho, joint_mass_split=0.3, gravity=(1.7, -9.81),
                               spring=Spring(stiffness=3.5, theta0=np.radians(250.0)))


@pytest.fixture(scope='module')
def kang():
    return load_mechanism('kang1990')


def _motion(t):
    """Crank motion with speed, acceleration and jerk: theta, w, a, j at times t."""
    return (0.4 + 30.0 * t + 150.0 * t ** 2 + 400.0 * t ** 3, 30.0 + 300.0 * t + 1200.0 * t ** 2,
            300.0 + 2400.0 * t, 2400.0 + 0.0 * t)


def _state(mech, t):
    return solve_kinematics(mech, *_motion(np.atleast_1d(t)))


def test_every_link_body_balances_forces_and_moments(rich):
    t = np.linspace(0.0, 0.15, 23)
    state = _state(rich, t)
    result = solve_dynamics(rich, state)
    g = complex(*rich.gravity)
    # joint centres recomputed from the joint positions and link rates, independently
    ends = {0: (state.joints['O2'], state.joints['A']), 1: (state.joints['A'], state.joints['B']),
            2: (state.joints['O4'], state.joints['B'])}
    spring = result.spring_torque
    body_torque = {0: result.input_torque, 1: -spring, 2: spring}
    for link, body in enumerate(rich.links):
        first, second = ends[link]
        centre = 0.5 * (first + second)
        _, _, accel, _ = state.point(link, 0.5 * body.length)
        p1, p2 = result.end_forces[link]
        np.testing.assert_allclose(p1 + p2 + body.mass * g, body.mass * accel,
                                   atol=1e-9 * np.abs(p1).max())
        moment = (np.imag(np.conj(first - centre) * p1) + np.imag(np.conj(second - centre) * p2)
                  + body_torque[link])
        np.testing.assert_allclose(moment, body.inertia * state.alpha[link],
                                   atol=1e-9 * np.abs(result.input_torque).max())


def test_each_joint_particle_balances_and_split_moves_only_the_bearing_force(rich):
    # The whole joint mass: forces of its members' bars on it, plus weight, give m a. The
    # pin-on-bar forces do not depend on how the mass is split; the bearing force shifts by
    # exactly the share moved across the bearing.
    t = np.array([0.0, 0.07])
    state = _state(rich, t)
    results = {s: solve_dynamics(dataclasses.replace(rich, joint_mass_split=s), state)
               for s in (0.0, 0.3, 1.0)}
    g = complex(*rich.gravity)
    accel = {'A': state.point(0, rich.links[0].length)[2],
             'B': state.point(2, rich.links[2].length)[2]}
    for split, result in results.items():
        for joint, (bar_first, bar_second) in {'A': ((0, 1), (1, 0)),
                                               'B': ((1, 1), (2, 1))}.items():
            on_first = result.end_forces[bar_first[0]][bar_first[1]]
            on_second = result.end_forces[bar_second[0]][bar_second[1]]
            mass = rich.joint_masses[joint]
            np.testing.assert_allclose(-on_first - on_second + mass * g, mass * accel[joint],
                                       atol=1e-10)
            shift = result.reaction(joint) - results[0.0].reaction(joint)
            np.testing.assert_allclose(shift, split * mass * (g - accel[joint]), atol=1e-10)
        for link in range(3):
            for end in range(2):
                np.testing.assert_allclose(result.end_forces[link][end],
                                           results[0.0].end_forces[link][end], atol=1e-10)


def test_whole_mechanism_balance_with_ground_reactions(rich):
    # External forces on the moving system: ground on crank at O2, ground on lever at O4
    # (= -F_O4 in the first-on-second convention), weights; total force = sum m a.
    state = _state(rich, np.linspace(0.0, 0.1, 5))
    result = solve_dynamics(rich, state)
    g = complex(*rich.gravity)
    inertia = 0.0
    weight = 0.0
    for link, body in enumerate(rich.links):
        inertia = inertia + body.mass * state.point(link, 0.5 * body.length)[2]
        weight += body.mass * g
    s = rich.joint_mass_split
    masses = rich.joint_masses
    inertia = inertia + masses['A'] * state.point(0, rich.links[0].length)[2]
    inertia = inertia + masses['B'] * state.point(2, rich.links[2].length)[2]
    weight += (masses['A'] + masses['B'] + (1 - s) * masses['O2'] + s * masses['O4']) * g
    np.testing.assert_allclose(result.reaction('O2') - result.reaction('O4') + weight, inertia,
                               atol=1e-10)


def test_rates_match_central_differences_in_time(rich):
    h = 1e-6
    t = np.linspace(0.0, 0.15, 11)
    result = solve_dynamics(rich, _state(rich, t))
    plus = solve_dynamics(rich, _state(rich, t + h))
    minus = solve_dynamics(rich, _state(rich, t - h))
    scale = np.abs(result.force_rate).max()
    np.testing.assert_allclose(result.force_rate, (plus.force - minus.force) / (2 * h),
                               atol=2e-7 * scale)
    np.testing.assert_allclose(result.input_torque_rate,
                               (plus.input_torque - minus.input_torque) / (2 * h),
                               atol=2e-7 * np.abs(result.input_torque_rate).max())
    np.testing.assert_allclose(result.spring_torque_rate,
                               (plus.spring_torque - minus.spring_torque) / (2 * h),
                               atol=1e-6 * np.abs(result.spring_torque_rate).max())


def test_input_power_equals_rate_of_mechanical_energy(rich):
    # T_in w = d/dt (kinetic + gravity + spring energy); the energy rate itself is checked
    # against a central difference of the energy.
    t = np.linspace(0.0, 0.15, 31)
    state = _state(rich, t)
    result = solve_dynamics(rich, state)
    energy, energy_rate = mechanical_energy(rich, state)
    h = 1e-6
    fd = (mechanical_energy(rich, _state(rich, t + h))[0]
          - mechanical_energy(rich, _state(rich, t - h))[0]) / (2 * h)
    np.testing.assert_allclose(energy_rate, fd, atol=1e-6 * np.abs(energy_rate).max())
    power = result.input_torque * state.omega[0]
    np.testing.assert_allclose(power, energy_rate, atol=1e-10 * np.abs(power).max())


def test_static_gravity_by_hand(kang):
    # At rest under gravity (no joint masses): coupler and lever moments about A and O4 give
    # the pin force at B; force balances give the rest; the crank's moment gives T_in.
    mech = dataclasses.replace(kang, gravity=(0.0, -9.81))
    theta = np.radians([0.0, 77.0, 200.0, 311.0])
    state = solve_kinematics(mech, theta)
    result = solve_dynamics(mech, state)
    w0, w1, w2 = (body.mass * -9.81j for body in mech.links)
    for k in range(theta.size):
        a, b, o4 = (state.joints[j][k] for j in ('A', 'B', 'O4'))
        cross = lambda r, f: r.real * f.imag - r.imag * f.real  # noqa: E731
        # unknown F_B = (X, Y), coupler on lever:
        # coupler about A: (b - a) x (-F_B) + ((b - a) / 2) x w1 = 0
        # lever about O4:  (b - o4) x F_B + ((b - o4) / 2) x w2 = 0
        rows = np.array([[(b - a).imag, -(b - a).real], [-(b - o4).imag, (b - o4).real]])
        rhs = np.array([-cross((b - a) / 2, w1), -cross((b - o4) / 2, w2)])
        fx, fy = np.linalg.solve(rows, rhs)
        f_b = fx + 1j * fy
        f_a = f_b - w1
        f_o4 = f_b + w2
        f_o2 = f_a - w0
        torque = cross(a, f_a) - cross(a / 2, w0)
        expected = np.array([f_o2, f_a, f_b, f_o4])
        np.testing.assert_allclose(result.force[:, k], expected, atol=1e-12)
        assert result.input_torque[k] == pytest.approx(torque, abs=1e-13)
    # the whole weight goes to the two ground pins
    total = sum(body.mass for body in mech.links) * 9.81
    np.testing.assert_allclose((result.reaction('O2') - result.reaction('O4')).imag, total)


def test_pieces_rebuild_the_reactions_and_their_rates(rich):
    rng = np.random.default_rng(3)
    theta = 2 * np.pi * rng.random(9)
    w, a = 35.0 * rng.standard_normal(9), 500.0 * rng.standard_normal(9)
    pieces = reaction_pieces(rich, theta)
    force, rate = pieces['force'], pieces['force_rate']
    direct = solve_dynamics(rich, solve_kinematics(rich, theta, w, a))
    rebuilt = force['1'] + a[:, None, None] * force['a'] + (w ** 2)[:, None, None] * force['w2']
    scale = np.abs(direct.force_xy()).max()
    np.testing.assert_allclose(rebuilt, direct.force_xy(), atol=1e-11 * scale)
    dtheta = rate['1'] + a[:, None, None] * rate['a'] + (w ** 2)[:, None, None] * rate['w2']
    dt = w[:, None, None] * dtheta + 2 * (w * a)[:, None, None] * force['w2']
    np.testing.assert_allclose(dt, direct.force_rate_xy(),
                               atol=1e-11 * np.abs(direct.force_rate_xy()).max())
    torque = pieces['torque']['1'] + a * pieces['torque']['a'] + w ** 2 * pieces['torque']['w2']
    np.testing.assert_allclose(torque, direct.input_torque, atol=1e-11 * scale)
    assert set(force) == set(rate) == {'1', 'a', 'w2'}
    assert force['1'].shape == (9, len(JOINT_NAMES), 2)


def test_piece_angle_derivatives_match_central_differences(rich):
    theta = np.linspace(0.1, 6.0, 13)
    h = 1e-6
    rate = reaction_pieces(rich, theta)['force_rate']
    plus, minus = reaction_pieces(rich, theta + h), reaction_pieces(rich, theta - h)
    for piece in ('1', 'a', 'w2'):
        fd = (plus['force'][piece] - minus['force'][piece]) / (2 * h)
        np.testing.assert_allclose(rate[piece], fd, atol=1e-6 * np.abs(rate[piece]).max(),
                                   err_msg=piece)


def test_axial_force_meets_the_end_forces(rich):
    # N(0) = -P_first . e and N(L) = +P_second . e: the integrated distributed inertia and
    # weight balance the axial end forces.
    state = _state(rich, np.linspace(0.0, 0.1, 7))
    result = solve_dynamics(rich, state)
    for link, body in enumerate(rich.links):
        tension = axial_force(rich, state, link, np.array([0.0, 0.3, body.length]))
        assert tension.shape == (7, 3)
        axis = np.exp(1j * state.angle[link])
        first, second = result.end_forces[link]
        along = lambda f: f.real * axis.real + f.imag * axis.imag  # noqa: E731
        np.testing.assert_allclose(tension[:, 0], -along(first), atol=1e-12)
        np.testing.assert_allclose(tension[:, 2], along(second),
                                   atol=1e-9 * np.abs(tension).max())
    with pytest.raises(ValueError, match='link'):
        axial_force(rich, state, 3, np.array([0.0]))


def test_spring_torque_sign_is_minus_gradient_of_its_energy(kang):
    # At rest without gravity the motor holds the spring: T_in = dV/dtheta of V = K s^2 / 2
    # (central difference in the crank angle).
    mech = dataclasses.replace(kang, spring=Spring(stiffness=20.0, theta0=np.radians(279.14)))
    theta = np.radians(np.arange(0.0, 360.0, 30.0))
    h = 1e-6
    torque = solve_dynamics(mech, solve_kinematics(mech, theta)).input_torque
    energy = lambda th: mechanical_energy(mech, solve_kinematics(mech, th))[0]  # noqa: E731
    np.testing.assert_allclose(torque, (energy(theta + h) - energy(theta - h)) / (2 * h),
                               rtol=1e-6, atol=1e-9)
    assert np.abs(torque).max() > 0.1
