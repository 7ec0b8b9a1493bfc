"""
The nonlinear follower over spans, each from a warm-up (core/estimation/follow_spans.py).

At reduced size (2 elements per link) and a damping that fades a start within a fraction of
a second (the paper's takes about 8 s): the slowest decay rate is the damped lowest mode's
(checked against the frozen modes of the stiffness-proportional damping), and a span
followed from its warm-up gives the sequential follower's outputs and counts, to rounding,
with gaps inside the warm-up, inside the span and longer than the warm-up.
"""

import math

from flexlink_ros.core.estimation.follow_spans import follow_span, slowest_decay_rate, \
    warm_up_s
from flexlink_ros.core.estimation.nonlinear_follow import NonlinearFollower
from flexlink_ros.core.estimation.nonlinear_stream import linear_part
import numpy as np
import pytest
import scipy.linalg
from small_nonlinear import small_nonlinear_tables

SPEED = 391.0 * math.pi / 30.0
BETA = 5e-3


@pytest.fixture(scope='module')
def tables():
    return small_nonlinear_tables(BETA)


def test_the_slowest_decay_is_the_least_damped_frozen_mode(tables):
    theta = 2.0 * math.pi * np.arange(tables.grid_size) / tables.grid_size
    mass, _, stiffness, _ = linear_part(tables, tables.at(theta), np.zeros(theta.size), 0.0)
    decays = []
    for m, k in zip(mass, stiffness):
        omega = np.sqrt(scipy.linalg.eigh(k, m, eigvals_only=True))
        zeta = 0.5 * BETA * omega           # C = beta K at rest
        decays.append(np.min(zeta * omega - omega * np.sqrt(np.maximum(zeta ** 2 - 1.0, 0.0))))
    assert slowest_decay_rate(tables, [0.0]) == pytest.approx(min(decays), rel=1e-6)
    warm = warm_up_s(tables, SPEED, reset_gap_s=0.01)
    assert warm == pytest.approx(math.log(1e12) / slowest_decay_rate(tables, [0.0, SPEED]))
    assert warm_up_s(tables, SPEED, reset_gap_s=10.0) == 20.0


def _signal(count, rate_hz=1000.0, seed=5):
    steps = (1.0 + 0.3 * np.random.default_rng(seed).uniform(-1.0, 1.0, count - 1)) / rate_hz
    time_s = np.concatenate([[0.0], np.cumsum(steps)])
    speeds = SPEED * (1.0 + 0.05 * np.sin(2.0 * time_s))
    angles = np.mod(np.cumsum(np.concatenate([[0.0], speeds[1:] * steps])), 2.0 * math.pi)
    return np.round(time_s * 1e9).astype(np.int64), angles, speeds


@pytest.mark.parametrize('gaps', [(), (900,), (1700,), (1200, 2300)])
def test_a_span_from_its_warm_up_gives_the_sequential_follower(tables, gaps):
    """Gaps (1 s, beyond the 0.1 s reset gap) in the warm-up and in the span."""
    stamps, angles, speeds = _signal(3000)
    for row in gaps:
        stamps[row:] += 1_000_000_000
    sequential = NonlinearFollower(tables, reset_gap_s=0.1)
    expected = sequential.follow(stamps[:2000], angles[:2000], speeds[:2000])
    counts_before, first = dict(sequential.counts), 2000
    expected = np.concatenate([expected, sequential.follow(stamps[first:], angles[first:],
                                                           speeds[first:])])
    warm = warm_up_s(tables, SPEED, 0.1)
    assert warm < 0.9, warm
    keep = stamps[:first] >= stamps[first] - round(warm * 1e9)
    outputs, follower = follow_span(tables, 0.1, tuple(v[:first][keep] for v in (
        stamps, angles, speeds)), (stamps[first:], angles[first:], speeds[first:]), True)
    span = np.ptp(expected[first:], axis=0)
    error = np.max(np.abs(outputs - expected[first:]), axis=0) / span
    assert np.all(error <= 1e-11), error
    assert follower.counts == {key: sequential.counts[key] - counts_before[key]
                               for key in counts_before}
    assert follower.last[0] == sequential.last[0]
    assert follower.validity == pytest.approx(sequential.validity, rel=1e-9)
    # Without the warm-up the start is off by far more than rounding.
    alone, _ = follow_span(tables, 0.1, None, (stamps[first:], angles[first:],
                                               speeds[first:]), True)
    if 1700 not in gaps:
        assert np.max(np.abs(alone - expected[first:]) / span) > 1e-6


def test_a_span_after_a_gap_longer_than_the_warm_up_restarts_as_one_follower(tables):
    stamps, angles, speeds = _signal(1200)
    stamps[600:] += 5_000_000_000
    sequential = NonlinearFollower(tables, reset_gap_s=0.1)
    expected = np.concatenate([sequential.follow(stamps[:600], angles[:600], speeds[:600]),
                               sequential.follow(stamps[600:], angles[600:], speeds[600:])])
    warm = warm_up_s(tables, SPEED, 0.1)
    keep = stamps[:600] >= stamps[600] - round(warm * 1e9)
    assert not keep.any()
    outputs, follower = follow_span(tables, 0.1, tuple(v[:600][keep] for v in (
        stamps, angles, speeds)), (stamps[600:], angles[600:], speeds[600:]), True)
    assert np.array_equal(outputs, expected[600:])
    assert follower.counts['restarts'] == 1 == sequential.counts['restarts']
