"""
The nonlinear Radau IIA Newton step (core/fe/nonlinear_step.py).

With the linear strain one step is the project's linear step (core/integrators.py); the
system tangents and the linearised step map equal finite differences of the nonlinear force
and of the step itself.
"""

import dataclasses
import math

from flexlink_ros.core.fe import nonlinear_response as nr
from flexlink_ros.core.fe import nonlinear_step as nstep
from flexlink_ros.core.fe.linkage import FlexibleLinkage
from flexlink_ros.core.fe.stiffness_damping import system_matrices
from flexlink_ros.core.mechanism_file import load_mechanism
from flexlink_ros.core.options import ModelOptions
from flexlink_ros.errors import ConvergenceError
import numpy as np
import pytest

SPEED = 391.0 * math.pi / 30.0
BETA = 1e-4


@pytest.fixture(scope='module')
def model():
    mech = dataclasses.replace(load_mechanism('cho1992'), elements_per_link=2)
    return FlexibleLinkage(mech, ModelOptions.full_model(rigid_crank=True, bearings='flexible'))


def _run(model, nonlinear):
    return nr.make_run(model, SPEED, 360, 60, 2, 0.0, BETA, nonlinear, 0.3)


def _stage(model, run):
    (stage,) = nr._chunk_stages(model, run, np.array([5]))
    return stage


def _bent_state(model, scale=3e-3, seed=4):
    rng = np.random.default_rng(seed)
    q = scale * rng.standard_normal(model.size)
    return q, 200.0 * q + scale * rng.standard_normal(model.size)


def test_linear_strain_step_is_the_linear_step(model):
    run = _run(model, nonlinear=False)
    stage = _stage(model, run)
    q, v = _bent_state(model)
    q1, v1, _, count, _ = nstep.newton_step(run.integrator, run.h, q, v, stage, run.law)
    angles = run.start_angle + SPEED * run.h * (5 + run.integrator.c)
    mass, damping, stiffness, load = system_matrices(model, angles, SPEED, BETA)
    q2, v2, _ = run.integrator.step(q, v, run.h, mass, damping, stiffness, load)
    assert count <= 3
    np.testing.assert_allclose(q1, q2, rtol=0, atol=1e-12 * np.abs(q2).max())
    np.testing.assert_allclose(v1, v2, rtol=0, atol=1e-11 * np.abs(v2).max())


def test_system_tangents_equal_finite_differences(model):
    run = _run(model, nonlinear=True)
    stage = _stage(model, run)
    q, v = _bent_state(model)
    disp, vel = np.stack([q, 1.01 * q]), np.stack([v, 0.99 * v])
    _, f_q, f_v = nstep.stage_forces(run.law, stage, disp, vel)
    for tangent, moved in ((f_q, 'disp'), (f_v, 'vel')):
        fd = np.zeros_like(tangent)
        base = disp if moved == 'disp' else vel
        for j in range(model.size):
            step = 1e-6 * np.abs(base).max()
            delta = np.zeros_like(base)
            delta[:, j] = step
            args = [(disp + delta, vel), (disp - delta, vel)] if moved == 'disp' else [
                (disp, vel + delta), (disp, vel - delta)]
            plus, _, _ = nstep.stage_forces(run.law, stage, *args[0], tangents=False)
            minus, _, _ = nstep.stage_forces(run.law, stage, *args[1], tangents=False)
            fd[:, :, j] = (plus - minus) / (2.0 * step)
        np.testing.assert_allclose(fd, tangent, rtol=0, atol=1e-7 * np.abs(tangent).max())


def test_step_map_equals_finite_differences_of_the_step(model):
    run = _run(model, nonlinear=True)
    stage = _stage(model, run)
    q, v = _bent_state(model)
    _, _, acc, count, step_map = nstep.newton_step(run.integrator, run.h, q, v, stage,
                                                   run.law, sensitivity=True)
    assert 2 <= count <= 6              # nonlinear: more than the one update of a linear step
    n = model.size
    state = np.concatenate([q, v])
    fd = np.zeros((2 * n, 2 * n))
    for j in range(2 * n):
        step = 1e-7 * np.abs(state[:n] if j < n else state[n:]).max()
        delta = np.zeros(2 * n)
        delta[j] = step
        ends = []
        for sign in (1.0, -1.0):
            moved = state + sign * delta
            qe, ve, _, _, _ = nstep.newton_step(run.integrator, run.h, moved[:n], moved[n:],
                                                stage, run.law, guess=acc)
            ends.append(np.concatenate([qe, ve]))
        fd[:, j] = (ends[0] - ends[1]) / (2.0 * step)
    scale = np.abs(step_map).max(axis=1, keepdims=True)
    np.testing.assert_allclose(fd / scale, step_map / scale, rtol=0, atol=1e-6)


def test_newton_failure_is_a_convergence_error(model):
    run = _run(model, nonlinear=True)
    stage = _stage(model, run)
    q, v = _bent_state(model, scale=0.5)           # half a metre: far outside the model
    with pytest.raises(ConvergenceError, match='Newton'):
        nstep.newton_step(run.integrator, run.h, q, v, stage, run.law, iterations=2)
