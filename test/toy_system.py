"""Synthetic full-order frozen system shared by the reduced-model and estimator tests."""

import pathlib

from flexlink_ros.core.options import ModelOptions
from flexlink_ros.core.reduction.basis import frozen_modes, FrozenSamples
from flexlink_ros.core.reduction.build import reduce_samples
from flexlink_ros.core.reduction.cells import periodic_cell_coefficients
from flexlink_ros.core.reduction.model import output_values
from flexlink_ros.core.reduction.periodic import periodic_response
import numpy as np

ZETA = 0.02
CONFIG = pathlib.Path(__file__).resolve().parents[1] / 'config'


def _sym(rng, n, scale):
    a = rng.normal(size=(n, n))
    return scale * (a + a.T) / 2.0


def toy_samples(grid=48, dofs=10, seed=0):
    """
    Make a synthetic full-order frozen system with the structure of Cho's model.

    Angle-dependent mass and stiffness, Coriolis (skew) terms, centrifugal softening, loads
    with several crank harmonics, and modal damping zeta on the frozen modes; the lowest
    frequencies are ~30-60 Hz and the highest a few kHz, like the linkage's bending and
    axial modes.
    """
    rng = np.random.default_rng(seed)
    theta = 2 * np.pi * np.arange(grid) / grid
    mass0 = np.diag(rng.uniform(0.5, 1.5, dofs)) * 1e-2
    mass1 = _sym(rng, dofs, 1e-4)
    chain = (np.diag(np.full(dofs, 2.0)) - np.diag(np.ones(dofs - 1), 1)
             - np.diag(np.ones(dofs - 1), -1))
    scales = np.geomspace(1.0, 300.0, dofs)
    stiff0 = 6e2 * np.diag(np.sqrt(scales)) @ chain @ np.diag(np.sqrt(scales))
    stiff_var = _sym(rng, dofs, 10.0)
    skew = rng.normal(size=(dofs, dofs)) * 1e-3
    skew = skew - skew.T
    harmonic = lambda k, phase: np.cos(k * theta + phase)  # noqa: E731
    mass = np.array([mass0 + np.sin(t) * mass1 for t in theta])
    stiffness = {
        '1': np.array([stiff0 + np.cos(2 * t) * stiff_var for t in theta]),
        'a': np.array([np.sin(t) * skew for t in theta]),
        'w2': np.array([-(mass0 + 0.3 * np.sin(t) * mass1) for t in theta]),
    }
    load_dirs = rng.normal(size=(3, 4, dofs)) * 1e-3
    load = {piece: sum(harmonic(k + 1, 0.3 * k)[:, None] * load_dirs[i, k] for k in range(4))
            for i, piece in enumerate(('1', 'a', 'w2'))}
    gyroscopic = np.array([(1.0 + 0.5 * np.cos(t)) * skew * 2 for t in theta])
    out_dirs = rng.normal(size=(4, dofs))
    outputs = np.array([out_dirs * (1.0 + 0.2 * np.cos(t)) for t in theta])
    points = 3
    shape_op = rng.normal(size=(3, points, 2, dofs))
    shape_operator = np.array([shape_op * (1.0 + 0.1 * np.sin(t)) for t in theta])
    shape_positions = np.array([np.ones((3, points, 2)) * np.cos(t) for t in theta])

    def damping(k, w):
        stiff = stiffness['1'][k] + w * w * stiffness['w2'][k]
        omega, shapes = frozen_modes(stiff, mass[k], dofs)
        modal = mass[k] @ shapes
        return modal @ np.diag(2 * ZETA * omega) @ modal.T

    return FrozenSamples(mass=mass, gyroscopic=gyroscopic, stiffness=stiffness, load=load,
                         outputs=outputs, damping=damping, shape_operator=shape_operator,
                         shape_positions=shape_positions)


def full_periodic_outputs(samples, speed, steps=720):
    """Periodic outputs of the full toy system (a 'reduced' model keeping every direction)."""
    model = reduce_samples(samples, modes=samples.dofs, speed_max=speed, zeta=ZETA)
    angles, q, _ = periodic_response(model, speed, steps=steps)
    rows = model.evaluate(angles, speed, 0.0)
    return angles, output_values(model, rows, q)


# Toy models by (modes, static, grid) (model_for_mechanism caches too).
TOY_CACHE = {}


def toy_model(mechanism, options=None, cache_dir=None, use_cache=True, progress=None):
    """Stand in for model_for_mechanism: the toy system reduced at the options' sizes."""
    options = options or ModelOptions.linear()
    key = (min(options.modes, 6), min(options.static, 2), options.grid_size)
    if key not in TOY_CACHE:
        TOY_CACHE[key] = reduce_samples(
            toy_samples(grid=options.grid_size), key[0], key[1],
            speed_max=options.speed_max, zeta=ZETA, info={'options': {'modes': key[0]}})
    return TOY_CACHE[key]


def toy_reference(mechanism, options, speed, angles):
    """Return the toy system with every direction kept, periodic at `speed`, at `angles`."""
    full = toy_model(None, ModelOptions.linear(modes=10, static=0, grid_size=32,
                                               speed_max=70.0))
    steps = 1024
    grid, q, _ = periodic_response(full, speed, start_angle=0.0, steps=steps)
    out = output_values(full, full.evaluate(grid, speed, 0.0), q)[:-1]
    coef = periodic_cell_coefficients(out)
    phase = np.mod(angles, 2 * np.pi) / (2 * np.pi) * steps
    k = np.floor(phase).astype(int) % steps
    values = np.einsum('mp,mpc->mc', (phase - np.floor(phase))[:, None] ** np.arange(4),
                       coef[k])
    return {'lever_tip': values[:, :2], 'coupler_mid': values[:, 2:], 'source': 'toy'}
