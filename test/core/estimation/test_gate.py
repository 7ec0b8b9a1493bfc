"""Hostile input (wild speeds, reset storms): outliers skipped, new regimes, repeats, restarts."""

import logging
import math

import estimation_toys as toys
from estimation_toys import clean_signal, feed, largest, outputs, PATHS, SPEED, SPEED_MAX
from flexlink_ros.core.estimation.gate import InputGate, REGIME_SAMPLES
from flexlink_ros.core.estimation.sample import SampleFlag
from flexlink_ros.core.estimation.streaming import StreamingEstimator
from flexlink_ros.errors import ConflictingSample, OutlierSample
import numpy as np
import pytest


@pytest.fixture(scope='module')
def toy_model():
    return toys.toy_model()


def test_repeated_and_backward_stamps(toy_model, caplog):
    est = StreamingEstimator(toy_model)
    first = est.update(1_000_000, 0.5, 40.0)
    second = est.update(2_000_000, 0.54, 40.0)
    repeated = est.update(2_000_000, 0.54, 40.0)
    assert repeated.flags & SampleFlag.REPEATED
    assert repeated.lever_tip == second.lever_tip
    with caplog.at_level(logging.WARNING, logger='flexlink_ros.core.estimation.streaming'):
        back = est.update(1_500_000, 0.52, 40.0)
        gap = est.update(1_500_000 + 2_000_000_000, 0.6, 40.0)
    assert back.flags & SampleFlag.RESET and 'back' in back.message
    assert gap.flags & SampleFlag.RESET and 'gap' in gap.message
    assert 'estimator reset' in caplog.text
    for sample in (first, second, back, gap):
        assert np.all(np.isfinite(sample.lever_tip + sample.coupler_mid))
    # Same stamp, different angle: neither a repeat nor a restart but a conflict, skipped.
    with pytest.raises(ConflictingSample, match='conflicting'):
        est.update(1_500_000 + 2_000_000_000, 0.7, 40.0)


@pytest.mark.parametrize('compiled', PATHS)
def test_same_stamp_other_angle_is_conflicting_and_changes_nothing(toy_model, compiled):
    # Pairs of messages with one stamp and angles 0.3 rad apart: the first of each pair is
    # estimated, the second refused; the outputs are those of the first ones alone.
    events = clean_signal(0.4)
    alone = StreamingEstimator(toy_model, compiled=compiled)
    expected = [alone.update(*event) for event in events]
    est = StreamingEstimator(toy_model, compiled=compiled)
    got, refused = [], 0
    for stamp, angle, speed in events:
        got.append(est.update(stamp, angle, speed))
        with pytest.raises(ConflictingSample):
            est.update(stamp, angle + 0.3, speed)
        refused += 1
    assert refused == len(events) > 100
    assert not any(sample.flags & SampleFlag.RESET for sample in got[1:])
    np.testing.assert_array_equal([g.lever_tip for g in got], [e.lever_tip for e in expected])
    gate = InputGate(SPEED_MAX, 1e4)
    assert gate.decide(5, 0.1, None)[0] == InputGate.START
    assert gate.decide(5, 0.4, None)[0] == InputGate.CONFLICTING
    assert gate.decide(5, 0.1, None)[0] == InputGate.REPEATED


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
    count = REGIME_SAMPLES
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


@pytest.mark.parametrize('back_ns, text', [(500_000, 'stamp went back by 0.5 ms'),
                                           (1, 'stamp went back by 1e-06 ms'),
                                           (3_000_000_000, 'stamp went back by 3000 ms')])
def test_a_backward_stamp_is_said_with_its_magnitude_in_ms(back_ns, text):
    gate = InputGate(SPEED_MAX, 1e4)
    gate.decide(10_000_000_000, 0.5, SPEED)
    kind, flags, message = gate.decide(10_000_000_000 - back_ns, 0.5, SPEED)
    assert kind == InputGate.START and message == text


def test_a_same_stamp_with_another_angle_is_never_said_as_minus_zero():
    gate = InputGate(SPEED_MAX, 1e4)
    gate.decide(10_000_000_000, 0.5, SPEED)
    _, _, message = gate.decide(10_000_000_000, 0.8, SPEED)
    assert message and '-0' not in message and 'went back' not in message
