"""
flexlink_node: live elastic deflections and joint criteria of the flexible four-bar.

Subscribes ``sensor_msgs/JointState`` (``input_topic``), picks the crank joint by name, runs
:class:`core.estimation.streaming.StreamingEstimator` on every message and publishes, stamped
with the input's stamp, in frame ``frame_id`` (SI units, see ros/messages.py):

- ``~/lever_tip/deflection``, ``~/coupler_mid/deflection``: ``geometry_msgs/Vector3Stamped``;
- ``~/joint_criteria``: ``sensor_msgs/JointState`` (O2, A, B, O4; position = |dgamma/dt|/R);
- ``~/quality``: ``sensor_msgs/JointState`` (error_indicator, nonlinearity; dimensionless);
- ``~/markers``: ``visualization_msgs/MarkerArray``, every ``markers.every_n``-th sample;
- ``/diagnostics``: ``diagnostic_msgs/DiagnosticArray`` every ``diagnostics.period_s`` (steady
  time: also on ``use_sim_time`` without ``/clock``, which is warned about, ros/sim_time.py).

Inputs and outputs are optionally recorded to MCAP (``record.*``). A message that cannot be
used (malformed or oversized CDR, NaN, missing joint, empty arrays, an outlier) is counted by
kind, warned about at most once a second and skipped; no single message can stop the node.
Exact repeats are counted and not published again; an estimate beyond the model's bound (or
non-finite) is counted and not published. SIGINT/SIGTERM during start-up exit with one line
and code 0 (ros/startup.py).

The work is :class:`estimator_node.EstimatorNode`; this module holds the two node classes that
run it (plain and managed), the start-up and ``main``.
"""

import argparse
import gc
import sys
import warnings

# Absolute, so that they sort before the third-party imports that must follow the handlers.
from flexlink_ros.names import NODE_NAME
from flexlink_ros.ros.startup import install_startup_signal_handlers

if __name__ == '__main__':  # before the second or so of imports below
    install_startup_signal_handlers()

import rclpy  # noqa: E402  (after the start-up signal handlers, see above)
from rclpy.exceptions import (InvalidParameterTypeException,  # noqa: E402
                              InvalidParameterValueException, NameValidationException)
from rclpy.executors import ExternalShutdownException  # noqa: E402
from rclpy.lifecycle import LifecycleNode, TransitionCallbackReturn  # noqa: E402
from rclpy.node import Node  # noqa: E402
from rclpy.utilities import remove_ros_args  # noqa: E402

from . import parameters, runtime, startup  # noqa: E402
from .estimator_node import EstimatorNode  # noqa: E402
from .overrides import NODE_OPTIONS  # noqa: E402
from .parameters import parameter_help  # noqa: E402
from ..errors import FlexlinkError  # noqa: E402

# GIL switch interval of the node process [s] (see main).
SWITCH_INTERVAL_S = 0.0005


class FlexlinkNode(EstimatorNode, Node):
    """flexlink_node: configured and streaming from construction."""

    finalized = False   # runs until SIGINT/SIGTERM

    def __init__(self, **kwargs):
        super().__init__(NODE_NAME, **NODE_OPTIONS, **kwargs)
        self._declare()
        self._configure(self.create_publisher)
        self._activate()


class FlexlinkManagedNode(EstimatorNode, LifecycleNode):
    """
    flexlink_node as a managed (lifecycle) node.

    configure loads or builds the model, creates the publishers and opens the recording;
    activate subscribes and starts publishing; deactivate stops receiving; cleanup closes
    the recording; shutdown (from any state) closes it and the process exits.
    """

    def __init__(self, **kwargs):
        super().__init__(NODE_NAME, **NODE_OPTIONS, **kwargs)
        self.finalized = False
        self._declare()

    def on_configure(self, state):
        try:
            self._configure(self.create_lifecycle_publisher)
        except (FlexlinkError, ValueError) as exc:
            self.get_logger().error(f'configure failed: {exc}')
            return TransitionCallbackReturn.FAILURE
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state):
        self._activate()
        return super().on_activate(state)

    def on_deactivate(self, state):
        self._deactivate()
        return super().on_deactivate(state)

    def on_cleanup(self, state):
        self._cleanup()
        return TransitionCallbackReturn.SUCCESS

    def on_shutdown(self, state):
        self._cleanup()
        self.finalized = True   # the spin ends once the transition has been answered
        return TransitionCallbackReturn.SUCCESS


def make_node(managed=False, **kwargs):
    """
    Create a FlexlinkNode, or its managed (lifecycle) variant (rclpy must be initialised).

    Parameters
    ----------
    managed : bool
        Build the lifecycle node (unconfigured until a configure transition).
    **kwargs
        Passed to rclpy's Node.

    """
    return (FlexlinkManagedNode if managed else FlexlinkNode)(**kwargs)


def build_parser():
    """Build the command-line parser for the non-ROS arguments."""
    parser = argparse.ArgumentParser(
        prog=NODE_NAME, formatter_class=argparse.RawDescriptionHelpFormatter,
        description='Elastic deflections and joint criteria of the flexible four-bar from a '
        'crank JointState (parameters: --ros-args --params-file FILE).',
        epilog=parameter_help(parameters.PARAMETERS))
    parser.add_argument('--managed', action='store_true',
                        help='start as a lifecycle node (configure/activate via '
                        'lifecycle services)')
    return parser


def main(args=None):
    """
    Run the ``flexlink_node`` executable.

    SIGINT or SIGTERM before the node spins (rclpy init, model build) end it with one line
    on stderr and exit code 0, as the same signals do while it spins.

    Parameters
    ----------
    args : list of str or None
        Command-line arguments (None: ``sys.argv``).

    """
    if not startup.starting_up():      # not started as `python -m flexlink_ros.ros.node`
        install_startup_signal_handlers()
    try:
        return _run(args)
    finally:
        startup.end_startup()


def _make_node_at_start_up(managed):
    """Call make_node, or raise StartupInterrupted if a signal came first (or caused an error)."""
    startup.check_startup_signal()
    # rclpy warns when a signal shuts the context down under a node being created; those
    # warnings are held back, and shown only if no signal explains them.
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter('always')
            node = make_node(managed=managed)
    except Exception:
        startup.check_startup_signal()      # a signal inside rclpy shut the context down
        raise
    finally:
        if startup.startup_signal() is None:
            for warning in caught:
                warnings.warn_explicit(warning.message, warning.category,
                                       warning.filename, warning.lineno)
    startup.check_startup_signal()
    return node


def _run(args):
    argv = sys.argv if args is None else [NODE_NAME, *args]
    options = build_parser().parse_args(remove_ros_args(argv)[1:])
    node = None
    try:
        with rclpy.init(args=argv):
            try:
                node = _make_node_at_start_up(options.managed)
            except (FlexlinkError, ValueError, InvalidParameterValueException,
                    InvalidParameterTypeException, NameValidationException) as exc:
                print(f'{NODE_NAME}: error: {exc}', file=sys.stderr)
                return 1
            _settle_for_streaming()
            startup.check_startup_signal()
            startup.end_startup()      # from here on rclpy's shutdown ends the spin
            executor = runtime.make_executor()
            executor.add_node(node)
            runtime.spin_until_shutdown(executor, lambda: node.finalized)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            node.close()
    return 0


def _settle_for_streaming():
    """Prepare the process for 1 kHz samples once the model is built."""
    # The model, rclpy and numpy are loaded: move them out of the collector's reach,
    # so a full collection never scans them between two samples (p99 latency).
    gc.collect()
    gc.freeze()
    runtime.release_free_heap()
    # A background Python thread (the recorder's flusher) holds the GIL for up to
    # the switch interval when a message arrives: 5 ms by default, 0.5 ms here.
    sys.setswitchinterval(SWITCH_INTERVAL_S)


if __name__ == '__main__':
    sys.exit(main())
