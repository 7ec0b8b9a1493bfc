"""
Periodic steady state of a reduced model at constant crank speed (shooting over Radau IIA).

The full-order counterpart is core/fe/simulate.py's ``periodic_response``.
"""

import numpy as np

from .model import system_blocks
from ..integrators import compose_affine, RadauIIA, step_maps

# Steps per chunk of periodic_response (bounds its peak memory).
PERIODIC_CHUNK = 60


def periodic_response(model, speed, start_angle=0.0, steps=720, stages=2, blocks=None):
    """
    Periodic steady state of the reduced model at constant crank speed (shooting).

    The one-revolution map of the Radau IIA discretisation is affine in the initial state,
    ``z_T = P z_0 + g``; it is the product of the steps' affine maps (all solved at once),
    and ``z_0 = (I - P)^-1 g`` is the periodic state. At zero speed the static state K^-1 f
    is returned.

    Parameters
    ----------
    model : ReducedModel
        The model to integrate.
    speed : float
        Crank speed [rad/s] (either sign).
    start_angle : float
        Crank angle of the first state [rad].
    steps : int
        Time steps per revolution.
    stages : int
        Radau IIA stages.
    blocks : callable or None
        ``blocks(theta, w, a)`` -> M, C, K, f at crank angles ``theta`` (arrays of shapes
        (m, r, r) x 3 and (m, r)); None: from ``model.evaluate``.

    Returns
    -------
    angles : ndarray, shape (steps + 1,)
        Unwrapped crank angles [rad] from ``start_angle``.
    q, v : ndarray, shape (steps + 1, r)
        Reduced coordinates and velocities.

    """
    size = model.step_size
    if blocks is None:
        blocks = lambda theta, w, a: system_blocks(model, model.evaluate(theta, w, a))  # noqa
    if speed == 0.0:
        _, _, stiffness, load = blocks(np.atleast_1d(float(start_angle)), 0.0, 0.0)
        q = np.linalg.solve(stiffness[0], load[0])
        return (np.full(steps + 1, float(start_angle)), np.tile(q, (steps + 1, 1)),
                np.zeros((steps + 1, size)))
    method = RadauIIA(stages)
    period = 2.0 * np.pi / abs(speed)
    h = period / steps
    stage_times = (np.arange(steps)[:, None] + method.c[None, :]) * h
    maps = np.empty((steps, 2 * size, 2 * size + 1))
    # In chunks: the table rows of a whole revolution at once would add tens of MB to the
    # peak (and, through malloc's heap, to the node's resident size for good).
    for first in range(0, steps, PERIODIC_CHUNK):
        chunk = slice(first, min(first + PERIODIC_CHUNK, steps))
        count = chunk.stop - chunk.start
        mass, damping, stiffness, load = (
            b.reshape((count, stages) + b.shape[1:])
            for b in blocks(start_angle + speed * stage_times[chunk].ravel(), speed, 0.0))
        maps[chunk] = step_maps(method, np.full(count, h), mass, damping, stiffness, load)
    total = np.concatenate([np.eye(2 * size), np.zeros((2 * size, 1))], axis=1)
    for step in maps:
        total = step[:, :2 * size] @ total
        total[:, -1] += step[:, -1]
    start = np.linalg.solve(np.eye(2 * size) - total[:, :-1], total[:, -1])
    states = compose_affine(maps, start)
    q_all, v_all = states[:, :size], states[:, size:]
    angles = start_angle + speed * h * np.arange(steps + 1)
    return angles, q_all, v_all
