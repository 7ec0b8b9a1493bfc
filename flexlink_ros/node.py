"""
flexlink_node: live elastic deflections and joint criteria of the flexible four-bar.

Subscribes ``sensor_msgs/JointState`` (``input_topic``), picks the crank joint by name, runs
:class:`core.estimator.StreamingEstimator` on every message and publishes, stamped with the
input's stamp, in frame ``frame_id`` (SI units, see ros_messages.py):

- ``~/lever_tip/deflection``, ``~/coupler_mid/deflection``: ``geometry_msgs/Vector3Stamped``;
- ``~/joint_criteria``: ``sensor_msgs/JointState`` (O2, A, B, O4; position = |dgamma/dt|/R);
- ``~/markers``: ``visualization_msgs/MarkerArray``, every ``markers.every_n``-th sample;
- ``/diagnostics``: ``diagnostic_msgs/DiagnosticArray`` every ``diagnostics.period_s``.

Inputs and outputs are optionally recorded to MCAP (``record.*``). A message that cannot be
used (NaN, missing joint, empty arrays) is counted, warned about at most once a second and
skipped; core errors are logged and estimation goes on.
"""

import ctypes
import dataclasses
import gc
import math
import struct
import sys
import time

import numpy as np

from . import cdr, node_params
from .core import reduced
from .core.errors import FlexlinkError, RecorderError
from .core.estimator import SampleFlag, StreamingEstimator
from .core.mechanism import load_mechanism

NODE_NAME = 'flexlink_node'
# Topics relative to the node's namespace (~ = the node's private namespace).
TOPICS = {'lever_tip': '~/lever_tip/deflection', 'coupler_mid': '~/coupler_mid/deflection',
          'criteria': '~/joint_criteria', 'markers': '~/markers', 'diagnostics': '/diagnostics'}
WARN_THROTTLE_S = 1.0  # at most one warning per second per kind of bad input
# The default model (node parameters, core.reduced.DEFAULT_SIZES) meets this relative RMS
# error on Cho 1992 against flexlink plan's scene reference (1.3 % coupler, 0.9 % lever).
DEFAULT_MODEL_TOLERANCE = 0.02
READY_MESSAGE = 'ready: listening on'  # logged once the node is subscribed (cli_demo waits)
FIRST_INPUT_MESSAGE = 'first crank sample'
# GIL switch interval of the node process [s] (see main).
SWITCH_INTERVAL_S = 0.0005


def load_node_model(values, warn):
    """
    Load the mechanism and its reduced model (cached), falling back where a module is missing.

    With geometric stiffness requested and the model failing to build (core/dynamics.py not
    in this checkout), the model is built without it and ``warn`` says so.

    Parameters
    ----------
    values : dict
        Parameter name -> value.
    warn : callable
        Called with a warning sentence.

    Returns
    -------
    model : core.reduced.ReducedModel
    options : core.reduced.ModelOptions
        The options actually used.
    notes : list of str
        Fallbacks taken (empty if none).

    """
    mechanism = load_mechanism(values['mechanism'])
    if values['damping_ratio'] != mechanism.damping_ratio:
        mechanism = dataclasses.replace(mechanism, damping_ratio=values['damping_ratio'])
    options = node_params.model_options(values)
    notes = []
    if values['model.modes'] == 0 and values['model.tolerance'] < DEFAULT_MODEL_TOLERANCE:
        notes.append(f'the default model was planned for {DEFAULT_MODEL_TOLERANCE:g} relative '
                     f'error; for {values["model.tolerance"]:g} run `flexlink plan --tolerance '
                     f'{values["model.tolerance"]:g}` and set model.modes')
        warn(notes[-1])
    cache_dir = values['model.cache_dir'] or None
    model, options = build_with_fallback(
        lambda o: reduced.model_for_mechanism(mechanism, o, cache_dir=cache_dir), options,
        lambda note: (notes.append(note), warn(note)))
    return model, options, notes


def build_with_fallback(build, options, warn):
    """
    ``build(options)``, or without geometric stiffness if that part cannot be built.

    The geometric stiffness needs the rigid-body axial forces (core/dynamics.py); where they
    are unavailable the model is built without it and ``warn`` is told why.

    Returns
    -------
    model : core.reduced.ReducedModel
    options : core.reduced.ModelOptions
        The options actually used.

    """
    try:
        return build(options), options
    except FlexlinkError as exc:
        if not options.geometric_stiffness:
            raise
        warn(f'geometric stiffness left out (model built without it): {exc}')
        options = dataclasses.replace(options, geometric_stiffness=False)
        return build(options), options


@dataclasses.dataclass
class PeriodStats:
    """What happened since the last /diagnostics message."""

    valid: int = 0
    rejected: int = 0
    update_ns: list = dataclasses.field(default_factory=list)
    max_error_indicator: float = 0.0
    max_criterion: list = dataclasses.field(default_factory=lambda: [0.0] * 4)
    near_zero: list = dataclasses.field(default_factory=lambda: [False] * 4)
    flags: int = 0


def parameter_descriptor(spec):
    """rcl_interfaces ParameterDescriptor of a node_params.ParameterSpec."""
    from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
    descriptor = ParameterDescriptor(description=spec.description, read_only=spec.read_only)
    if spec.choices:
        descriptor.additional_constraints = 'one of: ' + ', '.join(spec.choices)
    if spec.low is not None and isinstance(spec.default, float):
        descriptor.floating_point_range = [FloatingPointRange(from_value=float(spec.low),
                                                              to_value=float(spec.high))]
    elif spec.low is not None and not isinstance(spec.default, bool):
        descriptor.integer_range = [IntegerRange(from_value=int(spec.low),
                                                 to_value=int(spec.high), step=1)]
    return descriptor


def _make_node_class():
    """The rclpy node classes, plain and managed (built lazily: the helpers need no rclpy)."""
    from diagnostic_msgs.msg import DiagnosticArray
    from geometry_msgs.msg import Vector3Stamped
    from rcl_interfaces.msg import SetParametersResult
    from rclpy import logging as rclpy_logging
    from rclpy.lifecycle import LifecycleNode, TransitionCallbackReturn
    from rclpy.node import Node
    from rclpy._rclpy_pybind11 import RCLError
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from rclpy.serialization import deserialize_message, serialize_message
    from sensor_msgs.msg import JointState
    from visualization_msgs.msg import MarkerArray

    from . import ros_messages as rm
    from .recorder import McapRecorder

    class Pipeline:
        """The node's work, shared by the plain and the managed (lifecycle) node."""

        def _declare(self):
            for spec in node_params.PARAMETERS:
                self.declare_parameter(spec.name, spec.default, parameter_descriptor(spec))
            self.values = node_params.validate_all(
                {spec.name: self.get_parameter(spec.name).value
                 for spec in node_params.PARAMETERS})
            self.add_on_set_parameters_callback(self._validate)
            self.add_post_set_parameters_callback(self._apply)
            self.estimator = self.recorder = self.subscription = self._timer = None
            self.publishers_ = {}
            self._clock = self.get_clock()
            self._deserialize = lambda data: deserialize_message(data, JointState)
            self._serialize = serialize_message
            self._frame = self.values['frame_id'].encode()
            self._marker_encoder = None

        def _configure(self, make_publisher):
            """Load or build the model, create the publishers, open the recording."""
            values = self.values
            log = self.get_logger()
            start = time.perf_counter()
            self.model, self.options, self.notes = load_node_model(values, log.warning)
            self.criteria_source = self.model.info.get('criteria', 'unknown')
            log.info(f'model: {self.model.size} coordinates, {self.model.grid_size} grid cells, '
                     f'{self.options} ({time.perf_counter() - start:.2f} s); '
                     f'criteria: {self.criteria_source}')
            self.estimator = StreamingEstimator(self.model,
                                                warm_start=values['model.warm_start'])
            # The node only streams: the step tables serve it, the full table can go.
            self.model = self.estimator.release_model_table()
            reliability = (ReliabilityPolicy.RELIABLE if values['qos.reliability'] == 'reliable'
                           else ReliabilityPolicy.BEST_EFFORT)
            self.qos = QoSProfile(depth=values['qos.depth'], reliability=reliability)
            types = {'lever_tip': Vector3Stamped, 'coupler_mid': Vector3Stamped,
                     'criteria': JointState, 'markers': MarkerArray,
                     'diagnostics': DiagnosticArray}
            self.publishers_ = {
                key: make_publisher(types[key], TOPICS[key],
                                    self.qos if key in ('lever_tip', 'coupler_mid', 'criteria')
                                    else 10)
                for key in types}
            self.input_topic = self.resolve_topic_name(values['input_topic'])
            self.output_topics = {key: publisher.topic_name
                                  for key, publisher in self.publishers_.items()}
            self.recorder = self._open_recorder(self.qos) if values['record.enabled'] else None
            self.received = self.rejected = self.published = 0
            self.last_valid_wall = None
            self.last_rejection = ''

        def _activate(self):
            """Subscribe and start the diagnostics timer: estimates flow from now on."""
            values = self.values
            self.estimator.reset()
            self.period = PeriodStats()
            self._period_start = time.monotonic()
            self.subscription = self.create_subscription(
                JointState, values['input_topic'], self._on_joint_state, self.qos, raw=True)
            self._timer = self.create_timer(values['diagnostics.period_s'],
                                            self._publish_diagnostics)
            self.get_logger().info(
                f'{READY_MESSAGE} {self.subscription.topic_name} (joint '
                f'{values["crank_joint"]!r}), publishing under {self.get_name()}/'
                + ('' if self.recorder is None else f'; recording to {self.recorder.path}'))
            if not self.estimator.compiled:
                self.get_logger().warning(
                    'the compiled estimator step (flexlink_ros.core._radau_step) is not built: '
                    'the numpy step runs, about twice as slow (build the package with '
                    'colcon build or pip install .)')

        def _deactivate(self):
            """Stop receiving (the model, publishers and recording stay)."""
            if self.subscription is not None:
                self.destroy_subscription(self.subscription)
                self.subscription = None
            if self._timer is not None:
                self.destroy_timer(self._timer)
                self._timer = None

        def _cleanup(self):
            """Close the recording and drop publishers and model."""
            self._deactivate()
            self.close()
            for publisher in self.publishers_.values():
                self.destroy_publisher(publisher)
            self.publishers_ = {}
            self.estimator = self.recorder = None

        # -- parameters ---------------------------------------------------------------

        def _validate(self, parameters):
            current = dict(self.values)
            current.update({p.name: p.value for p in parameters})
            for parameter in parameters:
                reason = node_params.validate_parameter(parameter.name, parameter.value,
                                                        current)
                if reason is not None:
                    return SetParametersResult(successful=False, reason=reason)
            return SetParametersResult(successful=True)

        def _apply(self, parameters):
            for parameter in parameters:
                self.values[parameter.name] = parameter.value
            if self.estimator is not None:
                self.estimator.warm_start = self.values['model.warm_start']
            self._frame = self.values['frame_id'].encode()

        # -- recording ----------------------------------------------------------------

        def _open_recorder(self, qos):
            values = self.values
            path = values['record.path'] or time.strftime('flexlink_%Y%m%d_%H%M%S')
            recorder = McapRecorder(path, split_size_bytes=values['record.max_bytes'],
                                    split_duration_s=values['record.max_duration_s'])
            # Topics first: if opening fails, writes to them are then dropped as failed,
            # not refused as undeclared.
            recorder.add_topic(self.resolve_topic_name(values['input_topic']), JointState, [qos])
            for key, publisher in self.publishers_.items():
                recorder.add_topic(publisher.topic_name, publisher.msg_type,
                                   [publisher.qos_profile])
            try:
                recorder.open()
            except RecorderError as exc:
                self.get_logger().error(f'recording disabled: {exc}')
            return recorder

        def _record(self, topic, message, log_time_ns):
            if self.recorder is None:
                return
            try:
                # rclpy's bytes are exact here: none of the types has a float64[] (which can
                # be empty); only the input and the per-sample outputs are exact CDR anyway.
                self.recorder.enqueue(topic, message if isinstance(message, bytes)
                                      else self._serialize(message), log_time_ns)
            except RecorderError as exc:
                self.get_logger().error(f'recording stopped, estimation goes on: {exc}')

        # -- the per-message path -----------------------------------------------------

        def _on_joint_state(self, data):
            receive_ns = self._clock.now().nanoseconds
            self.received += 1
            if self.recorder is not None:
                self._record(self.input_topic, data, receive_ns)
            try:
                stamp_ns, angle, speed = self._crank(data)
                start = time.perf_counter_ns()
                sample = self.estimator.update(stamp_ns, angle, speed)
                self.period.update_ns.append(time.perf_counter_ns() - start)
            except (rm.InputRejected, FlexlinkError, ValueError) as exc:
                self.rejected += 1
                self.period.rejected += 1
                self.last_rejection = str(exc)
                self.get_logger().warning(f'input skipped: {exc}',
                                          throttle_duration_sec=WARN_THROTTLE_S)
                return
            if self.last_valid_wall is None:
                self.get_logger().info(f'{FIRST_INPUT_MESSAGE}: angle {angle:.4f} rad, '
                                       f'speed {speed} rad/s')
            self.last_valid_wall = time.monotonic()
            self._publish_sample(stamp_ns, sample)

        def _crank(self, data):
            """Stamp, angle and speed of the crank joint; InputRejected says why not."""
            joint = self.values['crank_joint']
            try:
                stamp_ns, angle, speed = cdr.parse_joint_state(data, joint.encode())
            except (struct.error, IndexError, ValueError):
                raise rm.InputRejected('malformed JointState CDR') from None
            if angle is None or not math.isfinite(angle) or (
                    speed is not None and not math.isfinite(speed)):
                # The slow path only for bad messages: it names what is wrong.
                stamp_ns, angle, speed = rm.crank_from_joint_state(self._deserialize(data),
                                                                   joint)
            if stamp_ns == 0:
                raise rm.InputRejected('zero stamp (the publisher does not stamp its messages)')
            return stamp_ns, angle, speed

        def _publish_sample(self, stamp_ns, sample):
            values = self.values
            period = self.period
            period.valid += 1
            period.flags |= sample.flags
            period.max_error_indicator = max(period.max_error_indicator,
                                             sample.error_indicator)
            for j, value in enumerate(sample.criterion):
                if value > period.max_criterion[j]:
                    period.max_criterion[j] = value
                period.near_zero[j] = period.near_zero[j] or sample.near_zero[j]
            if sample.message:
                self.get_logger().warning(f'estimator: {sample.message}',
                                          throttle_duration_sec=WARN_THROTTLE_S)
            # Serialised once (exact CDR), published raw and recorded as the same bytes. The
            # per-sample outputs go out first; the markers (every n-th sample: link shapes
            # and a MarkerArray) after them, so they do not delay this sample's deflection.
            sec, nanosec = divmod(stamp_ns, 1_000_000_000)
            frame = self._frame
            outputs = [
                ('lever_tip', cdr.vector3_stamped_cdr(sec, nanosec, frame, *sample.lever_tip)),
                ('coupler_mid', cdr.vector3_stamped_cdr(sec, nanosec, frame,
                                                        *sample.coupler_mid)),
                ('criteria', cdr.criteria_cdr(sec, nanosec, frame, sample.criterion,
                                              sample.gamma_dot, sample.reaction_n))]
            published = self._publish(outputs)
            if published and self.published % values['markers.every_n'] == 0:
                markers = [('markers', self._markers(stamp_ns, sample))]
                self._publish(markers)
                outputs += markers
            self.published += 1
            if self.recorder is not None:   # recorded even if shut down meanwhile: the input was
                log_ns = self._clock.now().nanoseconds
                for key, data in outputs:
                    self._record(self.output_topics[key], data, log_ns)

        def _publish(self, outputs):
            """Publish (key, CDR) pairs; False if SIGINT/SIGTERM shut the context down."""
            for key, data in outputs:
                try:
                    self.publishers_[key].publish(data)
                except RCLError as exc:
                    if not self._shutting_down(exc):
                        raise
                    return False
            return True

        def _shutting_down(self, exc):
            """Whether a publish error is SIGINT/SIGTERM shutting the context down."""
            from .crank_driver import is_shutdown_error
            return is_shutdown_error(exc, self.context)

        def _markers(self, stamp_ns, sample):
            """CDR of the deformed-linkage markers (template encoder, rebuilt on changes)."""
            values = self.values
            count = values['markers.points_per_link']
            encoder = self._marker_encoder
            if encoder is None or (encoder.frame_id, encoder.count) != (values['frame_id'],
                                                                        count):
                encoder = self._marker_encoder = cdr.MarkerEncoder(values['frame_id'], count)
            positions, deflections = self.estimator.link_shapes(sample)
            source = np.linspace(0.0, 1.0, positions.shape[1])
            target = np.linspace(0.0, 1.0, count)
            resample = lambda a: np.stack([np.interp(target, source, a[:, i])  # noqa: E731
                                           for i in range(2)], axis=1)
            joints = (positions[0, 0], positions[0, -1], positions[1, -1], positions[2, 0])
            levels = [rm.joint_level(c, False, values['diagnostics.criterion_warn'],
                                     values['diagnostics.criterion_error'])
                      for c in sample.criterion]
            return encoder.encode(stamp_ns, [resample(p) for p in positions],
                                  [resample(d) for d in deflections],
                                  values['markers.exaggeration'], joints, levels)

        # -- diagnostics ----------------------------------------------------------------

        def diagnostic_statuses(self):
            """The statuses of one /diagnostics message (and the period is restarted)."""
            values = self.values
            now = time.monotonic()
            elapsed = max(now - self._period_start, 1e-9)
            period, self.period, self._period_start = self.period, PeriodStats(), now
            rate = period.valid / elapsed
            stale = math.inf if self.last_valid_wall is None else now - self.last_valid_wall
            level, message = rm.OK, 'receiving'
            if stale > values['diagnostics.stale_input_s']:
                level = rm.ERROR
                message = ('no valid input yet' if self.last_valid_wall is None
                           else f'no valid input for {stale:.2f} s')
            elif rate < values['diagnostics.min_rate_hz']:
                level, message = rm.WARN, f'input rate {rate:.1f} Hz below ' \
                    f'{values["diagnostics.min_rate_hz"]:g} Hz'
            elif period.rejected:
                level, message = rm.WARN, f'{period.rejected} input messages skipped'
            statuses = [rm.status(f'{NODE_NAME}: input', level, message, {
                'topic': self.input_topic, 'rate_hz': rate,
                'stale_s': stale, 'received': self.received, 'skipped': self.rejected,
                'skipped_in_period': period.rejected, 'last_skip_reason': self.last_rejection})]
            durations = np.array(period.update_ns) / 1e3
            median = float(np.median(durations)) if durations.size else math.nan
            p99 = float(np.percentile(durations, 99)) if durations.size else math.nan
            flags = [flag.name for flag in SampleFlag if flag and period.flags & flag]
            indicator = period.max_error_indicator
            level, message = rm.OK, 'ok'
            if indicator > values['diagnostics.error_indicator_warn']:
                level, message = rm.WARN, f'error indicator {indicator:.3g}'
            statuses.append(rm.status(f'{NODE_NAME}: estimator', level, message, {
                'error_indicator_max': indicator, 'update_us_median': median,
                'update_us_p99': p99, 'samples_in_period': period.valid,
                'flags': ' '.join(flags), 'model_size': self.model.size,
                'model_grid': self.model.grid_size, 'model_options': str(self.options),
                'criteria_source': self.criteria_source, 'notes': '; '.join(self.notes)}))
            no_criteria = period.flags & SampleFlag.NO_CRITERIA
            for j, name in enumerate(rm.JOINT_NAMES):
                ratio = period.max_criterion[j]
                if no_criteria:
                    level, message = rm.STALE, f'criteria unavailable: {self.criteria_source}'
                elif not period.valid:
                    level, message = rm.STALE, 'no samples'
                else:
                    level = rm.joint_level(ratio, period.near_zero[j],
                                           values['diagnostics.criterion_warn'],
                                           values['diagnostics.criterion_error'])
                    message = f'max |dgamma/dt|/R {ratio:.4g} rad/(s N)' + (
                        ', reaction near zero' if period.near_zero[j] else '')
                statuses.append(rm.status(f'{NODE_NAME}: joint {name}', level, message,
                                          {'criterion_max': ratio,
                                           'near_zero': period.near_zero[j]}))
            statuses.append(self._recorder_status())
            return statuses

        def _recorder_status(self):
            if self.recorder is None:
                return rm.status(f'{NODE_NAME}: recorder', rm.OK, 'disabled', {})
            status = self.recorder.status()
            failed = status['state'] == 'failed'
            return rm.status(f'{NODE_NAME}: recorder', rm.ERROR if failed else rm.OK,
                             (f'FAILED: {status["error"]}' if failed else status['state']), {
                                 'path': status['path'], 'messages': status['message_count'],
                                 'dropped': status['dropped_count'],
                                 'bytes': status['bytes_written'],
                                 'files': len(status['files'])})

        def _publish_diagnostics(self):
            now = self._clock.now()
            message = rm.diagnostics_message(now.to_msg(), self.diagnostic_statuses())
            publisher = self.publishers_['diagnostics']
            try:
                publisher.publish(message)
            except RCLError as exc:
                if not self._shutting_down(exc):
                    raise
                return
            self._record(publisher.topic_name, message, now.nanoseconds)

        def close(self):
            """Close the recording (idempotent); returns its status or None."""
            if self.recorder is None or self.recorder.state.value == 'closed':
                return None
            # Not the node's logger: after shutdown its /rosout publisher is gone.
            log = rclpy_logging.get_logger(f'{NODE_NAME}.recorder')
            try:
                status = self.recorder.close()
            except RecorderError as exc:
                log.error(str(exc))
                status = self.recorder.status()
            log.info(f'recording closed: {status["message_count"]} messages in '
                     f'{status["path"]} ({status["state"]})')
            return status

    class FlexlinkNode(Pipeline, Node):
        """flexlink_node: configured and streaming from construction."""

        def __init__(self, **kwargs):
            super().__init__(NODE_NAME, **kwargs)
            self._declare()
            self._configure(self.create_publisher)
            self._activate()

    class FlexlinkManagedNode(Pipeline, LifecycleNode):
        """
        flexlink_node as a managed (lifecycle) node.

        configure loads or builds the model, creates the publishers and opens the recording;
        activate subscribes and starts publishing; deactivate stops receiving; cleanup closes
        the recording.
        """

        def __init__(self, **kwargs):
            super().__init__(NODE_NAME, **kwargs)
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
            return TransitionCallbackReturn.SUCCESS

    return FlexlinkNode, FlexlinkManagedNode


def make_node(managed=False, **kwargs):
    """
    A FlexlinkNode, or its managed (lifecycle) variant (rclpy must be initialised).

    Parameters
    ----------
    managed : bool
        Build the lifecycle node (unconfigured until a configure transition).
    **kwargs
        Passed to rclpy's Node.

    """
    plain, lifecycle = _make_node_class()
    return (lifecycle if managed else plain)(**kwargs)


def release_free_heap():
    """Give the heap freed after the precompute back to the OS (glibc; else nothing).

    Building the model allocates several times its size in temporaries; glibc keeps freed
    heap pages mapped, so without this the node's resident size stays at its build peak.
    """
    try:
        libc = ctypes.CDLL('libc.so.6')
        libc.malloc_trim(0)
    except (OSError, AttributeError):
        pass


def build_parser():
    """Command-line parser for the non-ROS arguments."""
    import argparse
    parser = argparse.ArgumentParser(
        prog=NODE_NAME, description='Elastic deflections and joint criteria of the flexible '
        'four-bar from a crank JointState (parameters: --ros-args --params-file FILE).')
    parser.add_argument('--managed', action='store_true',
                        help='start as a lifecycle node (configure/activate via '
                        'lifecycle services)')
    return parser


def main(args=None):
    """Entry point of the ``flexlink_node`` executable."""
    import rclpy
    from rclpy.exceptions import InvalidParameterTypeException, InvalidParameterValueException
    from rclpy.executors import ExternalShutdownException

    from .crank_driver import make_executor, spin_until_shutdown

    from rclpy.utilities import remove_ros_args

    argv = sys.argv if args is None else [NODE_NAME, *args]
    options = build_parser().parse_args(remove_ros_args(argv)[1:])
    node = None
    try:
        with rclpy.init(args=argv):
            try:
                node = make_node(managed=options.managed)
            except (FlexlinkError, ValueError, InvalidParameterValueException,
                    InvalidParameterTypeException) as exc:
                print(f'{NODE_NAME}: error: {exc}', file=sys.stderr)
                return 1
            executor = make_executor()
            executor.add_node(node)
            # The model, rclpy and numpy are loaded: move them out of the collector's reach,
            # so a full collection never scans them between two samples (p99 latency).
            gc.collect()
            gc.freeze()
            release_free_heap()
            # A background Python thread (the recorder's flusher) holds the GIL for up to
            # the switch interval when a message arrives: 5 ms by default, 0.5 ms here.
            sys.setswitchinterval(SWITCH_INTERVAL_S)
            spin_until_shutdown(executor)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            node.close()
    return 0


if __name__ == '__main__':
    sys.exit(main())
