"""Synthetic crank signals (studies/synthetic.py): constant speed sampled with jitter."""

import math

from flexlink_ros.studies.synthetic import last_revolution, synthetic_signal
import numpy as np
import pytest


@pytest.mark.parametrize('jitter', [0.0, 0.3])
def test_angles_advance_by_speed_times_the_step(jitter):
    rpm, rate = 269.0, 500.0
    stamps, angles, speeds = synthetic_signal(rpm, 1.5, rate, jitter=jitter, seed=4,
                                              start_angle=0.25)
    speed = rpm * 2.0 * math.pi / 60.0
    assert stamps.dtype == np.int64 and stamps[0] == 0 and angles[0] == 0.25
    assert np.allclose(speeds, speed, rtol=1e-15, atol=0.0)
    dt = np.diff(stamps) * 1e-9
    assert np.allclose(np.diff(angles), speed * dt, rtol=1e-12, atol=1e-12)
    # each step is (1 + jitter U(-1, 1)) / rate, to the nanosecond
    assert np.all(dt >= (1.0 - jitter) / rate - 1e-9)
    assert np.all(dt <= (1.0 + jitter) / rate + 1e-9)
    # the samples fill the duration (the last one may be a step short: float sums of steps)
    assert 1.5e9 - 2.0 * (1.0 + jitter) / rate * 1e9 < stamps[-1] <= 1.5e9
    if jitter:
        assert np.ptp(dt) > jitter / rate        # the steps do vary
    else:
        assert np.ptp(np.diff(stamps)) <= 1      # nanosecond rounding only


def test_seed_makes_the_jitter_repeatable():
    first = synthetic_signal(391.0, 0.2, 1000.0, jitter=0.2, seed=7)[0]
    again = synthetic_signal(391.0, 0.2, 1000.0, jitter=0.2, seed=7)[0]
    other = synthetic_signal(391.0, 0.2, 1000.0, jitter=0.2, seed=8)[0]
    assert np.array_equal(first, again) and not np.array_equal(first[:50], other[:50])


def test_negative_speed_turns_the_crank_backwards():
    _, angles, speeds = synthetic_signal(-120.0, 0.5, 200.0)
    assert np.all(np.diff(angles) < 0.0) and np.allclose(speeds, -4.0 * math.pi, rtol=1e-15)


def test_last_revolution_keeps_one_period_of_samples():
    rpm = 300.0                                   # 0.2 s per revolution
    stamps, angles, _ = synthetic_signal(rpm, 1.0, 1000.0)
    mask = last_revolution(stamps, rpm)
    kept = stamps[mask]
    assert kept[-1] == stamps[-1]
    assert kept[-1] - kept[0] < 0.2e9 and stamps[~mask][-1] <= stamps[-1] - 0.2e9
    # the kept samples span one turn of the crank, not more
    assert np.ptp(angles[mask]) == pytest.approx(2.0 * math.pi, rel=1e-2)
    assert np.ptp(angles[mask]) < 2.0 * math.pi
    assert np.array_equal(mask, last_revolution(stamps, -rpm))


@pytest.mark.parametrize('kwargs', [{'jitter': 1.0}, {'jitter': -0.1}, {'seconds': 0.0},
                                    {'rate_hz': -5.0}])
def test_bad_arguments_are_refused(kwargs):
    arguments = {'rpm': 269.0, 'seconds': 1.0, 'rate_hz': 100.0, **kwargs}
    with pytest.raises(ValueError):
        synthetic_signal(**arguments)
