"""Shared inputs of the estimation tests: sample times, the toy model and its forces, feeds."""

import dataclasses

from flexlink_ros.core.estimation.native import compiled_step_available
from flexlink_ros.core.mechanism_file import load_mechanism
from flexlink_ros.core.options import ModelOptions
from flexlink_ros.core.reduction import build, cells, mechanism_model
from flexlink_ros.core.reduction import model as tables
from flexlink_ros.core.reduction import periodic
from flexlink_ros.errors import OutlierSample
import numpy as np
import pytest
from toy_system import CONFIG, toy_samples, ZETA

SPEED_MAX = 65.0
SPEED = 41.0            # rad/s (391 rpm)
RATE_HZ = 1000.0
PATHS = [pytest.param(False, id='numpy'),
         pytest.param(True, id='compiled', marks=pytest.mark.skipif(
             not compiled_step_available(), reason='compiled step not built'))]


def sample_times(rate_hz, seconds, jitter, drop, seed):
    """Jittered sample times with a fraction of samples dropped."""
    rng = np.random.default_rng(seed)
    steps = (1.0 + jitter * rng.uniform(-1.0, 1.0, int(seconds * rate_hz * 1.6))) / rate_hz
    times = np.cumsum(steps)
    times = times[times <= seconds]
    return times[rng.random(times.size) >= drop]


def run(filter_, times, angle, speed, with_speed, wrap_seed=None):
    rng = np.random.default_rng(wrap_seed)
    out = []
    for t in times:
        measured = angle(t)
        if wrap_seed is not None:  # arbitrary multiples of 2 pi, as drivers may send
            measured += 2 * np.pi * rng.integers(-3, 4)
        out.append(filter_.update(t, measured, speed(t) if with_speed else None))
    return np.array(out)


def toy_forces(grid):
    """Joint reactions F = F_1 + a F_a + w^2 F_w2 with two harmonics, and dF/dtheta."""
    theta = 2 * np.pi * np.arange(grid) / grid
    rng = np.random.default_rng(5)
    amp = rng.normal(size=(3, 4, 2, 2))
    force, rate = {}, {}
    for i, piece in enumerate(('1', 'a', 'w2')):
        force[piece] = np.zeros((grid, 4, 2))
        rate[piece] = np.zeros((grid, 4, 2))
        for h in (1, 2):
            force[piece] += amp[i, :, :, h - 1] * np.cos(h * theta + 0.3 * h)[:, None, None]
            rate[piece] += -h * amp[i, :, :, h - 1] * np.sin(h * theta + 0.3 * h)[:, None, None]
        force[piece] += 0.5 * (i == 2)  # an offset so reactions rarely vanish at speed
    return {'force': force, 'force_rate': rate}, amp


def cho1992():
    """Load the Cho 1992 mechanism of the package's configuration."""
    return load_mechanism(CONFIG / 'cho1992.yaml')


def cho_second_order_model(bearings='rigid', grid_size=32):
    """Cho 1992 reduced model of order 2 (rigid crank, the default sizes), cached."""
    return mechanism_model.model_for_mechanism(
        cho1992(), ModelOptions.linear(bearings=bearings, grid_size=grid_size, order=2))


def toy_model():
    """Reduced toy model (64-point grid, 4 modes + 2 static) with joint reactions."""
    samples = toy_samples(grid=64)
    forces, _ = toy_forces(64)
    return build.reduce_samples(samples, modes=4, static=2, speed_max=SPEED_MAX, zeta=ZETA,
                                forces=forces)


def toy_damped_model(beta=2e-4):
    """
    Build the toy model with stiffness damping: C_beta = beta K_1, D_beta = w Kb1 ('w' piece).

    Kb1 is an angle-dependent, non-symmetric beta-scaled matrix, as the linkage's
    ``beta sum g1_L T K_L D1^T`` (core/fe/stiffness_damping.py).
    """
    samples = toy_samples(grid=64)
    grid = samples.grid_size
    theta = 2 * np.pi * np.arange(grid) / grid
    rng = np.random.default_rng(9)
    rotation = rng.normal(size=(samples.dofs, samples.dofs)) * 30.0
    stiffness = dict(samples.stiffness)
    stiffness['w'] = beta * np.array([(1.0 + 0.5 * np.cos(t)) * rotation for t in theta])
    modal = samples.damping

    def damping(k, w):
        return modal(k, w) + beta * samples.stiffness['1'][k]

    damped = dataclasses.replace(samples, stiffness=stiffness, damping=damping)
    forces, _ = toy_forces(grid)
    return build.reduce_samples(damped, modes=4, static=2, speed_max=SPEED_MAX, zeta=ZETA,
                                forces=forces)


def periodic_outputs(model, speed, angles):
    """Periodic steady-state outputs of the reduced model at given crank angles."""
    steps = 2048
    grid, q, _ = periodic.periodic_response(model, speed, start_angle=0.0, steps=steps)
    out = tables.output_values(model, model.evaluate(grid, speed, 0.0), q)[:-1]
    phase = np.mod(angles, 2 * np.pi) / (2 * np.pi) * steps * np.sign(speed)
    # Periodic cubic interpolation of the fine reference.
    coef = cells.periodic_cell_coefficients(out)
    k = np.floor(np.mod(phase, steps)).astype(int)
    t = np.mod(phase, steps) - k
    return np.einsum('mp,mpc->mc', t[:, None] ** np.arange(4), coef[k])


def stream(estimator, times, angle, speed, with_speed=True):
    samples = []
    for t in times:
        samples.append(estimator.update(int(round(t * 1e9)), angle(t),
                                        speed(t) if with_speed else None))
    return samples


def deflections(samples):
    return np.array([s.lever_tip + s.coupler_mid for s in samples])


def relative_rms(estimate, exact):
    return np.sqrt(np.mean((estimate - exact) ** 2, axis=0) / np.mean(exact ** 2, axis=0))


def finite(samples):
    values = np.array([s.lever_tip + s.coupler_mid + s.reaction_n + s.gamma_dot
                       + (s.error_indicator, s.crank_speed, s.crank_accel) for s in samples])
    return np.all(np.isfinite(values))


def compiled_or_skip():
    """Skip a test of the compiled step where it is not built."""
    if not compiled_step_available():
        pytest.skip('the compiled step is not built (test_compiled_step_is_built fails)')


def samples_fields(samples):
    """Arrays of a list of samples' fields, by name."""
    return {name: np.array([getattr(s, name) for s in samples], dtype=float)
            for name in ('lever_tip', 'coupler_mid', 'reaction_n', 'gamma_dot', 'criterion',
                         'error_indicator', 'modal', 'crank_speed', 'crank_accel')}


def clean_signal(seconds, seed=21):
    times = sample_times(RATE_HZ, seconds, 0.3, 0.0, seed=seed)
    stamps = [int(round(t * 1e9)) + 10**9 for t in times]
    return [(stamp, SPEED * (stamp - 10**9) * 1e-9 + 0.3, SPEED) for stamp in stamps]


def feed(estimator, events):
    """update() over (stamp, angle, speed) events as the node does: outliers are skipped."""
    samples, refused = {}, []
    for stamp, angle, speed in events:
        try:
            samples[stamp] = estimator.update(stamp, angle, speed)
        except OutlierSample as exc:
            refused.append((stamp, exc.reason))
    return samples, refused


def outputs(sample):
    return np.array(sample.lever_tip + sample.coupler_mid + sample.reaction_n + sample.modal)


def largest(sample):
    return max(abs(d) for d in sample.lever_tip + sample.coupler_mid)
