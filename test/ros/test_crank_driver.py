"""crank_driver: speed profiles against quadrature, and the real node received over rclpy."""

import math
import re
import signal
import subprocess
import sys
import time

from flexlink_ros.core.numerics import RPM, wrap_to_pi
from flexlink_ros.ros.crank_driver import build_parser, periods_skipped, SpeedProfile
import numpy as np
import pytest
from scipy.integrate import quad

REPO_CONFIG = 'config/crank_driver.yaml'


@pytest.mark.parametrize('profile', [
    SpeedProfile('constant', speed_rpm=90.0),
    SpeedProfile('ramp', ramp_from_rpm=30.0, ramp_to_rpm=150.0, ramp_duration_s=2.0),
    SpeedProfile('ramp', ramp_from_rpm=100.0, ramp_to_rpm=-20.0, ramp_duration_s=0.7),
    SpeedProfile('sweep', sweep_max_rpm=120.0, sweep_period_s=1.3),
])
def test_angle_is_the_integral_of_speed(profile):
    for t in (0.0, 0.2, 0.65, 0.7, 1.0, 1.3, 2.0, 2.9, 4.05):
        integral, _ = quad(profile.speed, 0.0, t, limit=200, points=[0.65, 0.7, 1.3, 1.95, 2.0,
                                                                     2.6, 3.25, 3.9])
        assert profile.angle(t) == pytest.approx(integral, rel=1e-10, abs=1e-10)


def test_profile_shapes():
    ramp = SpeedProfile('ramp', ramp_from_rpm=0.0, ramp_to_rpm=60.0, ramp_duration_s=4.0)
    assert ramp.speed(0.0) == 0.0 and ramp.speed(2.0) == pytest.approx(30.0 * RPM)
    assert ramp.speed(100.0) == pytest.approx(60.0 * RPM)
    sweep = SpeedProfile('sweep', sweep_max_rpm=120.0, sweep_period_s=2.0)
    assert [sweep.speed(t) / RPM for t in (0.0, 0.5, 1.0, 1.5, 2.0)] == \
        pytest.approx([0.0, 60.0, 120.0, 60.0, 0.0], abs=1e-9)
    assert sweep.angle(4.0) == pytest.approx(2 * 0.5 * 120.0 * RPM * 2.0)
    assert wrap_to_pi(math.pi) == pytest.approx(-math.pi)
    assert wrap_to_pi(-math.pi) == pytest.approx(-math.pi)
    assert wrap_to_pi(7.0) == pytest.approx(7.0 - 2 * math.pi)
    with pytest.raises(ValueError, match='profile'):
        SpeedProfile('sine')


def test_help_lists_every_parameter(capsys):
    with pytest.raises(SystemExit) as exit_info:
        build_parser().parse_args(['--help'])
    assert exit_info.value.code == 0
    text = capsys.readouterr().out
    for name in ('rate_hz', 'profile', 'ramp.to_rpm', 'sweep.period_s', 'jitter_us'):
        assert name in text


def receive_joint_states(extra_parameters, count, timeout_s=120.0):
    """
    Run crank_driver in a subprocess until ``count`` samples arrive; SIGINT it.

    Returns (receive ns, stamp ns, position, velocity, names) per sample. The driver runs
    until the listener has its samples, however late discovery is on a loaded machine.
    """
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from sensor_msgs.msg import JointState

    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        node = rclpy.create_node('crank_listener', context=context)
        received = []
        node.create_subscription(
            JointState, 'joint_states',
            lambda m: received.append((time.time_ns(), m.header.stamp.sec * 10**9
                                       + m.header.stamp.nanosec, m.position[0], m.velocity[0],
                                       list(m.name))), 2000)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        command = [sys.executable, '-m', 'flexlink_ros.ros.crank_driver', '--ros-args',
                   '--params-file', REPO_CONFIG, '-p', f'duration_s:={timeout_s}']
        for item in extra_parameters:
            command += ['-p', item]
        driver = subprocess.Popen(command)
        try:
            deadline = time.monotonic() + 60.0   # start-up and discovery on a loaded machine
            while node.count_publishers('joint_states') == 0 and time.monotonic() < deadline:
                executor.spin_once(timeout_sec=0.05)
            assert node.count_publishers('joint_states') == 1, 'crank_driver not discovered'
            deadline = time.monotonic() + timeout_s
            while (len(received) < count and driver.poll() is None
                   and time.monotonic() < deadline):
                executor.spin_once(timeout_sec=0.05)
            assert len(received) >= count, (len(received), driver.poll())
            driver.send_signal(signal.SIGINT)
            assert driver.wait(timeout=20) == 0
        finally:
            if driver.poll() is None:
                driver.kill()
                driver.wait()
        return received
    finally:
        rclpy.shutdown(context=context)


def test_driver_publishes_the_profile_at_rate(config_dir, monkeypatch):
    monkeypatch.chdir(config_dir.parent)
    # The ramp outlasts the run (2 000 samples at 1 kHz, however late the discovery is on a
    # loaded machine): the listener still sees it ramping.
    ramp_s = 300.0
    received = receive_joint_states(
        ['profile:=ramp', 'ramp.from_rpm:=30.0', 'ramp.to_rpm:=90.0',
         f'ramp.duration_s:={ramp_s}', 'joint_name:=crank_joint'], 2000)
    assert len(received) >= 2000
    stamp, position, velocity = (np.array([r[i] for r in received]) for i in (1, 2, 3))
    assert all(r[4] == ['crank_joint'] for r in received)
    assert np.all(np.diff(stamp) > 0)  # strictly monotonic stamps
    span_s = (stamp[-1] - stamp[0]) * 1e-9
    rate = (len(stamp) - 1) / span_s
    print(f'received {len(stamp)} at {rate:.0f} Hz, '
          f'dt p50 {np.median(np.diff(stamp)) / 1e6:.3f} ms')
    assert rate > 300.0  # 1 kHz nominal; loose on a loaded 2-core machine
    assert np.all(np.abs(position) <= math.pi)
    # Velocity equals the ramp evaluated at the stamp: recover the start from the ramp itself.
    omega_from, omega_to = 30.0 * RPM, 90.0 * RPM
    slope = (omega_to - omega_from) / ramp_s
    ramping = velocity < omega_to - 1e-9
    assert ramping.sum() > 100
    since_first_s = (stamp - stamp[0]) * 1e-9  # int64 difference first: float64 keeps the ns
    start_s = since_first_s[ramping] - (velocity[ramping] - omega_from) / slope
    assert np.ptp(start_s) < 1e-6  # one start time explains every ramp sample (to 1 us)
    t = since_first_s - start_s.mean()
    profile = SpeedProfile('ramp', ramp_from_rpm=30.0, ramp_to_rpm=90.0,
                           ramp_duration_s=ramp_s)
    assert velocity == pytest.approx([profile.speed(x) for x in t], abs=1e-6)
    # Position is the integral of velocity: trapezoid between samples, modulo 2 pi.
    increments = np.diff(np.unwrap(position))
    trapezoid = 0.5 * (velocity[1:] + velocity[:-1]) * np.diff(stamp) * 1e-9
    assert increments == pytest.approx(trapezoid, abs=1e-6 + slope * 1e-6)


@pytest.mark.parametrize('gap_ms, skipped', [(1.0, 0), (1.4, 0), (0.6, 0), (2.0, 1), (2.6, 2),
                                             (10.0, 9)])
def test_periods_skipped_counts_the_periods_a_late_timer_left_empty(gap_ms, skipped):
    assert periods_skipped(round(gap_ms * 1e6), 1_000_000) == skipped


def test_the_driver_says_what_it_published_as_it_exits():
    # A real driver stopped by SIGINT: its last line counts the messages and skipped periods.
    driver = subprocess.Popen([sys.executable, '-m', 'flexlink_ros.ros.crank_driver',
                               '--ros-args', '-p', 'rate_hz:=200.0'],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    time.sleep(3.0)
    driver.send_signal(signal.SIGINT)
    _, err = driver.communicate(timeout=30)
    assert driver.returncode == 0, err
    last = err.strip().splitlines()[-1]
    published, heard, skipped = (int(x) for x in re.findall(
        r'(\d+) (?:JointState messages|while|periods)', last))
    # Nobody subscribes to this driver's topic in its run-unique domain.
    assert last.startswith('crank_driver: published') and published > 100 and heard == 0, last
    assert 0 <= skipped < published, last


@pytest.mark.parametrize('parameter, reason', [
    ('profile:=zigzag', 'must be one of'),
    ('rate_hz:=0.0', 'out of range'),
    ('speed_rpm:=fast', 'expecting type'),
])
def test_bad_parameter_is_a_one_line_error(parameter, reason):
    result = subprocess.run([sys.executable, '-m', 'flexlink_ros.ros.crank_driver', '--ros-args',
                             '-p', parameter], capture_output=True, text=True, timeout=60)
    assert result.returncode == 1
    assert result.stderr.startswith('crank_driver: error:') and reason in result.stderr
    assert 'Traceback' not in result.stderr


def test_shutdown_errors_are_told_from_failures():
    """Invalid-context errors of rcl mean shutdown even while Context.ok() still says True."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor

    from flexlink_ros.ros.runtime import is_shutdown_error, spin_until_shutdown

    live = rclpy.Context()
    rclpy.init(context=live)
    closing = rclpy.Context()
    rclpy.init(context=closing)
    try:
        node = rclpy.create_node('closing', context=closing)
        executor = SingleThreadedExecutor(context=closing)
        executor.add_node(node)
        closing.try_shutdown()
        # The real error rcl gives a wait set on a context it has shut down.
        with pytest.raises(Exception) as caught:
            executor.spin_once(timeout_sec=0.01)
        error = caught.value
        assert 'context is not valid' in str(error)
        assert is_shutdown_error(error, closing)
        # The race: the same error while the context still reports ok.
        assert live.ok() and is_shutdown_error(error, live)
        assert not is_shutdown_error(ValueError('a failure'), live)
        assert is_shutdown_error(ValueError('any error'), closing)
        # spin_until_shutdown re-raises real failures of a live context.
        failing = rclpy.create_node('failing', context=live)
        failing.create_timer(0.001, lambda: 1 / 0)
        live_executor = SingleThreadedExecutor(context=live)
        live_executor.add_node(failing)
        with pytest.raises(ZeroDivisionError):
            spin_until_shutdown(live_executor)
        # ... and return quietly once the context is shut down.
        live_executor.remove_node(failing)
        live_executor.add_node(rclpy.create_node('quiet', context=live))
        live.try_shutdown()
        spin_until_shutdown(live_executor)
    finally:
        for context in (live, closing):
            context.try_shutdown()
