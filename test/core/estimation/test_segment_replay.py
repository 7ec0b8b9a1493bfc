"""One segment replayed in batches (segment_replay.replay) against the streaming node."""

import dataclasses

import estimation_toys as toys
from estimation_toys import compiled_or_skip, sample_times, SPEED_MAX, toy_forces
from flexlink_ros.core import options as core_options
from flexlink_ros.core.estimation.segment_replay import replay
from flexlink_ros.core.estimation.step import MAX_SUBSTEP_NS
from flexlink_ros.core.estimation.streaming import StreamingEstimator
from flexlink_ros.core.numerics import relative_rms as numerics_relative_rms
from flexlink_ros.core.reduction import build, mechanism_model
from flexlink_ros.core.reduction import reference as reduction_reference
from flexlink_ros.ros import parameters as node_params
from flexlink_ros.studies import plan, synthetic
import numpy as np
import pytest
from toy_system import toy_samples, ZETA


@pytest.fixture(scope='module')
def toy_model():
    return toys.toy_model()


@pytest.mark.parametrize('with_speed', [True, False])
def test_replay_equals_streaming(toy_model, with_speed):
    times = sample_times(1000.0, 0.5, 0.3, 0.05, seed=15)
    stamps = np.round(times * 1e9).astype(np.int64)
    speed = lambda t: 30.0 + 40.0 * t  # noqa: E731
    angle = lambda t: 30.0 * t + 20.0 * t * t  # noqa: E731
    est = StreamingEstimator(toy_model)
    streamed = [est.update(int(s), angle(t), speed(t) if with_speed else None)
                for s, t in zip(stamps, times)]
    batch = replay(toy_model, stamps, angle(times), speed(times) if with_speed else None)
    np.testing.assert_allclose(batch['lever_tip'], [s.lever_tip for s in streamed],
                               rtol=1e-7, atol=1e-12)
    np.testing.assert_allclose(batch['coupler_mid'], [s.coupler_mid for s in streamed],
                               rtol=1e-7, atol=1e-12)
    np.testing.assert_allclose(batch['crank_accel'], [s.crank_accel for s in streamed])


def test_replay_equals_streaming_across_long_steps(toy_model):
    """Steps of 0.5-40 ms (sub-stepped alike in both paths)."""
    rng = np.random.default_rng(8)
    steps_ns = (10 ** rng.uniform(5.7, 7.6, 300)).astype(np.int64)
    assert steps_ns.max() > 10 * MAX_SUBSTEP_NS
    stamps = np.concatenate([[0], np.cumsum(steps_ns)])
    times = stamps * 1e-9
    speed = 30.0 + 10.0 * np.sin(times)
    angle = 30.0 * times - 10.0 * np.cos(times)
    est = StreamingEstimator(toy_model)
    streamed = [est.update(int(s), a, w) for s, a, w in zip(stamps, angle, speed)]
    batch = replay(toy_model, stamps, angle, speed)
    for key in ('lever_tip', 'coupler_mid'):
        np.testing.assert_allclose(batch[key], [getattr(s, key) for s in streamed],
                                   rtol=1e-7, atol=1e-12)


@pytest.mark.parametrize('modes, static', [(4, 2), (1, 0)])
def test_compiled_replay_equals_numpy_replay(modes, static):
    # r = 1 too: the compiled step's scratch sizes hold for the smallest model.
    compiled_or_skip()
    forces, _ = toy_forces(32)
    toy_model = build.reduce_samples(toy_samples(grid=32), modes=modes, static=static,
                                     speed_max=SPEED_MAX, zeta=ZETA, forces=forces)
    assert toy_model.size == modes + static
    times = sample_times(2000.0, 0.6, 0.5, 0.1, seed=5)
    times[300:] += 0.013       # one gap that takes sub-steps
    stamps = np.round(times * 1e9).astype(np.int64)
    angles, speeds = 40.0 * times, np.full(times.size, 40.0)
    fast = replay(toy_model, stamps, angles, speeds)
    slow = replay(toy_model, stamps, angles, speeds, compiled=False)
    for name in ('lever_tip', 'coupler_mid', 'modal', 'force', 'force_dot', 'rms2'):
        scale = np.max(np.abs(slow[name]))
        np.testing.assert_allclose(fast[name], slow[name], rtol=0.0, atol=1e-9 * scale,
                                   err_msg=name)


@pytest.fixture(scope='module')
def cho():
    pytest.importorskip('flexlink_ros.core.fe.linkage')
    return toys.cho1992()


def test_node_default_model_meets_its_budget_against_the_scene_reference(cho):
    """The node's default (flexible crank, 4 elements, 24 + 2) against the 6-element scene."""
    options = node_params.default_model_options()
    assert not options.rigid_crank and options.geometric_stiffness
    model = mechanism_model.model_for_mechanism(cho, options)
    # The node's default order (2) on both sides: the reference adds the second order too.
    scene = plan.scene_options(cho, core_options.ModelOptions.linear(bearings=options.bearings,
                                                                     order=options.order))
    assert options.order == 2 and scene.order == 2
    rpm = 391.0
    period = 60.0 / rpm
    stamps, angles, speeds = synthetic.synthetic_signal(rpm, 2.0 * period, 1000.0, 0.3, 3)
    mask = synthetic.last_revolution(stamps, rpm)
    out = replay(model, stamps, angles, speeds)
    speed = rpm * 2.0 * np.pi / 60.0
    reference = reduction_reference.reference_response(cho, scene, speed, angles[mask])
    errors = {key: numerics_relative_rms(out[key][mask], reference[key])
              for key in ('coupler_mid', 'lever_tip')}
    # Measured 1.04 % / 0.94 %; the budget the node states is 2 %.
    assert max(errors.values()) < core_options.PLANNED_TOLERANCE, errors
    # The rigid crank of the paper's cases would miss the same reference by far.
    rigid_scene = dataclasses.replace(scene, rigid_crank=True, elements_per_link=4)
    rigid = reduction_reference.reference_response(cho, rigid_scene, speed, angles[mask])
    assert numerics_relative_rms(rigid['coupler_mid'], reference['coupler_mid']) > 0.2


def test_order_2_replay_equals_streaming_and_its_numpy_replay():
    """The offline estimate of order 2: the streamed numbers, compiled equal to numpy."""
    model = toys.cho_second_order_model('flexible')
    times = sample_times(1000.0, 0.5, 0.3, 0.05, seed=8)
    stamps = np.round(times * 1e9).astype(np.int64)
    speed = 269.0 * np.pi / 30.0
    angles, speeds = speed * times, np.full(times.size, speed)
    fast = replay(model, stamps, angles, speeds)
    slow = replay(model, stamps, angles, speeds, compiled=False)
    est = StreamingEstimator(model)
    streamed = [est.update(int(s), float(a), speed) for s, a in zip(stamps, angles)]
    for key in ('lever_tip', 'coupler_mid'):
        scale = np.max(np.abs(slow[key]))
        np.testing.assert_allclose(fast[key], slow[key], rtol=0.0, atol=1e-9 * scale)
        np.testing.assert_allclose(fast[key], [getattr(s, key) for s in streamed],
                                   rtol=1e-7, atol=1e-12)
    linear = replay(dataclasses.replace(model, second_order=None), stamps, angles, speeds)
    np.testing.assert_array_equal(linear['modal'], fast['modal'])
    assert not np.array_equal(linear['lever_tip'], fast['lever_tip'])
