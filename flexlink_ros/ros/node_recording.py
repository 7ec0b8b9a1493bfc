"""
flexlink_node's recording: what it opens, what it records, with which QoS and log time.

:class:`NodeRecording` is the recording part of :class:`.estimator_node.EstimatorNode` (a
mixin of the node classes). The outputs are declared with their publishers' QoS when the
recording opens. The input topic is declared with the QoS its publishers offer, read from
the ROS graph as ``ros2 bag record`` does: at once if a publisher is known then, else at the
first input message (whose publisher the graph knows by then); the node's own subscription
QoS stands in only if the graph names none. Log times come from :class:`.sim_time.LogTime`:
the node clock, or the input stamp while a simulated clock reads 0.
"""

import time

from rclpy import logging as rclpy_logging
from sensor_msgs.msg import JointState

from .sim_time import cdr_stamp_ns
from ..errors import FlexlinkError, RecorderError
from ..io.provenance import provenance_entries
from ..io.recorder import McapRecorder
from ..names import NODE_NAME


def offered_qos_profiles(node, topic):
    """
    Return the QoS profiles the publishers of ``topic`` offer (from the ROS graph).

    Parameters
    ----------
    node : rclpy.node.Node
        Any node of the graph.
    topic : str
        Fully qualified topic name.

    Returns
    -------
    list of rclpy.qos.QoSProfile
        One per publisher (empty if none is known).

    """
    return [info.qos_profile for info in node.get_publishers_info_by_topic(topic)]


class NodeRecording:
    """Open, feed and close the node's MCAP recording (a mixin of the node classes)."""

    def _open_recorder(self, qos):
        values = self.values
        path = values['record.path'] or time.strftime('flexlink_%Y%m%d_%H%M%S')
        # The recorder never overwrites: a re-configure records next to the earlier takes.
        self._takes = getattr(self, '_takes', {})
        take = self._takes[path] = self._takes.get(path, 0) + 1
        if take > 1:
            stem, dot, suffix = path.rpartition('.') if path.endswith('.mcap') else (path, '', '')
            path = f'{stem}_{take}{dot}{suffix}'
        recorder = McapRecorder(path, split_size_bytes=values['record.max_bytes'],
                                split_duration_s=values['record.max_duration_s'],
                                provenance=self._provenance())
        # Topics first: if opening fails, writes to them are then dropped as failed,
        # not refused as undeclared.
        self._input_qos = qos
        self._input_declared = False
        self._declare_input(recorder, at_first_message=False)
        for publisher in self.publishers_.values():
            recorder.add_topic(publisher.topic_name, publisher.msg_type,
                               [publisher.qos_profile])
        try:
            recorder.open()
        except RecorderError as exc:
            self.get_logger().error(f'recording disabled: {exc}')
        return recorder

    def _provenance(self):
        """Say what makes the recording: mechanism file, model options, version."""
        values = self.values
        path, raw = self.mechanism_source       # the bytes the model was built from
        try:
            entries = provenance_entries(NODE_NAME, str(path.resolve()), self.options,
                                         self.model.zeta, values['crank_joint'],
                                         values['model.warm_start'], raw=raw)
            # What made the deflections: replay runs the same model on the recording.
            entries['nonlinear'] = 'off' if self.follower is None else 'on'
            return entries
        except (FlexlinkError, OSError) as exc:   # the recording goes on without it
            self.get_logger().warning(f'the recording will not name its mechanism: {exc}')
            return provenance_entries(NODE_NAME)

    def _recording_text(self):
        """Say in the ready line what the recording does (also that it was refused)."""
        recorder = self.recorder
        if recorder is None:
            return ''
        if recorder.state.value == 'recording':
            return f'; recording to {recorder.path}'
        return f'; not recording (cannot record to {recorder.path}: {recorder.error})'

    def _declare_input(self, recorder, at_first_message):
        """Declare the input topic with its publishers' offered QoS (see the module)."""
        profiles = offered_qos_profiles(self, self.input_topic)
        if not profiles and not at_first_message:
            return      # no publisher yet: declared at the first message
        recorder.add_topic(self.input_topic, JointState, profiles or [self._input_qos])
        self._input_declared = True

    def _record_input(self, data, clock_ns):
        """Record an input message (CDR) at its log time."""
        if not self._input_declared:
            try:
                self._declare_input(self.recorder, at_first_message=True)
            except RecorderError as exc:
                self.get_logger().error(f'recording stopped, estimation goes on: {exc}')
                return
        stamp_ns = cdr_stamp_ns(data) if clock_ns <= 0 else 0
        self._record(self.input_topic, data, self._log_time(clock_ns, stamp_ns))

    def _record(self, topic, message, log_time_ns):
        if self.recorder is None:
            return
        try:
            # Bytes come exact: the input's from rclpy, the outputs' from the node's
            # encoders; rclpy serialises only /diagnostics here, whose type has no float64[]
            # (rclpy can pad an empty one with stray bytes).
            self.recorder.enqueue(topic, message if isinstance(message, bytes)
                                  else self._serialize(message), log_time_ns)
        except RecorderError as exc:
            self.get_logger().error(f'recording stopped, estimation goes on: {exc}')

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
