"""Radau IIA for M(t) q'' + C(t) q' + K(t) q = f(t): exact solutions, order, stability."""

from flexlink_ros.core.integrators import (compose_affine, integrate, RadauIIA, stability_function,
                                           step_maps)
import numpy as np
import pytest
from scipy.integrate import solve_ivp

OMEGA = 2.0 * np.pi * 3.0   # natural frequency [rad/s]
ZETA = 0.05


def sdof(t):
    """Damped oscillator q'' + 2 zeta w q' + w^2 q = 0."""
    return (np.eye(1), np.array([[2.0 * ZETA * OMEGA]]), np.array([[OMEGA ** 2]]), np.zeros(1))


def sdof_exact(t, q0=1.0, v0=0.0):
    """Closed-form free response of the damped oscillator."""
    wd = OMEGA * np.sqrt(1.0 - ZETA ** 2)
    return np.exp(-ZETA * OMEGA * t) * (
        q0 * np.cos(wd * t) + (v0 + ZETA * OMEGA * q0) / wd * np.sin(wd * t))


def jittered_times(h, end, jitter, seed):
    """Return times 0..end with steps h (1 + jitter U(-1, 1))."""
    rng = np.random.default_rng(seed)
    steps = h * (1.0 + jitter * rng.uniform(-1.0, 1.0, int(2 * end / h) + 10))
    times = np.concatenate([[0.0], np.cumsum(steps)])
    return times[times <= end]


def observed_orders(stages, jitter):
    errors, sizes = [], [8e-3, 4e-3, 2e-3, 1e-3]
    for h in sizes:
        times = jittered_times(h, 1.0, jitter, seed=int(1e6 * h)) if jitter else \
            np.arange(0.0, 1.0 + 1e-12, h)
        q, _ = integrate(sdof, times, [1.0], [0.0], stages=stages)
        errors.append(np.max(np.abs(q[:, 0] - sdof_exact(times))))
    return np.log2(np.array(errors[:-1]) / np.array(errors[1:])), errors


@pytest.mark.parametrize('jitter', [0.0, 0.5])
def test_two_stage_is_third_order_with_and_without_jitter(jitter):
    orders, errors = observed_orders(2, jitter)
    assert np.all(orders > 2.7), orders
    assert errors[-1] < 2e-6


def test_three_stage_is_fifth_order():
    orders, errors = observed_orders(3, 0.0)
    assert np.all(orders[:2] > 4.6), orders


def test_stability_function_is_l_stable_and_accurate():
    # |R| <= 1 on the imaginary axis (A-stability) and R -> 0 at infinity (L-stability).
    for stages in (2, 3):
        for y in np.logspace(-3, 6, 50):
            assert abs(stability_function(stages, 1j * y)) <= 1.0 + 1e-12
        assert abs(stability_function(stages, -1e9)) < 1e-8
        # R(z) - e^z = O(z^(2s)), the order 2s - 1.
        z = 0.01 + 0.02j
        assert abs(stability_function(stages, z) - np.exp(z)) < 10 * abs(z) ** (2 * stages)


def test_forced_response_near_resonance_at_1khz():
    # Steady state of q'' + 2 zeta w q' + w^2 q = cos(W t): the 5th crank harmonic at 391 rpm
    # (32.6 Hz) against a 34 Hz link mode, sampled at 1 kHz with +-30 % jitter.
    wn, zeta, force_w = 2 * np.pi * 34.0, 0.02, 2 * np.pi * 32.6
    transfer = 1.0 / (wn ** 2 - force_w ** 2 + 2j * zeta * wn * force_w)

    def system(t):
        return (np.eye(1), np.array([[2 * zeta * wn]]), np.array([[wn ** 2]]),
                np.array([np.cos(force_w * t)]))

    times = jittered_times(1e-3, 3.0, 0.3, seed=3)
    q, _ = integrate(system, times, [0.0], [0.0])
    late = times > 2.5
    exact = np.real(transfer * np.exp(1j * force_w * times[late]))
    error = np.sqrt(np.mean((q[late, 0] - exact) ** 2) / np.mean(exact ** 2))
    assert error < 0.005


def test_stable_for_steps_far_beyond_the_period():
    # w h from 6e-4 to 6e7: energy never grows, the stiff response is annihilated.
    rng = np.random.default_rng(7)
    method = RadauIIA(2)
    for frequency in (0.1, 10.0, 1e3, 1e5):
        wn = 2 * np.pi * frequency
        mats = [np.eye(1)[None].repeat(2, 0), np.zeros((2, 1, 1)),
                np.full((2, 1, 1), wn ** 2)]
        q, v = np.array([1.0]), np.array([0.0])
        energy0 = 0.5 * wn ** 2
        for _ in range(3000):
            h = 10 ** rng.uniform(-5, -1) * (1.0 + 0.5 * rng.uniform(-1, 1))
            q, v, acc = method.step(q, v, h, *mats, np.zeros((2, 1)))
            energy = 0.5 * v[0] ** 2 + 0.5 * wn ** 2 * q[0] ** 2
            assert np.isfinite(energy) and energy <= energy0 * (1 + 1e-12)
    # One 0.1 s step on a 10 kHz mode: the free response is gone.
    wn = 2 * np.pi * 1e4
    q, v, _ = RadauIIA(2).step(np.array([1.0]), np.array([0.0]), 0.1, np.ones((2, 1, 1)),
                               np.zeros((2, 1, 1)), np.full((2, 1, 1), wn ** 2),
                               np.zeros((2, 1)))
    assert abs(q[0]) < 1e-6


def mathieu_system(t):
    """Two coupled DOFs with parametric stiffness and mass and a harmonic load."""
    mass = np.array([[1.0 + 0.2 * np.cos(t), 0.1], [0.1, 0.8 + 0.1 * np.sin(2 * t)]])
    stiffness = np.array([[40.0 * (1.0 + 0.3 * np.cos(2.0 * t)), -5.0],
                          [-5.0, 90.0 + 20.0 * np.sin(t)]])
    damping = np.array([[0.3, 0.5 * np.cos(t)], [-0.5 * np.cos(t), 0.4]])  # skew part: Coriolis
    load = np.array([np.sin(3.0 * t), 0.5])
    return mass, damping, stiffness, load


def test_parametric_system_against_tight_reference():
    q0, v0 = np.array([0.05, -0.02]), np.array([0.0, 0.3])

    def first_order(t, z):
        mass, damping, stiffness, load = mathieu_system(t)
        return np.concatenate([z[2:], np.linalg.solve(mass, load - damping @ z[2:]
                                                      - stiffness @ z[:2])])

    end = 6.0
    times = jittered_times(5e-3, end, 0.5, seed=11)
    ref = solve_ivp(first_order, (0.0, times[-1]), np.concatenate([q0, v0]), method='DOP853',
                    t_eval=times, rtol=1e-12, atol=1e-13)
    scale = np.max(np.abs(ref.y[:2]))
    for stages, tolerance in ((2, 1e-4), (3, 1e-8)):
        q, v = integrate(mathieu_system, times, q0, v0, stages=stages)
        assert np.max(np.abs(q.T - ref.y[:2])) < tolerance * scale


def test_columns_propagate_like_separate_runs():
    method = RadauIIA(2)
    rng = np.random.default_rng(0)
    mats = [mathieu_system(0.3 + c * 0.01) for c in method.c]
    mass, damping, stiffness = (np.array([m[k] for m in mats]) for k in range(3))
    q, v = rng.normal(size=(2, 3)), rng.normal(size=(2, 3))
    load = rng.normal(size=(2, 2, 3))
    together = method.step(q, v, 0.01, mass, damping, stiffness, load)
    for col in range(3):
        alone = method.step(q[:, col], v[:, col], 0.01, mass, damping, stiffness,
                            load[:, :, col])
        for a, b in zip(together, alone):
            np.testing.assert_allclose(a[:, col], b, rtol=1e-13, atol=1e-15)


def test_rejects_bad_arguments():
    with pytest.raises(ValueError, match='stages'):
        RadauIIA(4)
    with pytest.raises(ValueError, match='times'):
        integrate(sdof, [0.0, 0.1, 0.1], [1.0], [0.0])


def test_batched_step_maps_and_composition_match_sequential_steps():
    method = RadauIIA(2)
    rng = np.random.default_rng(3)
    steps = 37
    h = rng.uniform(1e-3, 2e-2, steps)
    times = np.concatenate([[0.0], np.cumsum(h)])
    mats = [[mathieu_system(t + c * hk) for c in method.c] for t, hk in zip(times[:-1], h)]
    mass, damping, stiffness = (np.array([[m[k] for m in row] for row in mats])
                                for k in range(3))
    load = np.array([[m[3] for m in row] for row in mats])
    maps = step_maps(method, h, mass, damping, stiffness, load)
    q, v = np.array([0.05, -0.02]), np.array([0.0, 0.3])
    states = compose_affine(maps, np.concatenate([q, v]))
    for k in range(steps):
        q, v, _ = method.step(q, v, h[k], mass[k], damping[k], stiffness[k], load[k])
        np.testing.assert_allclose(states[k + 1], np.concatenate([q, v]), rtol=1e-10,
                                   atol=1e-14)
