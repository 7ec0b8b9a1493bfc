"""Crank-rate filter on exact signals with jitter, drops and wrap-around; C twin bit for bit."""

import math

from estimation_toys import run, sample_times
from flexlink_ros.core.estimation.crank_filter import CompiledCrankRateFilter, CrankRateFilter
from flexlink_ros.core.estimation.native import compiled_step_available
from flexlink_ros.core.numerics import wrap_to_2pi
import numpy as np
import pytest


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
        wrapped = wrap_to_2pi(value)
        assert 0.0 <= wrapped < 2 * np.pi
        assert abs(math.remainder(wrapped - value, 2 * np.pi)) < 1e-9


def test_rejects_bad_time_constant():
    with pytest.raises(ValueError, match='time_constant_s'):
        CrankRateFilter(0.0)


@pytest.mark.parametrize('kind', ['speed', 'angle', 'mixed', 'steps'])
def test_compiled_crank_filter_gives_the_python_filter_bit_for_bit(kind):
    """The C filter (streaming and over a signal) returns the Python filter's doubles."""
    if not compiled_step_available():
        pytest.skip('compiled step not built')
    rng = np.random.default_rng(11)
    count = 3000
    steps = 1e-3 * (1.0 + 0.5 * rng.uniform(-1, 1, count))
    if kind == 'steps':     # 10 us to 100 ms steps, a speed step, a stop and a reversal
        steps = 10.0 ** rng.uniform(-5, -1, count)
    times = np.cumsum(steps)
    speed_true = np.where(times < times[-1] / 2, 40.0 + 6.0 * times, -20.0 * np.sin(times))
    angles = np.cumsum(speed_true * steps) + 7.0 * np.pi     # unwrapped, any range
    speeds = (speed_true + 0.01 * rng.normal(size=count)).tolist()
    if kind == 'angle':
        speeds = None
    elif kind in ('mixed', 'steps'):
        speeds[100:150] = [None] * 50
        speeds[900:905] = [math.nan] * 5
    python, compiled = CrankRateFilter(0.02), CompiledCrankRateFilter(0.02)
    expected, got = [], []
    for n, (t, angle) in enumerate(zip(times.tolist(), angles.tolist())):
        speed = None if speeds is None else speeds[n]
        if n == 2000:       # a reset midway
            python.reset()
            compiled.reset()
        expected.append(python.update(t, angle, speed) + (python.advance, python.count))
        got.append(compiled.update(t, angle, speed) + (compiled.advance, compiled.count))
    assert got == expected
    for kind_of_filter in (CompiledCrankRateFilter, CrankRateFilter):   # signal(): replay's
        motion = kind_of_filter(0.02).signal(times[:2000], angles[:2000],
                                             None if speeds is None else speeds[:2000])
        assert motion.tolist() == [list(row[:4]) for row in expected[:2000]], kind_of_filter
