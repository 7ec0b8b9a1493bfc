"""
The nonlinear model following accepted samples (core/estimation/nonlinear_follow.py).

At reduced size (2 elements per link): fed the samples of one segment it gives
estimate_nonlinear's outputs (to the rounding of the angle's unwrapping: a running sum here,
a cumulative sum there); a gap beyond the reset gap starts it again at the quasi-static
deflection; the validity indicator is the slope rule stated in the module.
"""

import math

from flexlink_ros.core.estimation.nonlinear_follow import nonlinear_validity, NonlinearFollower
from flexlink_ros.core.estimation.nonlinear_stream import (estimate_nonlinear, NonlinearStepper,
                                                           VON_KARMAN_SLOPE)
from flexlink_ros.core.validity import VALIDITY_THRESHOLD
import numpy as np
import pytest
from small_nonlinear import small_nonlinear_tables

SPEED = 391.0 * math.pi / 30.0


@pytest.fixture(scope='module')
def tables():
    return small_nonlinear_tables(1e-4)


def _signal(count, rate_hz=1000.0, seed=3):
    """Return a jittered 391 rpm crank: stamps [ns], wrapped angles, speeds."""
    steps = (1.0 + 0.3 * np.random.default_rng(seed).uniform(-1.0, 1.0, count - 1)) / rate_hz
    time_s = np.concatenate([[0.0], np.cumsum(steps)])
    return (np.round(time_s * 1e9).astype(np.int64), np.mod(SPEED * time_s, 2.0 * math.pi),
            np.full(count, SPEED))


def _assert_same(mine, reference):
    scale = np.abs(reference).max()
    assert np.abs(mine - reference).max() <= 1e-9 * scale


def test_one_segment_gives_estimate_nonlinear(tables):
    stamps, angles, speeds = _signal(600)
    reference = estimate_nonlinear(tables, stamps, angles, speeds)
    follower = NonlinearFollower(tables, reset_gap_s=0.5)
    mine = np.array([follower.sample(int(s), float(a), float(w))
                     for s, a, w in zip(stamps, angles, speeds)])
    _assert_same(mine, reference['outputs'])
    assert follower.counts == {'samples': 600, 'refused_samples': 0, 'restarts': 0,
                               'beyond_von_karman_samples': 0}
    assert follower.slope_max == pytest.approx(np.nanmax(reference['link_slope']), rel=1e-12)
    assert np.ptp(mine[:, 2]) > 1e-5     # a real response, not the static deflection


def test_a_gap_beyond_the_reset_gap_starts_again_at_the_quasi_static_deflection(tables):
    stamps, angles, speeds = _signal(400)
    stamps[200:] += 2_000_000_000        # a 2 s gap
    follower = NonlinearFollower(tables, reset_gap_s=0.5)
    mine = np.array([follower.sample(int(s), float(a), float(w))
                     for s, a, w in zip(stamps, angles, speeds)])
    assert follower.counts['restarts'] == 1
    start = NonlinearStepper(tables)
    start.start(float(angles[200]), SPEED)
    assert np.array_equal(mine[200], start.outputs(float(angles[200])))
    after = estimate_nonlinear(tables, stamps[200:], angles[200:], speeds[200:])
    _assert_same(mine[200:], after['outputs'])


def test_validity_is_the_threshold_at_the_slope_limit():
    assert nonlinear_validity([0.5 * VON_KARMAN_SLOPE, VON_KARMAN_SLOPE]) == \
        pytest.approx(VALIDITY_THRESHOLD)
    assert nonlinear_validity([0.5 * VON_KARMAN_SLOPE]) == pytest.approx(
        VALIDITY_THRESHOLD / 4.0)
    assert nonlinear_validity([]) == 0.0
    assert math.isnan(nonlinear_validity([math.nan]))


def test_validity_follows_the_last_samples_slope(tables):
    stamps, angles, speeds = _signal(300)
    follower = NonlinearFollower(tables, reset_gap_s=0.5)
    follower.sample(int(stamps[0]), float(angles[0]), SPEED)
    assert math.isnan(follower.validity)     # a start is not judged
    for s, a in zip(stamps[1:], angles[1:]):
        follower.sample(int(s), float(a), SPEED)
    assert follower.validity == pytest.approx(nonlinear_validity(follower.stepper.slope))
    assert 0.0 < follower.validity < VALIDITY_THRESHOLD


def test_judging_after_the_sample_gives_what_sample_gives(tables):
    # the node publishes the lever tip before the slopes are judged: the same outputs,
    # validity, largest slope and counts as judged within sample()
    stamps, angles, speeds = _signal(500)
    stamps[250:] += 2_000_000_000        # a restart: not judged (NaN)
    speeds = speeds * (1.0 + 0.2 * np.sin(np.arange(500) / 40.0))
    now, later = (NonlinearFollower(tables, reset_gap_s=0.5) for _ in range(2))
    for s, a, w in zip(stamps.tolist(), angles.tolist(), speeds.tolist()):
        output = now.sample(s, a, w)
        assert np.array_equal(later.sample(s, a, w, judge=False), output)
        validity = later.judge()
        # judged once (a start: NaN, as sample() leaves it)
        assert np.array_equal([validity, later.judge()], [now.validity] * 2, equal_nan=True)
        assert (later.slope_max, later.counts) == (now.slope_max, now.counts)
    assert now.slope_max > 0.0 and now.counts['restarts'] == 1


def test_a_sample_outputs_the_matrix_product_of_its_state(tables):
    # the output the node publishes: the operator times the state, as numpy's @, bit for bit
    stamps, angles, speeds = _signal(200)
    follower = NonlinearFollower(tables, reset_gap_s=0.5)
    for s, a, w in zip(stamps.tolist(), angles.tolist(), speeds.tolist()):
        output = follower.sample(s, a, w)
        stepper = follower.stepper
        if follower.counts['samples'] > 1:
            assert np.array_equal(output, stepper.output_operator @ stepper.q)
    assert follower.counts['refused_samples'] == 0


def test_following_blocks_of_samples_gives_what_sample_by_sample_gives(tables):
    """follow() marches runs in one compiled call: sample()'s numbers, gaps and counts."""
    stamps, angles, speeds = _signal(900)
    stamps[400:] += 2_000_000_000        # a 2 s gap: a restart
    stamps[650:] += 300_000_000          # 0.3 s: within the reset gap, stepped over
    speeds = speeds * (1.0 + 0.01 * np.sin(np.arange(900) / 50.0))
    one = NonlinearFollower(tables, reset_gap_s=0.5)
    expected = np.array([one.sample(int(s), float(a), float(w))
                         for s, a, w in zip(stamps, angles, speeds)])
    many = NonlinearFollower(tables, reset_gap_s=0.5)
    # Blocks that cut a run, start at the restart, and hold a single sample.
    bounds = [0, 1, 137, 400, 401, 402, 777, 900]
    got = np.concatenate([many.follow(stamps[a:b], angles[a:b], speeds[a:b])
                          for a, b in zip(bounds[:-1], bounds[1:])])
    span = np.ptp(expected, axis=0)
    assert np.all(np.abs(got - expected) <= 1e-12 * span), np.max(np.abs(got - expected) / span)
    assert many.counts == one.counts and one.counts['restarts'] == 1
    assert many.slope_max == pytest.approx(one.slope_max, rel=1e-12) and many.slope_max > 0
    assert many.validity == pytest.approx(one.validity, rel=1e-9)
    assert many.last[0] == one.last[0] and many.last[1:] == pytest.approx(one.last[1:],
                                                                          rel=1e-15)
