"""Warm starts: the periodic state from the first revolution, the kept orbit, the rate limit."""

import logging
import math
import time

import estimation_toys as toys
from estimation_toys import (clean_signal, deflections, feed, PATHS, periodic_outputs,
                             relative_rms, sample_times, SPEED, stream)
from flexlink_ros.core.estimation import throttled_log, warm_start
from flexlink_ros.core.estimation.sample import SampleFlag
from flexlink_ros.core.estimation.streaming import StreamingEstimator
import numpy as np
import pytest


@pytest.fixture(scope='module')
def toy_model():
    return toys.toy_model()


@pytest.mark.parametrize('jitter', [0.0, 0.3])
def test_warm_start_matches_periodic_state_from_the_first_revolution(toy_model, jitter):
    speed = 41.0
    times = sample_times(1000.0, 0.3, jitter, 0.0, seed=8)
    samples = stream(StreamingEstimator(toy_model), times, lambda t: 0.2 + speed * t,
                     lambda t: speed)
    exact = periodic_outputs(toy_model, speed, 0.2 + speed * times)
    assert samples[0].flags & SampleFlag.WARM_START and samples[0].flags & SampleFlag.RESET
    assert np.all(relative_rms(deflections(samples), exact) < 0.01)


def test_cold_start_converges_to_the_periodic_state(toy_model):
    speed = 30.0
    times = sample_times(1000.0, 3.0, 0.3, 0.05, seed=9)
    samples = stream(StreamingEstimator(toy_model, warm_start=False), times,
                     lambda t: speed * t, lambda t: speed)
    late = times > 2.0
    exact = periodic_outputs(toy_model, speed, speed * times[late])
    assert np.all(relative_rms(deflections(samples)[late], exact) < 0.01)


def test_missing_speed_is_derived_and_warm_start_follows(toy_model):
    speed = 41.0
    times = sample_times(1000.0, 0.3, 0.3, 0.0, seed=14)
    samples = stream(StreamingEstimator(toy_model), times, lambda t: speed * t,
                     lambda t: speed, with_speed=False)
    assert all(s.flags & SampleFlag.SPEED_FROM_ANGLE for s in samples)
    started = [i for i, s in enumerate(samples) if s.flags & SampleFlag.WARM_START]
    assert started and started[0] <= 3
    exact = periodic_outputs(toy_model, speed, speed * times)
    after = slice(started[0], None)
    assert np.all(relative_rms(deflections(samples)[after], exact[after]) < 0.01)


@pytest.mark.parametrize('speed', [30.0, -45.0])
def test_warm_start_reuses_the_periodic_orbit(toy_model, speed):
    # A second warm start at the same speed interpolates the kept orbit: the same state as
    # shooting afresh from that angle, to the interpolation's accuracy; another speed shoots.
    kept = StreamingEstimator(toy_model)
    kept.periodic_state(0.4, speed)
    scale_q = scale_v = 0.0
    for angle in (0.4, 1.234, 3.0, 6.2):
        q, v = kept.periodic_state(angle, speed * (1.0 + 0.5e-4))
        q_ref, v_ref = StreamingEstimator(toy_model).periodic_state(angle, speed)
        scale_q = max(scale_q, np.max(np.abs(q_ref)))
        scale_v = max(scale_v, np.max(np.abs(v_ref)))
        np.testing.assert_allclose(q, q_ref, rtol=0, atol=1e-6 * np.max(np.abs(q_ref)))
        np.testing.assert_allclose(v, v_ref, rtol=0, atol=1e-3 * np.max(np.abs(v_ref)))
    assert scale_q > 0.0 and scale_v > 0.0
    assert kept.orbit[0] == speed
    other = speed * (1.0 + 10 * warm_start.WARM_START_SPEED_TOLERANCE)
    q, _ = kept.periodic_state(1.0, other)
    assert kept.orbit[0] == other
    np.testing.assert_array_equal(q, StreamingEstimator(toy_model).periodic_state(1.0, other)[0])


@pytest.mark.parametrize('compiled', PATHS)
def test_reset_storm_degrades_to_cold_starts_and_valid_input_behind_it_goes_on(
        toy_model, compiled, caplog):
    """1000 backward stamps with a new speed each: a few warm starts, then cold starts."""
    events = clean_signal(3.0)
    split = 1000
    estimator = StreamingEstimator(toy_model, compiled=compiled)
    feed(estimator, events[:split])
    end = events[split - 1][0]
    before = estimator.warm_starts          # the first sample's
    # Each stamp 1 us before the previous (the crank's angle there), a new speed each time.
    storm = [(end - 1000 * (k + 1), SPEED * (end - 1000 * (k + 1) - 10**9) * 1e-9 + 0.3,
              20.0 + 0.02 * k) for k in range(1000)]
    start = time.monotonic()
    with caplog.at_level(logging.WARNING, logger='flexlink_ros.core.estimation.warm_start'):
        stormed, refused = feed(estimator, storm)
    elapsed = time.monotonic() - start
    assert not refused and len(stormed) == 1000
    # The token bucket: WARM_START_BURST at once, then WARM_START_RATE_HZ per second.
    allowed = warm_start.WARM_START_BURST + math.ceil(
        elapsed * warm_start.WARM_START_RATE_HZ)
    warm = estimator.warm_starts - before
    assert 1 <= warm <= allowed
    assert estimator.cold_starts == 1000 - warm
    assert sum(1 for s in stormed.values() if s.flags & SampleFlag.COLD_START) == \
        estimator.cold_starts
    warnings = [r for r in caplog.records if 'warm start skipped' in r.getMessage()]
    period_s = throttled_log.WARNING_PERIOD_S
    assert 1 <= len(warnings) <= 1 + math.ceil(elapsed / period_s)
    # Valid input behind the storm: every sample processed; settled, it equals a clean run.
    behind, refused = feed(estimator, events[split:])
    assert not refused and len(behind) == len(events) - split
    clean, _ = feed(StreamingEstimator(toy_model, compiled=compiled), events)
    late = [s for s, _, _ in events if s > events[-1][0] - 500_000_000]
    got = np.array([behind[s].lever_tip + behind[s].coupler_mid for s in late])
    want = np.array([clean[s].lever_tip + clean[s].coupler_mid for s in late])
    # The storm's last start was cold: its transient decays at the slowest modal rate
    # (about 3.6 /s for the toy model), e^(-3.6 x 1.5 s) = 0.5 % of it left here.
    assert np.max(np.abs(got - want)) < 1e-2 * np.max(np.abs(want))


@pytest.fixture(scope='module')
def cho_model():
    pytest.importorskip('flexlink_ros.core.fe.linkage')
    return toys.cho_second_order_model('flexible')


@pytest.mark.parametrize('rpm', [269.0, 600.0])
def test_the_warm_starts_shooting_is_converged_in_its_step(cho_model, rpm):
    """The periodic state of WARM_START_STEPS a revolution against 4 times as many steps."""
    estimator = StreamingEstimator(cho_model)
    speed = rpm * math.pi / 30.0
    steps = warm_start.WARM_START_STEPS
    states = [warm_start.periodic_response(cho_model, speed, start_angle=0.3, steps=n,
                                           blocks=estimator.system_blocks)
              for n in (steps, 4 * steps)]
    (_, q, v), (_, fine_q, fine_v) = states
    for coarse, fine in ((q, fine_q[::4]), (v, fine_v[::4])):    # the same instants
        span = np.max(np.linalg.norm(fine - fine.mean(axis=0), axis=1))
        # Radau IIA of order 3: 4 times the steps shrink the error 64 times, so the
        # difference is the coarse orbit's own error: below the estimate's start transient
        # (0.2-1 % of the deflections' span).
        assert np.max(np.linalg.norm(coarse - fine, axis=1)) < 5e-4 * span
