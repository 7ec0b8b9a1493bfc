"""Hostile input to the streaming estimator (issue #12 items 2-4): outliers, bounds, storms."""

import logging
import math
import time

import numpy as np
import pytest
from test_estimator import SPEED_MAX, sample_times, toy_forces
from test_reduced import ZETA, toy_samples

from flexlink_ros.core.estimation import streaming as core_estimator
from flexlink_ros.core.reduction import model as reduced
from flexlink_ros.errors import OutlierSample
from flexlink_ros.core.estimation.streaming import InputGate, SampleFlag, StreamingEstimator

SPEED = 41.0            # rad/s (391 rpm)
RATE_HZ = 1000.0
PATHS = [pytest.param(False, id='numpy'),
         pytest.param(True, id='compiled', marks=pytest.mark.skipif(
             not core_estimator.compiled_step_available(), reason='compiled step not built'))]


@pytest.fixture(scope='module')
def toy_model():
    forces, _ = toy_forces(64)
    return reduced.reduce_samples(toy_samples(grid=64), modes=4, static=2, speed_max=SPEED_MAX,
                                  zeta=ZETA, forces=forces)


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


@pytest.mark.parametrize('compiled', PATHS)
@pytest.mark.parametrize('poison', [(1.7e308, -1.7e308), (1e6,), (1e4,)],
                         ids=['plus-minus-1.7e308', '1e6', '1e4'])
def test_poison_speed_is_an_outlier_and_leaves_every_later_output_unchanged(
        toy_model, compiled, poison):
    events = clean_signal(1.0)
    at = 400
    # The poison between two samples, with a plausible angle: only its speed is absurd.
    stamp, angle, _ = events[at]
    bad = [(stamp - 300_000 + 100_000 * k, angle - 0.01, speed) for k, speed in
           enumerate(poison)]
    clean, _ = feed(StreamingEstimator(toy_model, compiled=compiled), events)
    estimator = StreamingEstimator(toy_model, compiled=compiled)
    poisoned, refused = feed(estimator, events[:at] + bad + events[at:])
    assert [s for s, _ in refused] == [s for s, _, _ in bad]
    assert all('beyond the plausible' in reason for _, reason in refused)
    assert estimator.outliers == len(poison)
    for stamp, sample in poisoned.items():
        np.testing.assert_array_equal(outputs(sample), outputs(clean[stamp]))
        # Only the OUTLIER flag tells them apart, on the first sample after the poison.
        expected = clean[stamp].flags | (SampleFlag.OUTLIER if stamp == events[at][0] else 0)
        assert sample.flags == expected


@pytest.mark.parametrize('compiled', PATHS)
def test_speed_jump_is_an_outlier_and_a_lasting_change_a_new_regime(toy_model, compiled):
    """A jump the crank cannot make is skipped; REGIME_SAMPLES agreeing ones restart."""
    events = clean_signal(0.6)
    # accel_limit 500 rad/s^2: the jump stays implausible over the REGIME_SAMPLES ms.
    estimator = StreamingEstimator(toy_model, compiled=compiled, accel_limit=500.0)
    gate = InputGate(SPEED_MAX, estimator.accel_limit)
    samples, refused = feed(estimator, events[:300])
    stamp, angle, _ = events[299]
    # -120 rad/s is within the plausible range (2 x 65) but 161 rad/s from the last speed.
    jump = -120.0
    assert abs(jump) <= gate.speed_bound
    assert abs(jump - SPEED) > gate.jump_accel * 6e-3 + gate.jump_allowance
    regime = [(stamp + k * 1_000_000, angle + jump * k * 1e-3, jump) for k in range(1, 40)]
    after, refused = feed(estimator, regime)
    count = core_estimator.REGIME_SAMPLES
    assert [s for s, _ in refused] == [s for s, _, _ in regime[:count - 1]]
    assert all('speed jumped' in reason for _, reason in refused)
    first = after[regime[count - 1][0]]
    assert first.flags & SampleFlag.RESET and first.flags & SampleFlag.OUTLIER
    assert 'new regime' in first.message
    later = [after[s] for s, _, _ in regime[count:]]
    assert all(s.crank_speed == jump and not s.flags & SampleFlag.OUTLIER for s in later)


@pytest.mark.parametrize('compiled', PATHS)
def test_angle_the_crank_cannot_reach_is_an_outlier(toy_model, compiled):
    """Without a measured speed: an advance beyond the plausible speed times the interval."""
    events = [(stamp, angle, None) for stamp, angle, _ in clean_signal(0.8)]
    at = 500
    stamp, angle, _ = events[at]
    bad = [(stamp - 400_000, angle + 2.0, None)]
    clean, _ = feed(StreamingEstimator(toy_model, compiled=compiled), events)
    poisoned, refused = feed(StreamingEstimator(toy_model, compiled=compiled),
                             events[:at] + bad + events[at:])
    assert len(refused) == 1 and 'angle moved' in refused[0][1]
    for stamp, sample in poisoned.items():
        np.testing.assert_array_equal(outputs(sample), outputs(clean[stamp]))


def fuzz_events(rng, count, around_ns, speed):
    """Mixed fuzz: plausible and absurd speeds, angles and stamps (some backward)."""
    events = []
    for _ in range(count):
        stamp = around_ns + int(rng.integers(-20_000_000, 2_000_000))
        angle = float(rng.choice([rng.uniform(0, 7), rng.uniform(-1e3, 1e3),
                                  10 ** rng.uniform(0, 300)]))
        magnitude = float(rng.choice([speed, rng.uniform(-200, 200), 10 ** rng.uniform(-3, 308)]))
        events.append((stamp, angle, magnitude * float(rng.choice([-1, 1]))))
    return events


@pytest.mark.parametrize('compiled', PATHS)
def test_mixed_fuzz_never_gives_a_deflection_beyond_the_bound(toy_model, compiled):
    rng = np.random.default_rng(12)
    events = clean_signal(0.5)
    estimator = StreamingEstimator(toy_model, compiled=compiled)
    before, _ = feed(estimator, events)
    fuzz = fuzz_events(rng, 3000, events[-1][0], SPEED)
    samples, refused = [], 0
    for event in fuzz:
        try:
            samples.append(estimator.update(*event))
        except OutlierSample:
            refused += 1
    assert refused == estimator.outliers and refused > 1000
    numbers = [s for s in samples if not s.flags & SampleFlag.OUT_OF_BOUND]
    assert numbers and all(largest(s) <= estimator.deflection_bound_m for s in numbers)
    for sample in samples:
        if sample.flags & SampleFlag.OUT_OF_BOUND:
            assert all(math.isnan(d) for d in sample.lever_tip + sample.coupler_mid)
    # Valid input after the fuzz: every sample accepted, finite, within the bound.
    after, refused_after = feed(estimator, [(s + 10**9, a, w) for s, a, w in clean_signal(0.3)])
    assert not refused_after
    assert all(math.isfinite(largest(s)) and largest(s) <= estimator.deflection_bound_m
               for s in after.values())


def test_deflection_bound_is_derived_from_the_model_and_above_normal_running(toy_model):
    estimator = StreamingEstimator(toy_model)
    peak = estimator.quasi_static_peak()
    assert estimator.deflection_bound_m == pytest.approx(
        core_estimator.DEFLECTION_SAFETY_FACTOR / (2 * ZETA) * peak)
    # Running at any speed in the range (warm start: the periodic state) stays well inside.
    for speed in (10.0, SPEED, SPEED_MAX):
        events = [(s, speed * (s - 10**9) * 1e-9, speed) for s, _, _ in clean_signal(0.2)]
        samples, _ = feed(StreamingEstimator(toy_model), events)
        assert max(largest(s) for s in samples.values()) < 0.2 * estimator.deflection_bound_m


@pytest.mark.parametrize('compiled', PATHS)
def test_out_of_bound_estimate_is_nan_and_the_next_sample_restarts(toy_model, compiled):
    events = clean_signal(0.3)
    estimator = StreamingEstimator(toy_model, compiled=compiled)
    samples, _ = feed(estimator, events[:100])
    normal = max(largest(s) for s in samples.values())
    estimator.deflection_bound_m = 0.5 * normal
    flagged, _ = feed(estimator, events[100:300])
    out = [s for s in flagged.values() if s.flags & SampleFlag.OUT_OF_BOUND]
    assert out and estimator.out_of_bound == len(out)
    assert all(math.isnan(largest(s)) and 'beyond the bound' in s.message for s in out)
    kept = [s for s in flagged.values() if not s.flags & SampleFlag.OUT_OF_BOUND]
    assert all(largest(s) <= 0.5 * normal for s in kept)
    # Each out-of-bound sample restarts the state: the next one is a RESET.
    stamps = sorted(flagged)
    for before, after in zip(stamps, stamps[1:]):
        if flagged[before].flags & SampleFlag.OUT_OF_BOUND:
            assert flagged[after].flags & SampleFlag.RESET


@pytest.mark.parametrize('compiled', PATHS)
def test_non_finite_filter_state_is_out_of_bound_and_the_next_sample_restarts(
        toy_model, compiled):
    events = clean_signal(0.3)
    estimator = StreamingEstimator(toy_model, compiled=compiled)
    feed(estimator, events[:50])
    # The filter's speed fit gone non-finite (as +1.7e308 then -1.7e308 did before).
    if compiled:
        estimator.rate_filter._state[core_estimator._FILTER_SPEED_FIT:
                                     core_estimator._FILTER_SPEED_FIT + 8] = math.inf
    else:
        estimator.rate_filter._speed_fit.s[1] = math.inf
    bad = estimator.update(*events[50])
    assert bad.flags & SampleFlag.OUT_OF_BOUND and 'non-finite' in bad.message
    after, refused = feed(estimator, events[51:])
    assert not refused and after[events[51][0]].flags & SampleFlag.RESET
    assert all(math.isfinite(largest(s)) for s in after.values())


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
    with caplog.at_level(logging.WARNING, logger='flexlink_ros.core.estimation.streaming'):
        stormed, refused = feed(estimator, storm)
    elapsed = time.monotonic() - start
    assert not refused and len(stormed) == 1000
    # The token bucket: WARM_START_BURST at once, then WARM_START_RATE_HZ per second.
    allowed = core_estimator.WARM_START_BURST + math.ceil(
        elapsed * core_estimator.WARM_START_RATE_HZ)
    warm = estimator.warm_starts - before
    assert 1 <= warm <= allowed
    assert estimator.cold_starts == 1000 - warm
    assert sum(1 for s in stormed.values() if s.flags & SampleFlag.COLD_START) == \
        estimator.cold_starts
    warnings = [r for r in caplog.records if 'warm start skipped' in r.getMessage()]
    period_s = core_estimator.WARNING_PERIOD_S
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
