"""The per-sample step: against the reference Radau IIA step, compiled against numpy."""

import dataclasses

import estimation_toys as toys
from estimation_toys import compiled_or_skip, sample_times, samples_fields
from flexlink_ros.core.estimation import native
from flexlink_ros.core.estimation.compiled_update import use_python_path
from flexlink_ros.core.estimation.native import compiled_step_available, RECORD_SIZE
from flexlink_ros.core.estimation.sample import SampleFlag
from flexlink_ros.core.estimation.step import (joint_criteria, MAX_SUBSTEP_NS,
                                               REACTION_FLOOR_FRACTION, STAGE1)
from flexlink_ros.core.estimation.streaming import StreamingEstimator
from flexlink_ros.core.integrators import RadauIIA
from flexlink_ros.core.reduction import model as tables
import numpy as np
import pytest


@pytest.fixture(scope='module')
def toy_model():
    return toys.toy_model()


@pytest.fixture(scope='module')
def damped_toy_model():
    return toys.toy_damped_model()


@pytest.mark.parametrize('damped', [False, True])
def test_fused_step_equals_the_reference_radau_step(toy_model, damped_toy_model, damped):
    # The per-sample algebra (stacked tables, transformed unknowns) against RadauIIA.step
    # with the same stage matrices (stage 1 at the crank state interpolated to c_1 h).
    # ``damped``: the model's K has the stiffness damping's monomial w (read from its table).
    if damped:
        toy_model = damped_toy_model
    est = StreamingEstimator(toy_model, warm_start=False)
    rng = np.random.default_rng(1)
    stamp, angle, speed = 0, 1.0, 30.0
    est.update(stamp, angle, speed)
    method = RadauIIA(2)
    clip = lambda a: float(np.clip(a, -est.accel_limit, est.accel_limit))  # noqa: E731
    for _ in range(50):
        # One step per sample up to MAX_SUBSTEP_NS (longer ones are split: tested below).
        step_ns = int(10 ** rng.uniform(4, np.log10(MAX_SUBSTEP_NS)))
        # Random speeds, each within the jump a sample may make (InputGate).
        speed = float(np.clip(speed + rng.uniform(-25, 25), -60, 60))
        last = est._last
        q, v = np.array(last.modal), est._stepper.z[toy_model.size:2 * toy_model.size].copy()
        stamp += step_ns
        angle += speed * step_ns * 1e-9
        sample = est.update(stamp, angle, speed)
        c1 = method.c[0]
        speeds = (last.crank_speed, sample.crank_speed)
        accels = (clip(last.crank_accel), clip(sample.crank_accel))
        stage1 = toy_model.evaluate(last.crank_angle + c1 * est.rate_filter.advance,
                                    speeds[0] + c1 * (speeds[1] - speeds[0]),
                                    accels[0] + c1 * (accels[1] - accels[0]))
        current = toy_model.evaluate(sample.crank_angle, speeds[1], accels[1])
        rows = np.vstack([stage1, current])
        q_new, _, _ = method.step(q, v, step_ns * 1e-9, *tables.system_blocks(toy_model, rows))
        # 1e-6: the step tables hold M and C in float32 (2e-8 of the outputs; an error in
        # the algebra shows at O(h) or more).
        np.testing.assert_allclose(sample.modal, q_new, rtol=1e-6,
                                   atol=1e-8 * np.max(np.abs(q_new)))


@pytest.mark.parametrize('with_speed,damped', [(True, False), (False, False), (True, True)])
def test_compiled_step_equals_numpy_step(toy_model, damped_toy_model, with_speed, damped):
    # Jitter, drops, gaps that take sub-steps (7 and 40 ms), a reset (stamp back) and a
    # speed beyond the model's range: every branch of the step runs on both paths.
    # ``damped``: stiffness damping, K's fourth monomial group (w) in the [K | f] table.
    compiled_or_skip()
    if damped:
        toy_model = damped_toy_model
        assert StreamingEstimator(toy_model)._tables.kf_groups == 4
    times = sample_times(1000.0, 0.4, 0.5, 0.05, seed=21)
    times = np.concatenate([times, times[-1] + 0.007 + times[:200],
                            times[-1] + 0.247 + times[:200], times[-1] + 0.1 + times[:100]])
    stamps = np.round(times * 1e9).astype(np.int64)
    speed = lambda t: 30.0 + 60.0 * np.sin(3.0 * t)  # noqa: E731
    angle = lambda t: 30.0 * t + 20.0 * (1.0 - np.cos(3.0 * t))  # noqa: E731
    runs = {}
    for compiled in (True, False):
        est = StreamingEstimator(toy_model, compiled=compiled)
        assert est.compiled is compiled
        runs[compiled] = [est.update(int(s), float(angle(t)),
                                     float(speed(t)) if with_speed else None)
                          for s, t in zip(stamps, times)]
    assert [s.flags for s in runs[True]] == [s.flags for s in runs[False]]
    assert any(s.flags & SampleFlag.RESET for s in runs[True][1:])
    compiled, numpy_step = samples_fields(runs[True]), samples_fields(runs[False])
    for name, values in numpy_step.items():
        scale = max(np.max(np.abs(values)), 1e-30)
        np.testing.assert_allclose(compiled[name], values, rtol=0.0, atol=1e-9 * scale,
                                   err_msg=name)


@pytest.mark.parametrize('bearings', ['rigid', 'flexible'])
def test_compiled_step_equals_numpy_step_with_the_second_order(bearings):
    """Order 2: the record's second-order outputs, compiled and numpy, equal to rounding."""
    compiled_or_skip()
    model = toys.cho_second_order_model(bearings)
    times = sample_times(1000.0, 0.3, 0.5, 0.05, seed=4)
    times = np.concatenate([times, times[-1] + 0.011 + times[:100]])  # sub-steps too
    speed = 391.0 * np.pi / 30.0
    runs = {}
    for compiled in (True, False):
        est = StreamingEstimator(model, compiled=compiled)
        runs[compiled] = samples_fields([est.update(int(round(t * 1e9)), speed * t, speed)
                                         for t in times])
        assert est._tables.second is not None
    for name, values in runs[False].items():
        scale = max(np.max(np.abs(values)), 1e-30)
        np.testing.assert_allclose(runs[True][name], values, rtol=0.0, atol=1e-9 * scale,
                                   err_msg=name)
    # The same model without its second-order tables: the difference is the second order,
    # the numpy forms of the record's modal state, and the linear part is unchanged.
    linear = StreamingEstimator(dataclasses.replace(model, second_order=None))
    est = StreamingEstimator(model)
    forms = est._tables.second
    for t in times[:300]:
        a, b = (e.update(int(round(t * 1e9)), speed * t, speed) for e in (est, linear))
        np.testing.assert_array_equal(a.modal, b.modal)
        cells, cell_t = model.cell(a.crank_angle)
        scalars = forms.spline_scalars(cells, cell_t)
        second = forms.outputs(scalars, forms.sums(scalars, np.array(a.modal)[None]))[0]
        np.testing.assert_allclose(np.array(a.lever_tip + a.coupler_mid),
                                   np.array(b.lever_tip + b.coupler_mid) + second,
                                   rtol=1e-12, atol=1e-15)
    assert np.abs(second[:2]).max() > 1e-7      # B moves by microns


def test_compiled_step_rejects_bad_second_order_tables():
    compiled_or_skip()
    model = toys.cho_second_order_model('rigid')
    est = StreamingEstimator(model)
    est.update(0, 0.0, 30.0)
    step, t = est._stepper, est._stepper.tables
    row = np.array([1e-3, 1.0, 0.03, 30.0, 0.0, 0.03])

    def call(second):
        native.impl.advance(t.mass, t.damping, t.kf, t.out, t.joint, t.g0,
                            step.cells_per_radian, STAGE1, step.z, step.previous, row,
                            np.empty(0), est.last_record, second)

    values, index = t.second_packed
    z_before = step.z.copy()
    bad_index = index.copy()
    bad_index[3 + 1] = index[0]              # the first gather reads a row beyond V's rows
    with pytest.raises(ValueError, match='out of range'):
        call((values, bad_index))
    bad_count = index.copy()
    bad_count[2] += 1                        # one form term more than the buffers hold
    with pytest.raises(ValueError, match='out of range'):
        call((values, bad_count))
    with pytest.raises(ValueError, match='out of range'):
        call((values[:-1], index))
    with pytest.raises(TypeError, match='int32'):
        call((values, index.astype(np.int64)))
    with pytest.raises(TypeError, match='float64'):
        call((values.astype(np.float32), index))
    with pytest.raises(TypeError, match='values, index'):
        call((values,))
    np.testing.assert_array_equal(step.z, z_before)
    call((values, index))
    assert np.all(np.isfinite(est.last_record))


@pytest.mark.parametrize('compiled', [False, True])
def test_non_finite_step_is_flagged_and_the_next_sample_restarts(toy_model, compiled):
    """A table gone non-finite: that sample is OUT_OF_BOUND (NaN), the next one restarts."""
    if compiled:
        compiled_or_skip()
    est = StreamingEstimator(toy_model, compiled=compiled)
    for n in range(5):
        est.update(n * 10**6, 0.4 + 0.02 * n, 20.0)
    # In place: the compiled update holds the table arrays the estimator was built with.
    kf = est._tables.kf
    column = kf[..., 0].copy()
    kf[..., 0] = np.nan
    bad = est.update(5 * 10**6, 0.5, 20.0)
    assert bad.flags & SampleFlag.OUT_OF_BOUND and 'non-finite' in bad.message
    assert np.all(np.isnan(bad.lever_tip + bad.coupler_mid))
    kf[..., 0] = column
    after = est.update(6 * 10**6, 0.52, 20.0)
    assert after.flags & SampleFlag.RESET and not after.flags & SampleFlag.OUT_OF_BOUND
    assert np.all(np.isfinite(after.lever_tip + after.coupler_mid))
    assert est.out_of_bound == 1


def test_compiled_step_rejects_bad_buffers(toy_model):
    compiled_or_skip()
    est = StreamingEstimator(toy_model)
    est.update(0, 0.0, 30.0)
    step = est._stepper
    t = step.tables
    row = np.array([1e-3, 1.0, 0.03, 30.0, 0.0, 0.03])

    def call(**change):
        args = {'mass': t.mass, 'damping': t.damping, 'kf': t.kf, 'out': t.out,
                'joint': t.joint, 'g0': t.g0, 'cells': step.cells_per_radian, 'c1': STAGE1,
                'z': step.z, 'prev': step.previous, 'rows': row, 'states': np.empty(0),
                'records': est.last_record}
        args.update(change)
        native.impl.advance(*args.values())

    z_before = step.z.copy()
    with pytest.raises(ValueError, match='kf'):
        call(kf=t.kf[:-1])
    with pytest.raises(ValueError, match='damping'):
        call(damping=np.zeros(7, dtype=np.float32))
    with pytest.raises(TypeError, match='float32'):
        call(mass=t.mass.astype(np.float64))
    with pytest.raises(TypeError, match='float64'):
        call(kf=t.kf.astype(np.float32))
    with pytest.raises(ValueError, match='rows'):
        call(rows=row[:5])
    with pytest.raises(ValueError, match='non-positive step'):
        call(rows=np.array([0.0, 1.0, 0.03, 30.0, 0.0, 0.03]))
    with pytest.raises(ValueError, match='records'):
        call(records=np.zeros(5))
    with pytest.raises(ValueError, match='states'):
        call(states=np.zeros(3))
    with pytest.raises((BufferError, ValueError), match='read-only|writable'):
        call(z=np.frombuffer(bytes(z_before.nbytes)))
    np.testing.assert_array_equal(step.z, z_before)
    poisoned = t.kf.copy()
    poisoned[..., 0] = np.nan
    with pytest.raises(ValueError, match='non-finite'):
        call(kf=poisoned)
    np.testing.assert_array_equal(step.z, z_before)
    call()
    assert np.all(np.isfinite(step.z)) and not np.array_equal(step.z, z_before)


def test_compiled_criteria_give_the_python_criteria_bit_for_bit(toy_model):
    """The C criteria (the node's path) equal StreamingEstimator._criteria, zeros included."""
    if not compiled_step_available():
        pytest.skip('compiled step not built')
    estimator = StreamingEstimator(toy_model, compiled=False)
    rng = np.random.default_rng(5)
    for n in range(2000):
        record = rng.normal(size=RECORD_SIZE) * 10.0 ** rng.uniform(-8, 3)
        joint = record[8:]
        if n % 4 == 1:
            joint[0:2] = 0.0                        # a zero reaction: clamped, flagged
        if n % 4 == 2:
            joint[2:4] *= 1e-9                      # near zero
        if n % 7 == 3:
            joint[16:] = 0.0                        # no cycle RMS either: criterion 0
        joint[16:] = np.abs(joint[16:])
        expected = joint_criteria(record[8:].tolist(), estimator.near_zero_fraction)
        got = native.impl.criteria(record, estimator.near_zero_fraction,
                                   REACTION_FLOOR_FRACTION)
        assert got == expected


@pytest.mark.parametrize('compiled', [False, True])
def test_soft_step_stage_interpolation_follows_exact_stages(compiled):
    """Stage 1 by quadratic interpolation in time against stage 1 from the tables."""
    if compiled:
        compiled_or_skip()
    model = toys.cho_second_order_model('flexible')
    assert model.soft is not None and model.step_size < model.size
    times = sample_times(1000.0, 0.4, 0.3, 0.05, seed=5)
    times = np.concatenate([times, times[-1] + 0.011 + times[:100]])  # sub-steps too
    speed = 391.0 * np.pi / 30.0
    runs = {}
    for interpolate in (True, False):
        est = StreamingEstimator(model, compiled=compiled)
        est._stepper = type(est._stepper)(model, est._tables, interpolate_stages=interpolate)
        use_python_path(est)        # the compiled update holds the first step's arrays
        assert (est._stepper.history is not None) == interpolate
        runs[interpolate] = np.array([
            est.update(int(round(t * 1e9)), speed * t, speed).lever_tip for t in times])
    scale = np.abs(runs[False]).max()
    difference = np.abs(runs[True] - runs[False]).max()
    assert 0.0 < difference < 1e-3 * scale


def test_compiled_soft_step_rejects_bad_lift_tables():
    compiled_or_skip()
    model = toys.cho_second_order_model('flexible')
    est = StreamingEstimator(model)
    est.update(0, 0.0, 30.0)
    step, t = est._stepper, est._stepper.tables
    row = np.array([1e-3, 1.0, 0.03, 30.0, 0.0, 0.03])
    phi, dphi, residual = t.lift.packed()

    def call(lift):
        native.impl.advance(t.mass, t.damping, t.kf, t.out, t.joint, t.g0,
                            step.cells_per_radian, STAGE1, step.z, step.previous, row,
                            np.empty(0), est.last_record, t.second_packed, lift)

    with pytest.raises(ValueError, match='phi'):
        call((phi[:-1], dphi, residual, step.lifted))
    with pytest.raises(TypeError, match='float32'):
        call((phi.astype(float), dphi, residual, step.lifted))
    with pytest.raises(ValueError, match='lifted'):
        call((phi, dphi, residual, step.lifted[:-1]))
    with pytest.raises(ValueError, match='history'):
        call((phi, dphi, residual, step.lifted, step.history[:-1]))
    z = step.z.copy()
    call((phi, dphi, residual, step.lifted, step.history))
    assert not np.array_equal(step.z, z)


def _constant_speed_rows(count, speed, seed):
    """Step rows (h, sub-steps, angle, speed, accel, advance) of a jittered 1 kHz signal."""
    rng = np.random.default_rng(seed)
    dt_ns = np.round(1e6 * (1.0 + 0.3 * rng.uniform(-1.0, 1.0, count))).astype(np.int64)
    dt_ns[count // 3] = 3 * MAX_SUBSTEP_NS // 2         # one row split into sub-steps
    angles = np.mod(speed * np.cumsum(dt_ns) * 1e-9, 2.0 * np.pi)
    return np.column_stack([dt_ns * 1e-9, -(-dt_ns // MAX_SUBSTEP_NS), angles,
                            np.full(count, speed), np.zeros(count), speed * dt_ns * 1e-9])


def _started(model, speed):
    est = StreamingEstimator(model, warm_start=False)
    est.update(0, 0.0, speed)
    return est


@pytest.mark.parametrize('soft', [False, True])
def test_batch_records_in_a_thread_of_their_own_equal_one_thread(toy_model, soft):
    """A long batch records its rows beside the steps: the same doubles as short batches."""
    compiled_or_skip()
    model = toys.cho_second_order_model('flexible') if soft else toy_model
    assert (model.soft is not None) == soft
    speed = 391.0 * np.pi / 30.0
    rows = _constant_speed_rows(1500, speed, seed=3)
    width = 2 * model.size
    outcomes = []
    for batch in (rows.shape[0], 100):      # one long batch; short ones, recorded in turn
        est = _started(model, speed)
        states = np.full((rows.shape[0], width), np.nan)
        records = np.full((rows.shape[0], RECORD_SIZE), np.nan)
        for first in range(0, rows.shape[0], batch):
            part = slice(first, first + batch)
            est.step_rows(rows[part], states[part], records[part])
        outcomes.append((states, records, est._stepper.z.copy(), est.state.copy()))
    (states, records, z, state), (states1, records1, z1, state1) = outcomes
    assert np.all(np.isfinite(records)) and np.abs(records[:, :4]).max() > 0.0
    np.testing.assert_array_equal(states, states1)
    np.testing.assert_array_equal(records, records1)
    np.testing.assert_array_equal(z, z1)
    np.testing.assert_array_equal(state, state1)


def test_batch_that_fails_midway_keeps_the_records_of_the_rows_before():
    compiled_or_skip()
    model = toys.cho_second_order_model('flexible')
    speed = 391.0 * np.pi / 30.0
    rows = _constant_speed_rows(1000, speed, seed=4)
    rows[700, 0] = 0.0                  # a row with no step: refused there
    results = []
    for parts in ((slice(0, 1000),), (slice(0, 100),) + tuple(
            slice(first, first + 100) for first in range(100, 1000, 100))):
        est = _started(model, speed)
        states = np.full((1000, 2 * model.size), np.nan)
        records = np.full((1000, RECORD_SIZE), np.nan)
        with pytest.raises(ValueError, match='non-positive step'):
            for part in parts:
                est.step_rows(rows[part], states[part], records[part])
        results.append((states, records, est.state.copy()))
    (states, records, state), (states1, records1, state1) = results
    assert np.all(np.isfinite(records[:700])) and np.all(np.isnan(records[700:]))
    assert np.all(np.isfinite(states[:700])) and np.all(np.isnan(states[700:]))
    np.testing.assert_array_equal(states, states1)
    np.testing.assert_array_equal(records, records1)
    np.testing.assert_array_equal(state, state1)
