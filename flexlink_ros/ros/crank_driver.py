"""
crank_driver: publish the crank joint's ``sensor_msgs/JointState`` at a fixed rate (1 kHz).

A stand-in for the encoder of a motor-driven crank, to drive ``flexlink_node`` (and tests)
without hardware. Each message carries one joint (``joint_name``): ``position`` = crank angle
[rad] wrapped to [-pi, pi) like a revolute joint's encoder, ``velocity`` = crank speed [rad/s];
``effort`` is empty. The stamp is the node clock at publication, and angle and speed are the
speed profile evaluated at that same instant (the angle is the profile's closed-form integral),
so timer jitter or missed ticks change the sample times but never make angle, speed and stamp
disagree, and there is no drift.

Speed profiles (``profile``): ``constant`` (``speed_rpm``); ``ramp`` (``ramp.from_rpm`` to
``ramp.to_rpm`` linearly over ``ramp.duration_s``, then held); ``sweep`` (0 up to
``sweep.max_rpm`` and back to 0, linearly, every ``sweep.period_s``, repeated). Changing a
profile parameter at run time restarts the profile from the current angle (no jump in angle).
"""

import argparse
import math
import random
import sys
import time

from rcl_interfaces.msg import SetParametersResult
import rclpy
from rclpy.exceptions import InvalidParameterTypeException, InvalidParameterValueException
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.task import Future
from rclpy.utilities import remove_ros_args
from sensor_msgs.msg import JointState

from . import runtime
from .overrides import declare_table, NODE_OPTIONS
from .parameters import parameter_help, ParameterSpec
from ..core.numerics import RPM, wrap_to_pi

PROFILES = ('constant', 'ramp', 'sweep')

PARAMETERS = (
    ParameterSpec('joint_name', 'crank', 'Name of the crank joint in the JointState'),
    ParameterSpec('topic', 'joint_states', 'Topic the JointState is published on',
                  read_only=True),
    ParameterSpec('rate_hz', 1000.0, 'Publication rate [Hz]', low=1.0, high=20000.0,
                  read_only=True),
    ParameterSpec('profile', 'constant', 'Speed profile', choices=PROFILES),
    ParameterSpec('speed_rpm', 60.0, 'Crank speed of the constant profile [rpm]',
                  low=-6000.0, high=6000.0),
    ParameterSpec('ramp.from_rpm', 0.0, 'Ramp start speed [rpm]', low=-6000.0, high=6000.0),
    ParameterSpec('ramp.to_rpm', 120.0, 'Ramp end speed, held afterwards [rpm]',
                  low=-6000.0, high=6000.0),
    ParameterSpec('ramp.duration_s', 10.0, 'Ramp duration [s]', low=1e-3, high=1e6),
    ParameterSpec('sweep.max_rpm', 120.0, 'Peak speed of the sweep [rpm]',
                  low=-6000.0, high=6000.0),
    ParameterSpec('sweep.period_s', 20.0, 'Duration of one 0 -> max -> 0 sweep [s]',
                  low=1e-3, high=1e6),
    ParameterSpec('initial_angle_deg', 0.0, 'Crank angle at start [deg]',
                  low=-360.0, high=360.0),
    ParameterSpec('jitter_us', 0.0, 'Random extra delay before each publication, uniform in '
                  '[0, jitter_us] [us] (tests sample-time irregularity)', low=0.0, high=1e5),
    ParameterSpec('duration_s', 0.0, 'Exit after this long [s]; 0 = run until stopped',
                  low=0.0, high=1e7, read_only=True),
    ParameterSpec('seed', 0, 'Seed of the jitter random generator', low=0, high=2**31 - 1,
                  read_only=True),
)


class SpeedProfile:
    """
    Crank speed as a function of time and its exact integral.

    Parameters
    ----------
    kind : {'constant', 'ramp', 'sweep'}
    speed_rpm : float
        Constant speed.
    ramp_from_rpm, ramp_to_rpm, ramp_duration_s : float
        Linear ramp, then held at ``ramp_to_rpm``.
    sweep_max_rpm, sweep_period_s : float
        Triangular sweep 0 -> max -> 0 over one period, repeated.

    """

    def __init__(self, kind, speed_rpm=60.0, ramp_from_rpm=0.0, ramp_to_rpm=120.0,
                 ramp_duration_s=10.0, sweep_max_rpm=120.0, sweep_period_s=20.0):
        if kind not in PROFILES:
            raise ValueError(f'`profile` must be one of {", ".join(PROFILES)}, got {kind!r}')
        if not ramp_duration_s > 0 or not sweep_period_s > 0:
            raise ValueError('`ramp.duration_s` and `sweep.period_s` must be > 0')
        self.kind = kind
        self.omega = speed_rpm * RPM
        self.omega_from = ramp_from_rpm * RPM
        self.omega_to = ramp_to_rpm * RPM
        self.ramp_duration = ramp_duration_s
        self.omega_max = sweep_max_rpm * RPM
        self.period = sweep_period_s

    @classmethod
    def from_parameters(cls, values):
        """Build from a mapping of parameter names (``PARAMETERS``) to values."""
        return cls(values['profile'], values['speed_rpm'], values['ramp.from_rpm'],
                   values['ramp.to_rpm'], values['ramp.duration_s'], values['sweep.max_rpm'],
                   values['sweep.period_s'])

    def speed(self, t):
        """Crank speed [rad/s] at time ``t`` [s] after the profile's start (t >= 0)."""
        if self.kind == 'constant':
            return self.omega
        if self.kind == 'ramp':
            if t >= self.ramp_duration:
                return self.omega_to
            return self.omega_from + (self.omega_to - self.omega_from) * t / self.ramp_duration
        phase = (t % self.period) / self.period
        return self.omega_max * (1.0 - abs(2.0 * phase - 1.0))

    def angle(self, t):
        """Angle turned [rad] from the start to time ``t`` [s]: the integral of :meth:`speed`."""
        if self.kind == 'constant':
            return self.omega * t
        if self.kind == 'ramp':
            T = self.ramp_duration
            if t <= T:
                return self.omega_from * t + 0.5 * (self.omega_to - self.omega_from) * t * t / T
            return 0.5 * (self.omega_from + self.omega_to) * T + self.omega_to * (t - T)
        P = self.period
        cycles, s = divmod(t, P)
        half = 0.5 * P
        if s <= half:
            partial = self.omega_max * s * s / P
        else:
            u = s - half
            partial = self.omega_max * (0.25 * P + u - u * u / P)
        return cycles * 0.5 * self.omega_max * P + partial


def build_parser():
    """Command-line parser for the non-ROS arguments (only --help)."""
    return argparse.ArgumentParser(
        prog='crank_driver', formatter_class=argparse.RawDescriptionHelpFormatter,
        description='Publish the crank JointState (angle wrapped to [-pi, pi), speed) at a '
                    'fixed rate with a constant, ramp or sweep speed profile.',
        epilog=parameter_help(PARAMETERS))


def periods_skipped(gap_ns, period_ns):
    """
    Return how many timer periods passed without a message between two sent ``gap_ns`` apart.

    rclpy's timer does not run a late callback once per missed period: it runs it once and
    waits for the next period, so a callback later than a period leaves a gap in the stamps.
    """
    return max(0, round(gap_ns / period_ns) - 1)


class CrankDriver(Node):
    """Publishes the crank JointState on a timer; see the module docstring."""

    def __init__(self):
        super().__init__('crank_driver', **NODE_OPTIONS)
        declare_table(self, PARAMETERS)
        self.add_on_set_parameters_callback(self._validate)
        self.add_post_set_parameters_callback(self._restart_profile)
        values = self._values()
        self.finished = Future()
        self._rng = random.Random(values['seed'])
        self._profile = SpeedProfile.from_parameters(values)
        self._origin_ns = self.get_clock().now().nanoseconds
        self._origin_angle = math.radians(values['initial_angle_deg'])
        self._start_ns = self._origin_ns
        self._message = JointState(name=[values['joint_name']])
        self._publisher = self.create_publisher(JointState, values['topic'], 10)
        timer_period = 1.0 / values['rate_hz']  # seconds
        self.create_timer(timer_period, self._publish)
        self.published = 0
        self.published_while_heard = 0
        self.periods_skipped = 0
        self._period_ns = round(timer_period * 1e9)
        self._last_ns = None

    def _values(self):
        return {spec.name: self.get_parameter(spec.name).value for spec in PARAMETERS}

    def _validate(self, parameters):
        for parameter in parameters:
            spec = next((s for s in PARAMETERS if s.name == parameter.name), None)
            if spec is not None and spec.choices and parameter.value not in spec.choices:
                return SetParametersResult(
                    successful=False,
                    reason=f'{spec.name} must be one of {", ".join(spec.choices)}')
        return SetParametersResult(successful=True)

    def summary(self):
        """Return the exit line: messages published (heard), periods that passed without one."""
        return (f'crank_driver: published {self.published} JointState messages '
                f'({self.published_while_heard} while a subscriber was matched); the timer '
                f'skipped {self.periods_skipped} periods (its callback ran late)')

    def _restart_profile(self, parameters):
        now_ns = self.get_clock().now().nanoseconds
        self._origin_angle = self._angle_at(now_ns)
        self._origin_ns = now_ns
        values = self._values()
        self._profile = SpeedProfile.from_parameters(values)
        self._message.name = [values['joint_name']]

    def _angle_at(self, now_ns):
        return self._origin_angle + self._profile.angle((now_ns - self._origin_ns) * 1e-9)

    def _publish(self):
        jitter_us = self.get_parameter('jitter_us').value
        if jitter_us > 0:
            time.sleep(self._rng.uniform(0.0, jitter_us) * 1e-6)
        now = self.get_clock().now()
        elapsed_s = (now.nanoseconds - self._origin_ns) * 1e-9
        message = self._message
        message.header.stamp = now.to_msg()
        message.position = [wrap_to_pi(self._angle_at(now.nanoseconds))]
        message.velocity = [self._profile.speed(elapsed_s)]
        heard = self._publisher.get_subscription_count() > 0
        self._publisher.publish(message)
        self.published += 1
        self.published_while_heard += heard
        if self._last_ns is not None:
            self.periods_skipped += periods_skipped(now.nanoseconds - self._last_ns,
                                                    self._period_ns)
        self._last_ns = now.nanoseconds
        duration_s = self.get_parameter('duration_s').value
        if duration_s > 0 and (now.nanoseconds - self._start_ns) * 1e-9 >= duration_s:
            if not self.finished.done():
                self.finished.set_result(self.published)


def main(args=None):
    """
    Run the ``crank_driver`` executable.

    Parameters
    ----------
    args : list of str or None
        Command-line arguments (None: ``sys.argv``).

    """
    argv = sys.argv if args is None else ['crank_driver', *args]
    build_parser().parse_args(remove_ros_args(argv)[1:])
    node = None
    try:
        with rclpy.init(args=argv):
            try:
                node = CrankDriver()
            except (ValueError, InvalidParameterValueException,
                    InvalidParameterTypeException) as exc:
                print(f'crank_driver: error: {exc}', file=sys.stderr)
                return 1
            executor = runtime.make_executor()
            executor.add_node(node)
            runtime.spin_until_shutdown(executor, node.finished.done)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    if node is not None:
        print(node.summary(), file=sys.stderr, flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
