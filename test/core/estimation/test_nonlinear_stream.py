"""
The reduced nonlinear estimator (core/estimation/nonlinear_stream.py).

At reduced size (2 elements per link, the basis spanning every DOF, so that only the per-link
lumping of the axial force differs from the full order): with the nonlinear terms off it
follows the linear full order, with them on the nonlinear full order's periodic orbit at the
paper's speed; the lumped force's tangents equal finite differences; the step converges and
stays bounded from 10 us to 100 ms steps with +-30 % jitter.
"""

import dataclasses
import math

from flexlink_ros.core.estimation import nonlinear_stream
from flexlink_ros.core.estimation.nonlinear_stream import (estimate_nonlinear, lumped_force,
                                                           NonlinearStepper)
from flexlink_ros.core.fe.linkage import FlexibleLinkage
from flexlink_ros.core.fe.nonlinear_response import nonlinear_response
from flexlink_ros.core.mechanism_file import load_mechanism
from flexlink_ros.core.options import ModelOptions
from flexlink_ros.core.reduction.nonlinear_tables import build_nonlinear_tables
from flexlink_ros.studies.peer_linear import linear_model
from flexlink_ros.studies.peer_model import OUTPUT_KEYS, resolve_mechanism
from flexlink_ros.studies.validation import BEARINGS, peer_run, Settings
import numpy as np
import pytest

SPEED = 391.0 * math.pi / 30.0
BETA = 1e-4
STEPS = 360


@pytest.fixture(scope='module')
def model():
    mech = dataclasses.replace(load_mechanism('cho1992'), elements_per_link=2)
    return FlexibleLinkage(mech, ModelOptions.full_model(rigid_crank=True, bearings='flexible'))


@pytest.fixture(scope='module')
def tables(model):
    return build_nonlinear_tables(model, BETA, size=model.size, modes=model.size)


def _relative_rms(mine, reference):
    """Relative RMS of the deflection vector per point (lever tip, coupler mid)."""
    return [math.sqrt(((mine[:, p] - reference[:, p]) ** 2).sum(axis=1).mean()
                      / (reference[:, p] ** 2).sum(axis=1).mean())
            for p in (slice(0, 2), slice(2, 4))]


def _last_revolution(tables, nonlinear, revolutions=14, points=36):
    h = 2.0 * math.pi / SPEED / STEPS
    count = revolutions * STEPS + 1
    stamps = np.round(np.arange(count) * h * 1e9).astype(np.int64)
    out = estimate_nonlinear(tables, stamps, SPEED * stamps * 1e-9, np.full(count, SPEED),
                             nonlinear)
    assert out['refused'] == 0 and out['converged'].all()
    return out['outputs'][-STEPS - 1:-1:STEPS // points]


@pytest.mark.parametrize('nonlinear', [False, True], ids=['linear', 'nonlinear'])
def test_follows_the_full_order_periodic_orbit(model, tables, nonlinear):
    reference = nonlinear_response(model, SPEED, steps=STEPS, points=36, zeta=0.0, beta=BETA,
                                   nonlinear=nonlinear).outputs
    errors = _relative_rms(_last_revolution(tables, nonlinear), reference)
    # linear: the same model in other coordinates (interpolated tables); nonlinear: plus the
    # per-link lumping of the axial force
    assert max(errors) < (0.005 if not nonlinear else 0.03), errors


def test_nonlinear_orbit_differs_from_the_linear_one(tables):
    linear, nonlinear = _last_revolution(tables, False), _last_revolution(tables, True)
    assert max(_relative_rms(linear, nonlinear)) > 0.2


def test_lumped_force_tangents_equal_finite_differences(tables):
    rng = np.random.default_rng(3)
    fields = tables.at(np.array([0.4, 0.9]))
    eta, rate = 1e-3 * rng.standard_normal((2, tables.size)), rng.standard_normal((2, tables.size))
    speed = np.array([40.0, 41.0])
    force, stiffness, damping, _ = lumped_force(tables, fields, eta, rate, speed)
    step = 1e-8
    for j in range(tables.size):
        bump = np.zeros_like(eta)
        bump[:, j] = step
        plus = lumped_force(tables, fields, eta + bump, rate, speed, tangents=False)[0]
        minus = lumped_force(tables, fields, eta - bump, rate, speed, tangents=False)[0]
        np.testing.assert_allclose((plus - minus) / (2 * step), stiffness[:, :, j],
                                   rtol=1e-5, atol=1e-6 * np.abs(stiffness).max())
        plus = lumped_force(tables, fields, eta, rate + bump, speed, tangents=False)[0]
        minus = lumped_force(tables, fields, eta, rate - bump, speed, tangents=False)[0]
        np.testing.assert_allclose((plus - minus) / (2 * step), damping[:, :, j],
                                   rtol=1e-5, atol=1e-6 * np.abs(damping).max())
    off = lumped_force(tables, fields, eta, rate, speed, nonlinear=False)
    assert not np.any(off[0]) and not np.any(off[1]) and not np.any(off[2])


@pytest.mark.parametrize('step_s', [1e-5, 1e-3, 1e-1])
def test_stable_with_jittered_steps(tables, step_s):
    rng = np.random.default_rng(7)
    count = {1e-5: 400, 1e-3: 1500, 1e-1: 60}[step_s]
    steps = step_s * (1.0 + 0.3 * rng.uniform(-1.0, 1.0, count - 1))
    stamps = np.concatenate([[0], np.cumsum(np.round(steps * 1e9).astype(np.int64))])
    angles = np.mod(SPEED * stamps * 1e-9, 2 * math.pi)
    out = estimate_nonlinear(tables, stamps, angles, np.full(count, SPEED))
    assert out['refused'] == 0 and np.all(np.isfinite(out['outputs']))
    # bounded by the orbit's size (a few mm at this speed): no growth from the step
    assert np.abs(out['outputs']).max() < 0.05


def test_jittered_1khz_matches_the_steady_1khz_estimate(tables):
    rng = np.random.default_rng(11)
    count = 2000
    steady = np.arange(count, dtype=np.int64) * 1_000_000
    jitter = steady + np.round(rng.uniform(-0.3, 0.3, count) * 1e6).astype(np.int64)
    jitter[0] = 0
    a = estimate_nonlinear(tables, steady, SPEED * steady * 1e-9)['outputs']
    b = estimate_nonlinear(tables, jitter, SPEED * jitter * 1e-9)['outputs']
    last = slice(count - 150, count)
    # the same motion sampled at other times: compare at equal crank angles
    angle_b = np.mod(SPEED * jitter[last] * 1e-9, 2 * math.pi)
    angle_a = np.mod(SPEED * steady[last] * 1e-9, 2 * math.pi)
    order = np.argsort(angle_a)
    resampled = np.stack([np.interp(angle_b, angle_a[order], a[last][order, c], period=2 * math.pi)
                          for c in range(4)], axis=1)
    assert max(_relative_rms(resampled, b[last])) < 0.03


def test_stepper_refuses_nothing_silently(tables):
    stepper = NonlinearStepper(tables)
    stepper.start(0.0, SPEED)
    assert stepper.step(1e-3, 0.0, SPEED * 1e-3, SPEED, SPEED)
    assert np.all(np.isfinite(stepper.q)) and stepper.iterations >= 1
    state = stepper.q.copy()
    assert not stepper.step(1e-3, SPEED * 1e-3, np.nan, SPEED, SPEED)
    assert not stepper.step(0.0, SPEED * 1e-3, SPEED * 2e-3, SPEED, SPEED)
    np.testing.assert_array_equal(stepper.q, state)


def test_jittered_1khz_estimate_agrees_with_the_exudyn_peer_through_the_resonance():
    # the scene: rigid crank, bearing springs, 8 elements per link, beta 1e-4 s, zeta 0,
    # gravity, 391 rpm; measured 2.4 / 1.7 % (lever tip / coupler mid) with +-30 % jitter and
    # the 20-vector basis the size rule picks (2.7 / 2.3 % with the 30 vectors before)
    pytest.importorskip('exudyn')
    settings = Settings(bearings='flexible', beta_s=BETA, stiffness_damping=BETA, zeta=0.0,
                        elements_per_link=8)
    mech = resolve_mechanism('cho1992')
    peer = peer_run(mech, 391.0, settings)
    span = slice(-settings.peer_steps - 1, -1)
    expected = np.stack([peer[key][span] for key in OUTPUT_KEYS], axis=1)
    peer_angle = np.mod(peer['crank_angle'][span], 2 * math.pi)
    linkage = linear_model(mech, elements_per_link=8, bearings=BEARINGS['flexible'],
                           gravity=True)
    tables = build_nonlinear_tables(linkage, BETA)
    rng = np.random.default_rng(1)
    count = 3000
    steps = np.round((1.0 + 0.3 * rng.uniform(-1.0, 1.0, count - 1)) * 1e6).astype(np.int64)
    stamps = np.concatenate([[0], np.cumsum(steps)])
    angles = SPEED * stamps * 1e-9
    out = estimate_nonlinear(tables, stamps, np.mod(angles, 2 * math.pi),
                             np.full(count, SPEED))
    assert out['refused'] == 0
    last = slice(count - 220, count)       # 1.4 revolutions of samples, read by crank angle
    angle = np.mod(angles[last], 2 * math.pi)
    order = np.argsort(angle)
    mine = np.column_stack([np.interp(peer_angle, angle[order], out['outputs'][last][order, c],
                                      period=2 * math.pi) for c in range(4)])
    errors = _relative_rms(mine, expected)
    assert max(errors) < 0.05, errors


def test_compiled_newton_equals_the_numpy_reference(tables):
    pytest.importorskip('flexlink_ros.core.estimation._nonlinear_step')
    rng = np.random.default_rng(2)
    count = 600
    steps = np.round((1.0 + 0.3 * rng.uniform(-1.0, 1.0, count - 1)) * 1e6).astype(np.int64)
    stamps = np.concatenate([[0], np.cumsum(steps)])
    angles = np.mod(SPEED * stamps * 1e-9, 2 * math.pi)
    for nonlinear in (False, True):
        numpy_run = estimate_nonlinear(tables, stamps, angles, np.full(count, SPEED), nonlinear,
                                       compiled=False)
        c_run = estimate_nonlinear(tables, stamps, angles, np.full(count, SPEED), nonlinear)
        scale = np.abs(numpy_run['outputs']).max()
        assert np.abs(c_run['outputs'] - numpy_run['outputs']).max() < 1e-9 * scale
        np.testing.assert_allclose(c_run['axial_force'], numpy_run['axial_force'],
                                   rtol=1e-6, atol=1e-9)
        assert c_run['newton_iterations'] == numpy_run['newton_iterations']


def _stage_cells(tables, stamps, angles):
    """Grid cells of the two Radau stages (c = 1/3, 1) of every step, (K - 1, 2)."""
    theta = np.unwrap(angles)
    stage_angles = theta[:-1, None] + np.array([1.0 / 3.0, 1.0]) * np.diff(theta)[:, None]
    position = np.mod(stage_angles, 2 * math.pi) * tables.grid_size / (2 * math.pi)
    return np.minimum(position.astype(int), tables.grid_size - 1)


@pytest.mark.parametrize('direction', [1.0, -1.0])
def test_compiled_step_equals_the_numpy_reference_wherever_the_stages_fall_in_the_grid(
        tables, direction):
    # the compiled step reads both stages' rows in one pass when their cells share grid nodes
    # (one cell, or neighbours, also across 2 pi, in either direction of turning) and apart
    # otherwise: every case, the same answers
    pytest.importorskip('flexlink_ros.core.estimation._nonlinear_step')
    rng = np.random.default_rng(5)
    count = 500
    steps = np.round(rng.uniform(0.2e6, 6e6, count - 1)).astype(np.int64)
    stamps = np.concatenate([[0], np.cumsum(steps)])
    speed = direction * SPEED
    angles = np.mod(speed * stamps * 1e-9, 2 * math.pi)
    cells = _stage_cells(tables, stamps, angles)
    gap = np.mod(direction * (cells[:, 1] - cells[:, 0]), tables.grid_size)
    last = tables.grid_size - 1
    wraps = {(last, 0), (0, last)} & set(map(tuple, cells.tolist()))
    assert (gap == 0).sum() > 20 and (gap == 1).sum() > 20 and (gap > 1).sum() > 20
    assert wraps
    numpy_run = estimate_nonlinear(tables, stamps, angles, np.full(count, speed),
                                   compiled=False)
    c_run = estimate_nonlinear(tables, stamps, angles, np.full(count, speed))
    assert c_run['refused'] == numpy_run['refused'] == 0
    scale = np.abs(numpy_run['outputs']).max()
    assert np.abs(c_run['outputs'] - numpy_run['outputs']).max() < 1e-9 * scale
    np.testing.assert_allclose(c_run['link_slope'], numpy_run['link_slope'], rtol=1e-9,
                               atol=1e-12)
    assert c_run['newton_iterations'] == numpy_run['newton_iterations']


@pytest.mark.parametrize('compiled', [True, False])
def test_newton_that_leaves_its_start_halves_the_step_instead_of_taking_a_far_root(
        tables, compiled):
    # Steps of 0.2-6 ms at random: on some of them Newton leaves the start's basin, and the
    # cubic strain has far roots (tens of kilometres of deflection) that its relative test
    # accepts. Without the divergence test the compiled step took one here (outputs of 3e7 m,
    # then 112 samples refused) and the numpy step did too on two BLAS threads.
    if compiled:
        pytest.importorskip('flexlink_ros.core.estimation._nonlinear_step')
    rng = np.random.default_rng(1)
    count = 500
    steps = np.round(rng.uniform(0.2e6, 6e6, count - 1)).astype(np.int64)
    stamps = np.concatenate([[0], np.cumsum(steps)])
    angles = np.mod(SPEED * stamps * 1e-9, 2 * math.pi)
    run = estimate_nonlinear(tables, stamps, angles, np.full(count, SPEED), compiled=compiled)
    assert run['refused'] == 0
    # millimetres, as at 1 kHz
    assert 1e-3 < np.abs(run['outputs']).max() < 1e-2


def test_non_finite_samples_are_refused_counted_and_do_not_poison_the_rest(tables):
    count = 600
    stamps = np.arange(count, dtype=np.int64) * 1_000_000
    angles = np.mod(SPEED * stamps * 1e-9, 2 * math.pi)
    speeds = np.full(count, SPEED)
    clean = estimate_nonlinear(tables, stamps, angles, speeds)
    bad_angles, bad_speeds = angles.copy(), speeds.copy()
    bad_angles[[100, 101]] = np.nan
    bad_speeds[300] = np.inf
    out = estimate_nonlinear(tables, stamps, bad_angles, bad_speeds)
    assert out['bad_input'] == 3 and out['refused'] == 3
    assert np.isnan(out['outputs'][[100, 101, 300]]).all()
    assert not out['converged'][[100, 101, 300]].any()
    # the samples after a gap of 3 ms step on from the last good one: close to the clean run
    later = slice(400, count)
    scale = np.abs(clean['outputs'][later]).max()
    assert np.isfinite(out['outputs'][later]).all()
    assert np.abs(out['outputs'][later] - clean['outputs'][later]).max() < 0.05 * scale


def test_link_slopes_are_reported_and_counted_beyond_the_von_karman_limit(tables, monkeypatch):
    count = 400
    stamps = np.arange(count, dtype=np.int64) * 1_000_000
    angles = np.mod(SPEED * stamps * 1e-9, 2 * math.pi)
    out = estimate_nonlinear(tables, stamps, angles, np.full(count, SPEED))
    # millimetres on links of 0.1-0.3 m: slopes below 0.1 rad, inside the limit
    assert 1e-3 < np.nanmax(out['link_slope']) < 0.1 and out['beyond_von_karman'] == 0
    monkeypatch.setattr(nonlinear_stream, 'VON_KARMAN_SLOPE', 1e-3)
    flagged = estimate_nonlinear(tables, stamps, angles, np.full(count, SPEED))
    expected = int((out['link_slope'] > 1e-3).any(axis=1).sum())
    assert flagged['beyond_von_karman'] == expected > 0


def test_ten_microsecond_jittered_steps_agree_with_one_millisecond_steps(tables):
    # the same motion stepped 100 times finer with +-30 % jitter: the fine run read at the
    # coarse run's times agrees with it (a step size the estimator follows, not just bounded)
    rng = np.random.default_rng(5)
    fine_steps = np.round((1.0 + 0.3 * rng.uniform(-1.0, 1.0, 6000)) * 1e4).astype(np.int64)
    fine = np.concatenate([[0], np.cumsum(fine_steps)])
    fine = fine[fine <= 50_000_000]
    coarse = np.arange(51, dtype=np.int64) * 1_000_000
    runs = [estimate_nonlinear(tables, stamps, SPEED * stamps * 1e-9,
                               np.full(stamps.size, SPEED)) for stamps in (fine, coarse)]
    assert runs[0]['refused'] == 0 and runs[1]['refused'] == 0
    resampled = np.column_stack([np.interp(coarse, fine, runs[0]['outputs'][:, c])
                                 for c in range(4)])
    span = np.ptp(runs[1]['outputs'], axis=0).max()
    assert np.abs(resampled - runs[1]['outputs']).max() < 0.01 * span      # measured 0.09 %


def test_march_steps_many_samples_as_one_sample_calls(tables):
    # the offline batch (one compiled call for many samples) and the streaming update (one
    # call per sample) are the same step: the same state, outputs to their rounding
    pytest.importorskip('flexlink_ros.core.estimation._nonlinear_step')
    count = 300
    stamps = np.arange(count, dtype=np.int64) * 1_000_000
    times, angles = stamps * 1e-9, SPEED * stamps * 1e-9
    batch, single = NonlinearStepper(tables), NonlinearStepper(tables)
    for stepper in (batch, single):
        stepper.start(angles[0], SPEED)
    outputs = batch.march(times, angles, np.full(count, SPEED))[0]
    for k in range(1, count):
        assert single.step(times[k] - times[k - 1], angles[k - 1], angles[k], SPEED, SPEED)
        np.testing.assert_allclose(single.output_operator @ single.q, outputs[k - 1],
                                   rtol=1e-12, atol=1e-18)
    np.testing.assert_array_equal(single.q, batch.q)
    assert single.iterations == batch.iterations > count


def test_one_sample_steps_follow_the_state_arrays_a_start_replaces(tables):
    # the per-sample step keeps the march's arguments; a start makes new state arrays, which
    # the next step must write (not the old ones)
    pytest.importorskip('flexlink_ros.core.estimation._nonlinear_step')
    kept, fresh = NonlinearStepper(tables), NonlinearStepper(tables)
    kept.start(0.0, SPEED)
    for k in range(5):
        assert kept.step(1e-3, SPEED * k * 1e-3, SPEED * (k + 1) * 1e-3, SPEED, SPEED)
    for stepper in (kept, fresh):
        stepper.start(1.0, SPEED)
    for k in range(20):
        angles = (1.0 + SPEED * k * 1e-3, 1.0 + SPEED * (k + 1) * 1e-3)
        for stepper in (kept, fresh):
            assert stepper.step(1e-3, *angles, SPEED, SPEED)
    for name in ('q', 'v', 'output_operator', 'slope', 'axial'):
        np.testing.assert_array_equal(getattr(kept, name), getattr(fresh, name))
    assert np.any(kept.q != 0.0)


def test_step_to_unwraps_and_steps_as_unwrap_next_and_the_march(tables):
    # the streaming update's one compiled call: the same angle and state, bit for bit, as
    # unwrap_next and a march over the pair; a non-finite angle raises as unwrap_next does
    pytest.importorskip('flexlink_ros.core.estimation._nonlinear_step')
    single, reference = NonlinearStepper(tables), NonlinearStepper(tables)
    for stepper in (single, reference):
        stepper.start(0.0, SPEED)
    theta0 = 0.0
    for k in range(1, 200):     # past a whole turn
        wrapped = math.fmod(SPEED * k * 1e-3, 2.0 * math.pi)
        theta, converged = single.step_to(1e-3, theta0, wrapped, SPEED, SPEED)
        expected = nonlinear_stream.unwrap_next(theta0, wrapped, SPEED, SPEED, 1e-3)
        marched = reference.march(np.array([0.0, 1e-3]), np.array([theta0, expected]),
                                  np.full(2, SPEED))
        assert theta == expected and converged == marched[3][0]
        for name in ('q', 'v', 'output_operator', 'slope', 'axial'):
            np.testing.assert_array_equal(getattr(single, name), getattr(reference, name))
        theta0 = theta
    assert theta0 > 2.0 * math.pi and single.iterations == reference.iterations
    with pytest.raises(ValueError):
        single.step_to(1e-3, theta0, math.nan, SPEED, SPEED)


def test_march_refuses_a_table_layout_outside_its_rows_and_bad_newton_limits(tables):
    pytest.importorskip('flexlink_ros.core.estimation._nonlinear_step')
    stepper = NonlinearStepper(tables)
    stepper.start(0.0, SPEED)
    arrays, sizes, constants, _ = stepper._native_arguments()
    bad = arrays[2].copy()
    bad[-1] = tables.values.shape[1] - 1.0           # the output operator past the row's end
    out = (np.empty((1, tables.outputs)), np.empty((1, tables.links)),
           np.empty((1, tables.links)), np.empty(1), np.empty(1))
    state = stepper.q.copy()
    with pytest.raises(ValueError, match='outside'):
        nonlinear_stream.compiled_newton.march(
            *arrays[:2], bad, *arrays[3:], np.array([0.0, 1e-3]), np.array([0.0, 0.04]),
            np.full(2, SPEED), stepper.q, stepper.v, stepper._guess_buffer, stepper.axial,
            stepper.slope, stepper.output_operator, *out, stepper._work, *sizes, 1,
            *constants, 0, False)
    with pytest.raises(ValueError, match='holds'):   # a workspace too small
        nonlinear_stream.compiled_newton.march(
            *arrays, np.array([0.0, 1e-3]), np.array([0.0, 0.04]), np.full(2, SPEED),
            stepper.q, stepper.v, stepper._guess_buffer, stepper.axial, stepper.slope,
            stepper.output_operator, *out, stepper._work[:10], *sizes, 1, *constants, 0,
            False)
    for divergence in (math.nan, 0.5, -1e4):  # NaN never ends Newton, below 1 almost always
        with pytest.raises(ValueError, match='Newton limits'):
            nonlinear_stream.compiled_newton.march(
                *arrays, np.array([0.0, 1e-3]), np.array([0.0, 0.04]), np.full(2, SPEED),
                stepper.q, stepper.v, stepper._guess_buffer, stepper.axial, stepper.slope,
                stepper.output_operator, *out, stepper._work, *sizes, 1, *constants[:-1],
                divergence, 0, False)
    np.testing.assert_array_equal(stepper.q, state)
