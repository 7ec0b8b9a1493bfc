"""Streaming estimator: crank-rate filter on exact signals with jitter, drops and wrap-around."""

import math

import numpy as np
import pytest

from flexlink_ros.core.estimator import CrankRateFilter, wrap_angle


def sample_times(rate_hz, seconds, jitter, drop, seed):
    """Jittered sample times with a fraction of samples dropped."""
    rng = np.random.default_rng(seed)
    steps = (1.0 + jitter * rng.uniform(-1.0, 1.0, int(seconds * rate_hz * 1.6))) / rate_hz
    times = np.cumsum(steps)
    times = times[times <= seconds]
    return times[rng.random(times.size) >= drop]


def run(filter_, times, angle, speed, with_speed, wrap_seed=None):
    rng = np.random.default_rng(wrap_seed)
    out = []
    for t in times:
        measured = angle(t)
        if wrap_seed is not None:  # arbitrary multiples of 2 pi, as drivers may send
            measured += 2 * np.pi * rng.integers(-3, 4)
        out.append(filter_.update(t, measured, speed(t) if with_speed else None))
    return np.array(out)


@pytest.mark.parametrize('with_speed', [True, False])
def test_exact_for_constant_acceleration_with_jitter_and_drops(with_speed):
    accel, speed0, angle0 = -30.0, 41.0, 2.0
    times = 0.5 + sample_times(1000.0, 1.0, 0.5, 0.1, seed=1)
    angle = lambda t: angle0 + speed0 * t + 0.5 * accel * t * t  # noqa: E731
    speed = lambda t: speed0 + accel * t  # noqa: E731
    out = run(CrankRateFilter(), times, angle, speed, with_speed, wrap_seed=2)
    settled = slice(3, None)
    wrapped_error = np.abs(np.remainder(out[:, 0] - angle(times) + np.pi, 2 * np.pi) - np.pi)
    assert np.all((out[:, 0] >= 0) & (out[:, 0] < 2 * np.pi))
    assert np.max(wrapped_error) < 1e-9
    np.testing.assert_allclose(out[settled, 1], speed(times[settled]), atol=1e-8)
    np.testing.assert_allclose(out[settled, 2], accel, atol=1e-6)


@pytest.mark.parametrize('rate_hz', [100_000.0, 1000.0, 10.0])
def test_constant_speed_at_any_rate(rate_hz):
    speed0 = 391 * 2 * np.pi / 60
    times = sample_times(rate_hz, 0.3 if rate_hz > 1e4 else 3.0, 0.5, 0.0, seed=3)
    out = run(CrankRateFilter(), times, lambda t: speed0 * t, lambda t: speed0, False)
    np.testing.assert_allclose(out[3:, 1], speed0, rtol=1e-9)
    np.testing.assert_allclose(out[3:, 2], 0.0, atol=1e-5 * speed0 ** 2)


def test_reversal_is_tracked_with_bounded_lag():
    # Oscillating crank: speed 20 cos(2 pi t) rad/s passes through zero and reverses.
    times = sample_times(1000.0, 3.0, 0.3, 0.05, seed=4)
    omega = 2 * np.pi
    angle = lambda t: 20.0 / omega * np.sin(omega * t)  # noqa: E731
    speed = lambda t: 20.0 * np.cos(omega * t)  # noqa: E731
    accel = -20.0 * omega * np.sin(omega * times)
    # With a measured speed the parabola's slope is exact for constant jerk: the error is of
    # order (omega tau)^2; from angles alone the acceleration lags by about tau (omega tau).
    for with_speed, speed_tol, accel_tol in ((True, 1e-12, 0.06), (False, 0.06, 0.45)):
        out = run(CrankRateFilter(0.02), times, angle, speed, with_speed)
        late = times > 0.2
        np.testing.assert_allclose(out[late, 1], speed(times[late]), atol=speed_tol * 20.0)
        assert np.max(np.abs(out[late, 2] - accel[late])) < accel_tol * 20.0 * omega
        assert np.any(out[late, 1] < -19.0) and np.any(out[late, 1] > 19.0)


def test_speed_step_settles_within_a_few_time_constants():
    tau = 0.02
    times = sample_times(1000.0, 1.0, 0.3, 0.0, seed=5)
    speed = lambda t: np.where(t < 0.5, 30.0, 40.0)  # noqa: E731
    angle = lambda t: np.where(t < 0.5, 30.0 * t, 15.0 + 40.0 * (t - 0.5))  # noqa: E731
    for with_speed in (True, False):
        out = run(CrankRateFilter(tau), times, angle, speed, with_speed)
        later = times > 0.5 + 15 * tau
        np.testing.assert_allclose(out[later, 1], 40.0, rtol=1e-3)
        assert np.max(np.abs(out[later, 2])) < 0.01 * 10.0 / tau
        assert np.all(np.isfinite(out))


def test_stop_gives_zero_speed():
    times = sample_times(500.0, 1.0, 0.5, 0.0, seed=6)
    out = run(CrankRateFilter(), times, lambda t: 1.234 + 0 * t, lambda t: 0.0 * t, False)
    np.testing.assert_allclose(out[:, 1:], 0.0, atol=1e-12)
    np.testing.assert_allclose(out[:, 0], 1.234)


def test_reset_forgets_history():
    f = CrankRateFilter()
    for k in range(10):
        f.update(k * 1e-3, 40.0 * k * 1e-3, 40.0)
    f.reset()
    angle, speed, accel = f.update(5.0, 7.0, None)
    assert (speed, accel) == (0.0, 0.0) and angle == pytest.approx(7.0 - 2 * np.pi)


def test_wrap_angle_range():
    for value in (-1e-18, -2 * np.pi, 2 * np.pi, 4 * np.pi - 1e-15, 1e6, -1e6, 0.0):
        wrapped = wrap_angle(value)
        assert 0.0 <= wrapped < 2 * np.pi
        assert abs(math.remainder(wrapped - value, 2 * np.pi)) < 1e-9


def test_rejects_bad_time_constant():
    with pytest.raises(ValueError, match='time_constant_s'):
        CrankRateFilter(0.0)
