"""
The work of flexlink_node, shared by the plain and the managed (lifecycle) node.

:class:`EstimatorNode` declares the parameters, loads the model, creates the publishers,
subscribes to the crank's JointState, runs the estimator on every message, publishes (and
records, :mod:`.node_recording`) the outputs as CDR and publishes ``/diagnostics`` on a timer
of the steady clock (so also on simulated time without ``/clock``, :mod:`.sim_time`). It is a
mixin: the node classes in :mod:`.node` combine it with rclpy's ``Node`` or ``LifecycleNode``.
"""

import functools
import time

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import Vector3Stamped
import numpy as np
from rcl_interfaces.msg import SetParametersResult
from rclpy.clock import Clock, ClockType
from rclpy.exceptions import InvalidHandle
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message, serialize_message
from rclpy.subscription import RCLError
from sensor_msgs.msg import JointState
from visualization_msgs.msg import MarkerArray

from . import diagnostics, parameters
from .input_watch import InputWatch
from .marker_worker import MarkerWorker
from .message_outcomes import (ClippedSpeedLog, crank_sample, one_line, PeriodStats,
                               publishable, SKIP_KINDS, Totals)
from .messages import diagnostics_message, joint_level, ns_to_stamp
from .node_model import choose_nonlinear, load_node_model, load_nonlinear_model, \
    marker_exaggeration
from .node_recording import NodeRecording
from .overrides import declare_table
from .progress_log import ProgressLog
from .runtime import is_shutdown_error
from .sim_time import ClockWatch, LogTime
from .startup import check_startup_signal
from ..core.estimation.nonlinear_follow import NonlinearFollower
from ..core.estimation.sample import OUT_OF_BOUND, OUTLIER, REPEATED
from ..core.estimation.streaming import StreamingEstimator
from ..core.mechanism_file import read_mechanism_source
from ..core.reduction.soft_basis import soft_basis_text
from ..errors import ConflictingSample, FlexlinkError, InputRejected, OutlierSample
from ..io import cdr
from ..io.output_cdr import criteria_cdr, MarkerEncoder, quality_cdr, vector3_stamped_cdr
from ..names import FIRST_INPUT_MESSAGE, READY_MESSAGE, TOPICS

WARN_THROTTLE_S = 1.0  # at most one warning per second per kind of bad input
INPUT_NOTE_THROTTLE_S = 10.0   # input lost or several publishers: at most every 10 s
# A flood of input can hold the diagnostics timer off: after this many periods without
# /diagnostics the input callback publishes them.
OVERDUE_PERIODS = 2
# Message type of each output (keys of names.TOPICS).
# /diagnostics is a plain publisher, created with the node: a managed node reports while
# unconfigured and inactive too.
OUTPUT_TYPES = {'lever_tip': Vector3Stamped, 'coupler_mid': Vector3Stamped,
                'criteria': JointState, 'quality': JointState, 'markers': MarkerArray}
PER_SAMPLE_OUTPUTS = ('lever_tip', 'coupler_mid', 'criteria', 'quality')   # the input's QoS
OTHER_OUTPUT_DEPTH = 10   # history depth of markers and /diagnostics


@functools.lru_cache(maxsize=4)
def linear_resampling(points, count):
    """Matrix (count, points): equally spaced points to ``count`` ones, linearly (as np.interp)."""
    source, target = np.linspace(0.0, 1.0, points), np.linspace(0.0, 1.0, count)
    return np.stack([np.interp(target, source, unit) for unit in np.eye(points)], axis=1)


class EstimatorNode(NodeRecording):
    """The node's work, shared by the plain and the managed (lifecycle) node."""

    def _declare(self):
        self.unknown_overrides = declare_table(self, parameters.PARAMETERS)
        self.values = parameters.validate_all(
            {spec.name: self.get_parameter(spec.name).value for spec in parameters.PARAMETERS})
        self.add_on_set_parameters_callback(self._validate)
        self.add_post_set_parameters_callback(self._apply)
        self.estimator = self.follower = self.recorder = self.subscription = self._timer = None
        self.publishers_ = {}
        self._clock = self.get_clock()
        self._log_time = LogTime()
        self._clock_watch = ClockWatch(self.get_logger().warning, self.get_logger().info)
        self._deserialize = lambda data: deserialize_message(data, JointState)
        self._serialize = serialize_message
        self._frame = self.values['frame_id'].encode()
        self._read_crank = cdr.JointStateReader(self.values['crank_joint'].encode())
        self._marker_encoder = self._marker_worker = None
        self.totals = self.model_facts = None
        self._diagnostics_publisher = self.create_publisher(
            DiagnosticArray, TOPICS['diagnostics'], OTHER_OUTPUT_DEPTH)
        self._start_diagnostics_timer()

    # -- lifecycle ------------------------------------------------------------------------

    def _configure(self, make_publisher):
        """Load or build the model, create the publishers, open the recording."""
        values = self.values
        log = self.get_logger()
        start = time.perf_counter()
        check_startup_signal()
        # Read once: the model is built from these bytes and the recording names them.
        self.mechanism_source = read_mechanism_source(values['mechanism'])
        self.model, self.options, self.notes = load_node_model(
            values, log.warning, ProgressLog(log.info), self.mechanism_source)
        check_startup_signal()
        self.criteria_source = self.model.info.get('criteria', 'unknown')
        log.info(f'model: {self.model.size} coordinates, {soft_basis_text(self.model)}, '
                 f'{self.model.grid_size} grid cells, '
                 f'{self.options} ({time.perf_counter() - start:.2f} s); '
                 f'criteria: {self.criteria_source}')
        self.estimator = StreamingEstimator(self.model, warm_start=values['model.warm_start'])
        self.auto_exaggeration = marker_exaggeration(self.estimator, log.info,
                                                     self.mechanism_source)
        check_startup_signal()
        self.follower, nonlinear_facts = self._nonlinear_model(log)
        # The node only streams: the step tables serve it, the full table can go.
        self.model = self.estimator.release_model_table()
        self.model_facts = {'model_size': self.model.size, 'model_grid': self.model.grid_size,
                            'model_step_size': self.model.step_size,
                            'model_options': str(self.options),
                            'criteria_source': self.criteria_source,
                            **nonlinear_facts, 'notes': '; '.join(self.notes)}
        self._create_publishers(make_publisher)
        self.recorder = self._open_recorder(self.qos) if values['record.enabled'] else None
        self._marker_worker = MarkerWorker(self._markers, self._deliver_markers,
                                           self._report_marker_error)
        self.totals = Totals()
        self.last_valid_wall = None
        self._clipped = ClippedSpeedLog(log.warning, self.context.ok, self.options.speed_max)

    def _nonlinear_model(self, log):
        """Choose and load the nonlinear model (model.nonlinear); (follower or None, facts)."""
        use, why = choose_nonlinear(self.values, self.model)
        if not use:
            log.info(f'model: linear ({why})')
            return None, {'model_nonlinear': 'off', 'model_choice': why}
        tables, damping = load_nonlinear_model(self.values, self.mechanism_source,
                                               self.options)
        log.info(f'model: nonlinear ({why}): the lever-tip and coupler-mid deflections are '
                 f"the nonlinear model's ({tables.size} coordinates, {damping}); criteria "
                 "and markers the linear model's")
        return (NonlinearFollower(tables, self.estimator.reset_gap_s),
                {'model_nonlinear': 'on', 'model_choice': why, 'nonlinear_damping': damping})

    def _create_publishers(self, make_publisher):
        """Create the output publishers with the QoS the parameters select."""
        values = self.values
        reliability = (ReliabilityPolicy.RELIABLE if values['qos.reliability'] == 'reliable'
                       else ReliabilityPolicy.BEST_EFFORT)
        self.qos = QoSProfile(depth=values['qos.depth'], reliability=reliability)
        self.publishers_ = {
            key: make_publisher(message_type, TOPICS[key],
                                self.qos if key in PER_SAMPLE_OUTPUTS else OTHER_OUTPUT_DEPTH)
            for key, message_type in OUTPUT_TYPES.items()}
        self.publishers_['diagnostics'] = self._diagnostics_publisher
        self.input_topic = self.resolve_topic_name(values['input_topic'])
        self.output_topics = {key: publisher.topic_name
                              for key, publisher in self.publishers_.items()}

    def _activate(self):
        """Subscribe and start the diagnostics timer: estimates flow from now on."""
        values = self.values
        self.estimator.reset()
        if self.follower is not None:
            self.follower.restart()
        self.period, self.watch = PeriodStats(), InputWatch()
        self._period_start = time.monotonic()
        self.subscription = self.create_subscription(
            JointState, values['input_topic'], self._on_joint_state, self.qos, raw=True)
        self.get_logger().info(
            f'{READY_MESSAGE} {self.subscription.topic_name} (joint '
            f'{values["crank_joint"]!r}), publishing under {self.get_name()}/'
            + self._recording_text())
        if not self.estimator.compiled:
            self.get_logger().warning(
                'the compiled estimator step (flexlink_ros.core.estimation._radau_step) is '
                'not built: the numpy step runs, about twice as slow (build the package with '
                'colcon build or pip install .)')

    def _start_diagnostics_timer(self):
        self._set_overdue()
        if self._timer is not None:
            self.destroy_timer(self._timer)
        self._timer = self.create_timer(self.values['diagnostics.period_s'],
                                        self._publish_diagnostics,
                                        clock=Clock(clock_type=ClockType.STEADY_TIME))

    def _deactivate(self):
        """Stop receiving (the model, publishers, recording and /diagnostics stay)."""
        if self.subscription is not None:
            self.destroy_subscription(self.subscription)
            self.subscription = None

    def _cleanup(self):
        """Close the recording and drop publishers and model."""
        self._deactivate()
        self.close()
        self._marker_worker = None
        for key, publisher in self.publishers_.items():
            if key != 'diagnostics':
                self.destroy_publisher(publisher)
        self.publishers_ = {}
        self.estimator = self.follower = self.recorder = None

    # -- parameters -----------------------------------------------------------------------

    def _validate(self, changes):
        current = dict(self.values)
        current.update({p.name: p.value for p in changes})
        for parameter in changes:
            reason = parameters.validate_parameter(parameter.name, parameter.value, current)
            if reason is not None:
                return SetParametersResult(successful=False, reason=reason)
        return SetParametersResult(successful=True)

    def _apply(self, changes):
        """Run-time changes take effect here (the others are read-only)."""
        period_changed = any(p.name == 'diagnostics.period_s'
                             and p.value != self.values[p.name] for p in changes)
        for parameter in changes:
            self.values[parameter.name] = parameter.value
        if self.estimator is not None:
            self.estimator.warm_start = self.values['model.warm_start']
        self._frame = self.values['frame_id'].encode()
        if self._read_crank.joint_name != self.values['crank_joint'].encode():
            self._read_crank = cdr.JointStateReader(self.values['crank_joint'].encode())
        if period_changed and self._timer is not None:
            self._start_diagnostics_timer()

    # -- the per-message path -------------------------------------------------------------

    def _on_joint_state(self, data):
        start = time.monotonic_ns()
        watch = self.watch
        self._take(data)
        watch.busy_ns += time.monotonic_ns() - start
        watch.received += 1
        if start > self._overdue_ns:
            self._publish_diagnostics()

    def _set_overdue(self):
        self._overdue_ns = time.monotonic_ns() + int(
            OVERDUE_PERIODS * self.values['diagnostics.period_s'] * 1e9)

    def _take(self, data):
        recorder = self.recorder
        receive_ns = self._clock.now().nanoseconds if recorder is not None else 0
        estimator = self.estimator
        if estimator is None or self.subscription is None:
            # Queued before a deactivate or cleanup that ran first: an inactive node's rule.
            if self.totals is not None:
                self.totals.received += 1
                self.totals.counts['inactive'] += 1
            return
        self.totals.received += 1
        if len(data) > cdr.MAX_MESSAGE_BYTES:   # not recorded either
            self._refuse('malformed', f'{len(data)} bytes, beyond the bound of '
                         f'{cdr.MAX_MESSAGE_BYTES}')
            return
        self._to_record = None
        try:
            self._estimate(data, estimator)
        except Exception as exc:    # last resort: no message may stop the node
            self.get_logger().error(f'unexpected {type(exc).__name__} on an input '
                                    f'message: {one_line(exc)}',
                                    throttle_duration_sec=WARN_THROTTLE_S)
            self._refuse('internal', f'{type(exc).__name__}: {one_line(exc)}')
        finally:
            # Recorded once the outputs are out (they wait for nothing), input first.
            if recorder is not None:
                self._record_input(data, receive_ns)
                self._record_outputs()

    def _estimate(self, data, estimator):
        try:
            stamp_ns, angle, speed = crank_sample(data, self.values['crank_joint'],
                                                  self._deserialize, self._read_crank)
            self.watch.note(stamp_ns)
            start = time.perf_counter_ns()
            sample = estimator.update(stamp_ns, angle, speed)
            self.period.update_ns.append(time.perf_counter_ns() - start)
        except InputRejected as exc:
            self._refuse(exc.kind, str(exc))
            return
        except OutlierSample as exc:
            self.period.flags |= OUTLIER
            self._refuse('outlier', str(exc))
            return
        except ConflictingSample as exc:
            self._refuse('conflicting', str(exc))
            return
        except (FlexlinkError, ValueError) as exc:
            self._refuse('estimator', one_line(exc))
            return
        if sample.flags & REPEATED:
            self._count('repeated')
            return
        reason = publishable(sample)
        if reason is not None:
            self._count('out_of_bound')
            self.period.flags |= sample.flags | OUT_OF_BOUND
            self.period.last_out_of_bound = reason
            self.get_logger().warning(f'estimate not published: {reason}',
                                      throttle_duration_sec=WARN_THROTTLE_S)
            return
        deflections = self._deflections(stamp_ns, sample)
        if deflections is None:
            return
        if self.last_valid_wall is None:
            self.get_logger().info(f'{FIRST_INPUT_MESSAGE}: angle {angle:.4f} rad, '
                                   f'speed {speed} rad/s')
        self.last_valid_wall = time.monotonic()
        self._publish_sample(stamp_ns, sample, *deflections)

    def _deflections(self, stamp_ns, sample):
        """
        Return (lever tip, coupler mid, validity indicator) to publish, or None (counted).

        The nonlinear model's where it runs (stepped on the linear estimator's crank angle
        and speed, its time counted in the update's; its validity None: the follower's
        ``judge`` gives it once the lever tip is published), else the linear sample's.
        """
        follower = self.follower
        if follower is None:
            return sample.lever_tip, sample.coupler_mid, sample.nonlinearity
        start = time.perf_counter_ns()
        values = follower.sample(stamp_ns, sample.crank_angle, sample.crank_speed,
                                 judge=False).tolist()
        self.period.update_ns[-1] += time.perf_counter_ns() - start
        largest = max(map(abs, values))
        bound = self.estimator.deflection_bound_m
        if not largest <= bound:      # also NaN
            follower.judge()
            follower.restart()
            self._count('out_of_bound')
            self.period.flags |= OUT_OF_BOUND
            self.period.last_out_of_bound = (f'nonlinear deflection {largest:.6g} m beyond '
                                             f'the bound {bound:.6g} m')
            self.get_logger().warning('estimate not published: '
                                      + self.period.last_out_of_bound,
                                      throttle_duration_sec=WARN_THROTTLE_S)
            return None
        # The validity (the link slopes judged) waits until the lever tip is out.
        return values[0:2], values[2:4], None

    def _count(self, kind):
        self.totals.counts[kind] += 1
        self.period.counts[kind] = self.period.counts.get(kind, 0) + 1

    def _refuse(self, kind, reason):
        """Count a message that gives no estimate; warn (at most once a second per branch)."""
        self._count(kind)
        reason = one_line(reason)
        if kind in SKIP_KINDS:
            self.totals.rejected += 1
            self.period.rejected += 1
            self.totals.last_rejection = reason
            self.get_logger().warning(f'input skipped: {reason}',
                                      throttle_duration_sec=WARN_THROTTLE_S)
        else:
            self.totals.last_outlier = reason
            self.get_logger().warning(f'input skipped as {reason}',
                                      throttle_duration_sec=WARN_THROTTLE_S)

    def _publish_sample(self, stamp_ns, sample, lever_tip, coupler_mid, validity):
        # Serialised once (exact CDR), published raw and recorded as the same bytes. The
        # per-sample outputs go out first, before any bookkeeping, the lever tip before the
        # others are encoded; the markers (every n-th sample: link shapes and a MarkerArray)
        # are drawn by their own thread, so they delay neither this sample nor the next.
        sec, nanosec = divmod(stamp_ns, 1_000_000_000)
        frame = self._frame
        outputs = [('lever_tip', vector3_stamped_cdr(sec, nanosec, frame, *lever_tip))]
        published = self._publish(outputs)     # False once SIGTERM shut rclpy down
        if validity is None:        # the nonlinear model's, judged after the lever tip
            validity = self.follower.judge()
        outputs += [
            ('coupler_mid', vector3_stamped_cdr(sec, nanosec, frame, *coupler_mid)),
            ('criteria', criteria_cdr(sec, nanosec, frame, sample.criterion,
                                      sample.gamma_dot, sample.reaction_n)),
            ('quality', quality_cdr(sec, nanosec, frame, sample.error_indicator, validity))]
        if published:
            self._publish(outputs[1:])
        self.period.add_sample(sample, validity)
        self._clipped.add(sample)     # beyond the model's speed range: counted and said
        if sample.message:
            self.get_logger().warning(f'estimator: {sample.message}',
                                      throttle_duration_sec=WARN_THROTTLE_S)
        # Drawn even if SIGTERM shut rclpy down meanwhile: recorded as this sample's outputs.
        marked = self.totals.published % self.values['markers.every_n'] == 0
        self.totals.published += 1
        log_ns = (self._log_time(self._clock.now().nanoseconds, stamp_ns)
                  if self.recorder is not None or marked else 0)
        if self.recorder is not None:   # recorded even if shut down meanwhile: the input was
            self._to_record = (outputs, log_ns)
        if marked:
            self._marker_worker.submit(stamp_ns, sample, log_ns)

    def _record_outputs(self):
        """Record the outputs of the message just taken (after its input)."""
        if self._to_record is not None:
            outputs, log_ns = self._to_record
            self._to_record = None
            for key, data in outputs:
                self._record(self.output_topics[key], data, log_ns)

    def _publish(self, outputs):
        """Publish (key, CDR) pairs; False if SIGINT/SIGTERM shut the context down."""
        for key, data in outputs:
            try:
                self.publishers_[key].publish(data)
            except (RCLError, InvalidHandle) as exc:
                # InvalidHandle: the markers still waiting at shutdown are delivered after
                # rclpy shut the context down (recorded all the same, not published).
                if not is_shutdown_error(exc, self.context):
                    raise
                return False
        return True

    def _deliver_markers(self, data, log_ns):
        """Publish and record a MarkerArray (the marker thread's)."""
        self._publish([('markers', data)])
        self._record(self.output_topics['markers'], data, log_ns)   # as the other outputs

    def _report_marker_error(self, exc):
        self.get_logger().error(f'markers not drawn: {type(exc).__name__}: {one_line(exc)}',
                                throttle_duration_sec=WARN_THROTTLE_S)

    def close(self):
        """Deliver the markers still waiting, then close the recording (idempotent)."""
        if self._marker_worker is not None:
            self._marker_worker.stop()
        return super().close()

    def _markers(self, stamp_ns, sample):
        """CDR of the deformed-linkage markers (template encoder, rebuilt on changes)."""
        values = self.values
        count = values['markers.points_per_link']
        encoder = self._marker_encoder
        if encoder is None or (encoder.frame_id, encoder.count) != (values['frame_id'], count):
            encoder = self._marker_encoder = MarkerEncoder(values['frame_id'], count)
        positions, deflections = self.estimator.link_shapes(sample)
        resample = linear_resampling(positions.shape[1], count)
        joints = (positions[0, 0], positions[0, -1], positions[1, -1], positions[2, 0])
        levels = [joint_level(c, False, values['diagnostics.criterion_warn'],
                              values['diagnostics.criterion_error'])
                  for c in sample.criterion]
        return encoder.encode(stamp_ns, list(resample @ positions), list(resample @ deflections),
                              values['markers.exaggeration'] or self.auto_exaggeration,
                              joints, levels)

    # -- diagnostics ----------------------------------------------------------------------

    def diagnostic_statuses(self):
        """Return the statuses of one /diagnostics message, named after the node."""
        if self.estimator is None:
            statuses = diagnostics.unconfigured_statuses()
        elif self.subscription is None:
            statuses = diagnostics.inactive_statuses(
                self.totals, self.input_topic, self.model_facts,
                None if self.recorder is None
                else self.recorder.status(list_files=False))
        else:
            statuses = self._active_statuses()
        return diagnostics.named(statuses, self.get_fully_qualified_name(),
                                 self.values['diagnostics.hardware_id'])

    def _active_statuses(self):
        """Return the statuses of a streaming node (and restart the period)."""
        now = time.monotonic()
        elapsed = max(now - self._period_start, 1e-9)
        period, self.period, self._period_start = self.period, PeriodStats(), now
        rate = period.valid / elapsed
        stale = float('inf') if self.last_valid_wall is None else now - self.last_valid_wall
        values = self.values
        watch = self.watch.judge(elapsed, period.counts.get('outlier', 0)
                                 + period.counts.get('conflicting', 0),
                                 self.count_publishers(self.input_topic),
                                 self.estimator.reset_gap_s)
        if watch[1]:
            self.get_logger().warning('input: ' + '; '.join(watch[1]),
                                      throttle_duration_sec=INPUT_NOTE_THROTTLE_S)
        return [diagnostics.input_status(self.totals, period, values, self.input_topic,
                                         rate, stale, watch),
                diagnostics.estimator_status(period, values, self._estimator_facts()),
                *diagnostics.joint_statuses(period, values, self.criteria_source),
                diagnostics.recorder_status(None if self.recorder is None
                                            else self.recorder.status(list_files=False))]

    def _estimator_facts(self):
        """
        Return the model's facts, and the nonlinear model's counts where it runs.

        Also the markers dropped by a marker thread that fell far behind, if any.
        """
        facts = self.model_facts
        dropped = self._marker_worker.dropped if self._marker_worker is not None else 0
        if dropped:
            facts = {**facts, 'markers_dropped': dropped}
        follower = self.follower
        if follower is None:
            return facts
        counts = follower.counts
        return {**facts, 'nonlinear_samples': counts['samples'],
                'nonlinear_refused_samples': counts['refused_samples'],
                'nonlinear_restarts': counts['restarts'],
                'nonlinear_link_slope_max_rad': follower.slope_max}

    def _publish_diagnostics(self):
        self._set_overdue()
        clock_ns = self._clock.now().nanoseconds
        self._clock_watch.check(self.get_parameter('use_sim_time').value, clock_ns)
        now_ns = self._log_time(clock_ns)     # not 0 on simulated time without /clock
        message = diagnostics_message(ns_to_stamp(now_ns), self.diagnostic_statuses())
        publisher = self._diagnostics_publisher
        try:
            publisher.publish(message)
        except RCLError as exc:
            if not is_shutdown_error(exc, self.context):
                raise
            return
        self._record(publisher.topic_name, message, now_ns)
