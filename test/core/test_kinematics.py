"""Rigid-body kinematics against loop closure and finite differences of itself."""

from flexlink_ros.core.kinematics import dead_centres, solve_kinematics
from flexlink_ros.core.mechanism_file import load_mechanism
import numpy as np
import pytest

MECHANISMS = ['cho1992', 'kang1990']


def _motion(t):
    """Return a crank motion with non-zero speed, acceleration and jerk: theta(t), derivatives."""
    theta = 0.3 + 20.0 * t + 40.0 * t ** 2 + 30.0 * t ** 3
    return theta, 20.0 + 80.0 * t + 90.0 * t ** 2, 80.0 + 180.0 * t, 180.0 + 0 * t


@pytest.mark.parametrize('name', MECHANISMS)
def test_loop_closes_with_link_lengths(name):
    mech = load_mechanism(name)
    theta = np.linspace(0, 2 * np.pi, 721)
    state = solve_kinematics(mech, theta)
    g, a, b, c = mech.lengths
    joints = state.joints
    np.testing.assert_allclose(np.abs(joints['A'] - joints['O2']), a, rtol=1e-12)
    np.testing.assert_allclose(np.abs(joints['B'] - joints['A']), b, rtol=1e-12)
    np.testing.assert_allclose(np.abs(joints['B'] - joints['O4']), c, rtol=1e-12)
    assert np.all(joints['B'].imag > 0), 'open branch keeps B above the ground line'
    np.testing.assert_allclose(joints['A'] + b * np.exp(1j * state.angle[1]), joints['B'],
                               atol=1e-14)


@pytest.mark.parametrize('name', MECHANISMS)
def test_rates_match_central_differences(name):
    mech = load_mechanism(name)
    t = np.linspace(0.0, 0.2, 41)
    h = 1e-6
    state = solve_kinematics(mech, *_motion(t))
    plus = solve_kinematics(mech, *_motion(t + h))
    minus = solve_kinematics(mech, *_motion(t - h))
    unwrap = np.angle(np.exp(1j * (plus.angle - minus.angle)))
    np.testing.assert_allclose(state.omega, unwrap / (2 * h), rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(state.alpha, (plus.omega - minus.omega) / (2 * h),
                               rtol=1e-6, atol=1e-4)
    np.testing.assert_allclose(state.jerk, (plus.alpha - minus.alpha) / (2 * h),
                               rtol=1e-6, atol=1e-2)


def test_material_point_motion_matches_differences():
    mech = load_mechanism('cho1992')
    t = np.linspace(0.0, 0.1, 11)
    h = 1e-6
    for link in range(3):
        x, y = 0.6 * mech.links[link].length, 0.01
        now = solve_kinematics(mech, *_motion(t)).point(link, x, y)
        plus = solve_kinematics(mech, *_motion(t + h)).point(link, x, y)
        minus = solve_kinematics(mech, *_motion(t - h)).point(link, x, y)
        for order in range(3):
            numeric = (plus[order] - minus[order]) / (2 * h)
            np.testing.assert_allclose(now[order + 1], numeric,
                                       rtol=1e-6, atol=1e-6 * np.abs(numeric).max())


def test_coupler_end_point_is_joint_b():
    mech = load_mechanism('cho1992')
    state = solve_kinematics(mech, np.linspace(0, 6, 13), 30.0, 5.0)
    coupler_end = state.point(1, mech.links[1].length)
    lever_end = state.point(2, mech.links[2].length)
    for order in range(4):
        np.testing.assert_allclose(coupler_end[order], lever_end[order], atol=1e-9)


@pytest.mark.parametrize('name', MECHANISMS)
def test_dead_centres_are_where_the_lever_stops(name):
    mech = load_mechanism(name)
    for theta in dead_centres(mech):
        state = solve_kinematics(mech, theta, 1.0)
        assert abs(state.omega[2, 0]) < 1e-9
        # crank and coupler collinear
        assert abs(np.sin(state.angle[1, 0] - state.angle[0, 0])) < 1e-9
