"""
Republish recorded JointState bytes with their recorded timing, for live subscribers.

What `ros2 bag play` does for one topic: messages at their recorded log-time spacing scaled by
a rate, optionally ``/clock`` from the recording's time (:mod:`ros.playback_schedule`), passes
repeated for a loop, and the node's ROS arguments (``--ros-args -r from:=to``, ``-r
__ns:=/robot1``) handed to rclpy. The recorded topic name is published relative to the node's
namespace (``/joint_states`` becomes ``joint_states``: the same topic unless the namespace is
remapped, then ``/robot1/joint_states``); ``/clock`` stays absolute, as every ROS time source
expects it. SIGINT or SIGTERM end the playback between two messages; what was published is
still returned.
"""

import itertools
import time

from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState

from .playback_schedule import CLOCK, pass_events


DISCOVERY_TIMEOUT_S = 10.0
HISTORY_DEPTH = 1000     # the node's qos.depth default
CLOCK_DISCOVERY_S = 1.0  # after the JointState subscriber: /clock may have none (no sim time)
ACK_TIMEOUT_S = 5.0      # a reliable subscriber gets the last messages before the process ends
SIGNAL_CHECK_S = 0.1     # longest sleep between two looks at the context (SIGINT shuts it down)


def _wait_for_subscribers(rclpy, publishers, timeout_s):
    """Return once every publisher has a subscriber, after ``timeout_s``, or at a signal."""
    deadline = time.monotonic() + timeout_s
    while (rclpy.ok() and time.monotonic() < deadline
           and any(p.get_subscription_count() == 0 for p in publishers)):
        time.sleep(0.05)


def _sleep_until(rclpy, wall):
    """Sleep until monotonic time ``wall`` in short steps, so that a signal ends it soon."""
    while rclpy.ok():
        delay = wall - time.monotonic()
        if delay <= 0:
            return
        time.sleep(min(delay, SIGNAL_CHECK_S))


def relative_topic(topic):
    """Return the recorded topic name relative to the publishing node's namespace."""
    return topic.lstrip('/') or topic


def _clock_message(clock_ns):
    """Return a rosgraph_msgs/Clock carrying ``clock_ns``."""
    message = Clock()
    message.clock.sec, message.clock.nanosec = divmod(int(clock_ns), 1_000_000_000)
    return message


def _play_pass(rclpy, publishers, samples, options, counts, progress):
    """Publish one pass; return False when interrupted (the context was shut down)."""
    joint_states, clock = publishers
    data = samples['data']
    start_wall = time.monotonic()
    for wall_s, kind, value in pass_events(samples['log_ns'], options['rate'],
                                           options['clock_hz'], options['clock_per_message']):
        _sleep_until(rclpy, start_wall + wall_s)
        if not rclpy.ok():
            return False
        if kind == CLOCK:
            clock.publish(_clock_message(value))
            counts['clock_messages'] += 1
            continue
        joint_states.publish(data[value])
        counts['published'] += 1
        counts['pass_position'] = value + 1
        if progress is not None:
            progress(value)
    return True


def _create_publishers(node, topic, options):
    """Create the JointState publisher and, with a clock, the /clock one (ClockQoS)."""
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    # A reliable subscriber that falls behind by up to a second (1 kHz) loses nothing.
    joint_states = node.create_publisher(JointState, relative_topic(topic), HISTORY_DEPTH)
    clock = None
    if options['clock_hz'] > 0 or options['clock_per_message']:
        # rclcpp's ClockQoS: best effort, keep last 1, as rclpy's time source subscribes.
        clock_qos = QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT)
        clock = node.create_publisher(Clock, '/clock', clock_qos)
    return joint_states, clock


def publish_recording(samples, topic, options, progress=None):
    """
    Republish recorded JointState bytes with their recorded timing (log time deltas).

    Parameters
    ----------
    samples : dict
        'data' (CDR payloads) and 'log_ns' (log times [ns]), as read_crank_samples gives.
    topic : str
        The recorded topic (published relative to the node's namespace).
    options : dict
        'rate' (playback speed factor, > 0), 'clock_hz' (fixed /clock frequency [Hz], 0:
        none), 'clock_per_message' (bool), 'passes' (0: until interrupted), 'ros_args'
        (list of str, the arguments after ``--ros-args``), optionally
        'discovery_timeout_s'.
    progress : callable, optional
        ``progress(n)`` after each message and ``progress(n, force=True)`` at the end.

    Returns
    -------
    dict
        'published', 'clock_messages', 'passes' (started), 'pass_position' (messages into
        the last pass), 'interrupted', 'topic' (the
        resolved, remapped name), 'node' (its fully qualified name), 'publish_s' (wall time).

    """
    import rclpy
    from rclpy.duration import Duration
    from rclpy.executors import ExternalShutdownException

    counts = {'published': 0, 'clock_messages': 0, 'passes': 0, 'pass_position': 0,
              'interrupted': True,
              'topic': None, 'node': None, 'publish_s': 0.0}
    start = time.monotonic()
    try:
        with rclpy.init(args=['--ros-args', *options.get('ros_args', ())]):
            node = rclpy.create_node('flexlink_replay')
            publishers = _create_publishers(node, topic, options)
            counts.update(topic=publishers[0].topic_name,
                          node=node.get_fully_qualified_name())
            _wait_for_subscribers(rclpy, publishers[:1],
                                  options.get('discovery_timeout_s', DISCOVERY_TIMEOUT_S))
            if publishers[1] is not None:    # /clock listeners, if any, are found by now
                _wait_for_subscribers(rclpy, publishers[1:], CLOCK_DISCOVERY_S)
            start = time.monotonic()
            passes = options['passes']
            for _ in (itertools.count() if passes == 0 else range(passes)):
                counts['passes'] += 1
                if not _play_pass(rclpy, publishers, samples, options, counts, progress):
                    break
            else:
                counts['interrupted'] = False
                publishers[0].wait_for_all_acked(Duration(seconds=ACK_TIMEOUT_S))
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    counts['publish_s'] = time.monotonic() - start
    if progress is not None:
        progress(counts['pass_position'], force=True)
    return counts
