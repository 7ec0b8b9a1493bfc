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
used (malformed or oversized CDR, NaN, missing joint, empty arrays, an outlier) is counted by
kind, warned about at most once a second and skipped; no single message can stop the node.
Exact repeats are counted and not published again; an estimate beyond the model's bound (or
non-finite) is counted and not published. SIGINT/SIGTERM during start-up exit with one line
and code 0.
"""

import os
import signal
import sys

from ..errors import StartupInterrupted
from ..names import NODE_NAME, TOPICS



# Start-up state: 'active' until the node spins; 'signal' = a signal not acted on yet.
_STARTUP = {'active': False, 'signal': None}


def _in_rclpy(frame):
    """Whether rclpy code is on the interrupted stack (an exception there can wedge it)."""
    while frame is not None:
        if f'{os.sep}rclpy{os.sep}' in frame.f_code.co_filename:
            return True
        frame = frame.f_back
    return False


def _on_startup_signal(signum, frame):
    if not _STARTUP['active']:
        if signum == signal.SIGINT:     # spinning: rclpy has shut the context down already
            raise KeyboardInterrupt
        return
    _STARTUP['signal'] = signal.Signals(signum).name
    if not _in_rclpy(frame):
        check_startup_signal()


def check_startup_signal():
    """Exit (StartupInterrupted) if SIGINT/SIGTERM arrived during start-up; a safe point."""
    name = _STARTUP['signal']
    if _STARTUP['active'] and name is not None:
        _STARTUP['active'] = False
        os.write(2, f'{NODE_NAME}: {name} during start-up: exiting\n'.encode())
        raise StartupInterrupted(name)


def install_startup_signal_handlers():
    """SIGINT/SIGTERM end the process cleanly until the node spins (rclpy chains to these)."""
    _STARTUP['active'] = True
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, _on_startup_signal)


if __name__ == '__main__':  # before the second or so of imports below
    install_startup_signal_handlers()

import ctypes  # noqa: E402  (after the start-up signal handlers, see above)
import dataclasses  # noqa: E402
import gc  # noqa: E402
import math  # noqa: E402
import time  # noqa: E402
import warnings  # noqa: E402

import numpy as np  # noqa: E402

from ..io import cdr
from . import parameters as node_params  # noqa: E402
from . import messages as rm  # noqa: E402
from ..core.reduction import model as reduced  # noqa: E402
from ..errors import FlexlinkError, OutlierSample, RecorderError  # noqa: E402
from ..core.estimation.streaming import SampleFlag, StreamingEstimator  # noqa: E402
from ..core.mechanism import load_mechanism  # noqa: E402

WARN_THROTTLE_S = 1.0  # at most one warning per second per kind of bad input
# The default model (node parameters, core.reduced.DEFAULT_SIZES) meets this relative RMS
# error on Cho 1992 against flexlink plan's scene reference (1.3 % coupler, 0.9 % lever).
DEFAULT_MODEL_TOLERANCE = 0.02
READY_MESSAGE = 'ready: listening on'  # logged once the node is subscribed (cli_demo waits)
FIRST_INPUT_MESSAGE = 'first crank sample'
# GIL switch interval of the node process [s] (see main).
SWITCH_INTERVAL_S = 0.0005
MAX_REASON_CHARS = 200   # a refusal's reason as logged and in /diagnostics
# What happens to a received message (counted per kind, in total and per diagnostics period).
SKIP_KINDS = ('malformed', 'content', 'estimator', 'internal')   # counted as 'skipped'
OTHER_KINDS = ('outlier', 'repeated', 'out_of_bound')
# Flags after which the estimate is not to be trusted blindly: the estimator status is WARN.
WARN_FLAGS = (SampleFlag.CLIPPED_SPEED | SampleFlag.CLIPPED_ACCEL | SampleFlag.OUTLIER
              | SampleFlag.COLD_START)


def one_line(text):
    """The first line of ``text``, cut to MAX_REASON_CHARS."""
    lines = str(text).strip().splitlines()
    line = lines[0] if lines else ''
    return line if len(line) <= MAX_REASON_CHARS else line[:MAX_REASON_CHARS - 3] + '...'


def crank_sample(data, joint_name, deserialize):
    """
    Stamp, angle and speed of the crank from JointState CDR; InputRejected says why not.

    The fast parser (cdr.parse_joint_state) checks the bytes against the input bounds; only a
    message without a usable sample is deserialised by rclpy, to name what is wrong, and an
    error there (rclpy raises RMWError on truncated CDR) is a refusal too.

    Parameters
    ----------
    data : bytes
        CDR of a ``sensor_msgs/JointState``.
    joint_name : str
        Name of the crank joint.
    deserialize : callable
        bytes -> sensor_msgs.msg.JointState (rclpy's deserialize_message).

    Returns
    -------
    stamp_ns : int
    angle : float
    speed : float or None

    Raises
    ------
    ros_messages.InputRejected
        With ``kind`` 'malformed' or 'content' and a one-line reason.

    """
    try:
        stamp_ns, angle, speed = cdr.parse_joint_state(data, joint_name.encode())
    except cdr.MalformedCdr as exc:
        raise rm.InputRejected(f'malformed JointState: {one_line(exc)}', 'malformed') from None
    if angle is None or not math.isfinite(angle) or (
            speed is not None and not math.isfinite(speed)):
        try:
            message = deserialize(data)
        except (RuntimeError, ValueError, TypeError, MemoryError) as exc:  # RMWError: Runtime
            raise rm.InputRejected(f'malformed JointState ({type(exc).__name__}): '
                                   f'{one_line(exc)}', 'malformed') from None
        stamp_ns, angle, speed = rm.crank_from_joint_state(message, joint_name)
    if stamp_ns <= 0:
        raise rm.InputRejected('zero stamp (the publisher does not stamp its messages)'
                               if stamp_ns == 0 else f'negative stamp {stamp_ns} ns')
    return stamp_ns, angle, speed


def publishable(sample):
    """
    Why a Sample's numbers may not be published (None if they may).

    The estimator flags OUT_OF_BOUND every estimate beyond its deflection bound or not finite
    (a non-finite state makes the deflections non-finite), so the flag is the one test.
    """
    if sample.flags & SampleFlag.OUT_OF_BOUND:
        return sample.message or 'deflection beyond the model\'s bound'
    return None


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
    counts: dict = dataclasses.field(default_factory=dict)   # kind -> messages
    last_out_of_bound: str = ''
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
    elif spec.max_bytes is not None:
        descriptor.additional_constraints = f'at most {spec.max_bytes} bytes (UTF-8)'
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

    from ..io.recorder import McapRecorder

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
            check_startup_signal()
            self.model, self.options, self.notes = load_node_model(values, log.warning)
            check_startup_signal()
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
            self.counts = dict.fromkeys(SKIP_KINDS + OTHER_KINDS, 0)
            self.last_valid_wall = None
            self.last_rejection = self.last_outlier = ''

        def _activate(self):
            """Subscribe and start the diagnostics timer: estimates flow from now on."""
            values = self.values
            self.estimator.reset()
            self.period = PeriodStats()
            self._period_start = time.monotonic()
            self.subscription = self.create_subscription(
                JointState, values['input_topic'], self._on_joint_state, self.qos, raw=True)
            self._start_diagnostics_timer()
            self.get_logger().info(
                f'{READY_MESSAGE} {self.subscription.topic_name} (joint '
                f'{values["crank_joint"]!r}), publishing under {self.get_name()}/'
                + ('' if self.recorder is None else f'; recording to {self.recorder.path}'))
            if not self.estimator.compiled:
                self.get_logger().warning(
                    'the compiled estimator step (flexlink_ros.core.estimation._radau_step) is not built: '
                    'the numpy step runs, about twice as slow (build the package with '
                    'colcon build or pip install .)')

        def _start_diagnostics_timer(self):
            if self._timer is not None:
                self.destroy_timer(self._timer)
            self._timer = self.create_timer(self.values['diagnostics.period_s'],
                                            self._publish_diagnostics)

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
            """Run-time changes take effect here (the others are read-only)."""
            period_changed = any(p.name == 'diagnostics.period_s'
                                 and p.value != self.values[p.name] for p in parameters)
            for parameter in parameters:
                self.values[parameter.name] = parameter.value
            if self.estimator is not None:
                self.estimator.warm_start = self.values['model.warm_start']
            self._frame = self.values['frame_id'].encode()
            if period_changed and self._timer is not None:
                self._start_diagnostics_timer()

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
            if len(data) > cdr.MAX_MESSAGE_BYTES:   # not recorded either
                self._refuse('malformed', f'{len(data)} bytes, beyond the bound of '
                             f'{cdr.MAX_MESSAGE_BYTES}')
                return
            if self.recorder is not None:
                self._record(self.input_topic, data, receive_ns)
            try:
                self._estimate(data)
            except Exception as exc:    # last resort: no message may stop the node
                self.get_logger().error(f'unexpected {type(exc).__name__} on an input '
                                        f'message: {one_line(exc)}',
                                        throttle_duration_sec=WARN_THROTTLE_S)
                self._refuse('internal', f'{type(exc).__name__}: {one_line(exc)}')

        def _estimate(self, data):
            try:
                stamp_ns, angle, speed = crank_sample(data, self.values['crank_joint'],
                                                      self._deserialize)
                start = time.perf_counter_ns()
                sample = self.estimator.update(stamp_ns, angle, speed)
                self.period.update_ns.append(time.perf_counter_ns() - start)
            except rm.InputRejected as exc:
                self._refuse(exc.kind, str(exc))
                return
            except OutlierSample as exc:
                self.period.flags |= SampleFlag.OUTLIER
                self._refuse('outlier', str(exc))
                return
            except (FlexlinkError, ValueError) as exc:
                self._refuse('estimator', one_line(exc))
                return
            if sample.flags & SampleFlag.REPEATED:
                self._count('repeated')
                return
            reason = publishable(sample)
            if reason is not None:
                self._count('out_of_bound')
                self.period.flags |= sample.flags | SampleFlag.OUT_OF_BOUND
                self.period.last_out_of_bound = reason
                self.get_logger().warning(f'estimate not published: {reason}',
                                          throttle_duration_sec=WARN_THROTTLE_S)
                return
            if self.last_valid_wall is None:
                self.get_logger().info(f'{FIRST_INPUT_MESSAGE}: angle {angle:.4f} rad, '
                                       f'speed {speed} rad/s')
            self.last_valid_wall = time.monotonic()
            self._publish_sample(stamp_ns, sample)

        def _count(self, kind):
            self.counts[kind] += 1
            self.period.counts[kind] = self.period.counts.get(kind, 0) + 1

        def _refuse(self, kind, reason):
            """Count a message that gives no estimate; warn (at most once a second per branch)."""
            self._count(kind)
            reason = one_line(reason)
            if kind in SKIP_KINDS:
                self.rejected += 1
                self.period.rejected += 1
                self.last_rejection = reason
                self.get_logger().warning(f'input skipped: {reason}',
                                          throttle_duration_sec=WARN_THROTTLE_S)
            else:
                self.last_outlier = reason
                self.get_logger().warning(f'input skipped as {reason}',
                                          throttle_duration_sec=WARN_THROTTLE_S)

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
            elif period.rejected or period.counts.get('outlier'):
                level, message = rm.WARN, (f'{period.rejected} input messages skipped, '
                                           f'{period.counts.get("outlier", 0)} outliers')
            statuses = [rm.status(f'{NODE_NAME}: input', level, message, self._input_counts(
                period, {'topic': self.input_topic, 'rate_hz': rate, 'stale_s': stale}))]
            durations = np.array(period.update_ns) / 1e3
            median = float(np.median(durations)) if durations.size else math.nan
            p99 = float(np.percentile(durations, 99)) if durations.size else math.nan
            flags = [flag.name for flag in SampleFlag if flag and period.flags & flag]
            level, message = self._estimator_level(period)
            indicator = period.max_error_indicator
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

        def _input_counts(self, period, values):
            """Key values of the input status: what became of every received message."""
            values.update({'received': self.received, 'published': self.published,
                           'skipped': self.rejected, 'skipped_in_period': period.rejected,
                           'last_skip_reason': self.last_rejection,
                           'last_outlier': self.last_outlier})
            for kind in SKIP_KINDS:
                values[f'skipped_{kind}'] = self.counts[kind]
            for kind in OTHER_KINDS:
                values[kind] = self.counts[kind]
                values[f'{kind}_in_period'] = period.counts.get(kind, 0)
            return values

        def _estimator_level(self, period):
            """ERROR for estimates out of bound, WARN for flagged ones or a large indicator."""
            if period.counts.get('out_of_bound'):
                return rm.ERROR, (f'{period.counts["out_of_bound"]} estimates not published: '
                                  f'{period.last_out_of_bound}')
            reasons = []
            flagged = SampleFlag(period.flags & WARN_FLAGS)
            if flagged:
                reasons.append('flagged ' + ' '.join(f.name for f in SampleFlag
                                                     if f and f & flagged))
            if period.counts.get('outlier'):
                reasons.append(f'{period.counts["outlier"]} outliers skipped')
            indicator = period.max_error_indicator
            if indicator > self.values['diagnostics.error_indicator_warn']:
                reasons.append(f'error indicator {indicator:.3g}')
            return (rm.WARN, ', '.join(reasons)) if reasons else (rm.OK, 'ok')

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
    """
    Entry point of the ``flexlink_node`` executable.

    SIGINT or SIGTERM before the node spins (rclpy init, model build) end it with one line
    on stderr and exit code 0, as the same signals do while it spins.
    """
    if not _STARTUP['active']:      # not started as `python -m flexlink_ros.ros.node`
        install_startup_signal_handlers()
    try:
        return _run(args)
    finally:
        _STARTUP['active'] = False


def _make_node_at_start_up(managed):
    """make_node, or StartupInterrupted if a signal came first (rclpy errors it caused too)."""
    check_startup_signal()
    # rclpy warns when a signal shuts the context down under a node being created; those
    # warnings are held back, and shown only if no signal explains them.
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter('always')
            node = make_node(managed=managed)
    except Exception:
        check_startup_signal()      # a signal inside rclpy shut the context down
        raise
    finally:
        if _STARTUP['signal'] is None:
            for warning in caught:
                warnings.warn_explicit(warning.message, warning.category,
                                       warning.filename, warning.lineno)
    check_startup_signal()
    return node


def _run(args):
    import rclpy
    from rclpy.exceptions import (InvalidParameterTypeException,
                                  InvalidParameterValueException, NameValidationException)
    from rclpy.executors import ExternalShutdownException
    from rclpy.utilities import remove_ros_args

    from .crank_driver import make_executor, spin_until_shutdown

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
            # The model, rclpy and numpy are loaded: move them out of the collector's reach,
            # so a full collection never scans them between two samples (p99 latency).
            gc.collect()
            gc.freeze()
            release_free_heap()
            # A background Python thread (the recorder's flusher) holds the GIL for up to
            # the switch interval when a message arrives: 5 ms by default, 0.5 ms here.
            sys.setswitchinterval(SWITCH_INTERVAL_S)
            check_startup_signal()
            _STARTUP['active'] = False      # from here on rclpy's shutdown ends the spin
            executor = make_executor()
            executor.add_node(node)
            spin_until_shutdown(executor)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            node.close()
    return 0


if __name__ == '__main__':
    sys.exit(main())
