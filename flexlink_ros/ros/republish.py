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

Playback starts once the JointState publisher has matched the number of subscriptions asked
for (or after a timeout, with a note), so a node that matches after another subscriber does
not miss the first messages. A publish the middleware refuses (a reliable subscriber that
cannot keep up) is counted, its reason kept, and playback goes on. Log times that go back
are replaced as :func:`.playback_schedule.playback_times` says, with a note.
"""

import contextlib
import itertools
import signal
import threading
import time

from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState

from .playback_schedule import CLOCK, pass_events, playback_times
from .runtime import is_shutdown_error


DISCOVERY_TIMEOUT_S = 10.0
HISTORY_DEPTH = 1000     # the node's qos.depth default
CLOCK_DISCOVERY_S = 1.0  # after the JointState subscriber: /clock may have none (no sim time)
ACK_TIMEOUT_S = 5.0      # a reliable subscriber gets the last messages before the process ends
SIGNAL_CHECK_S = 0.1     # longest sleep between two looks at the context (SIGINT shuts it down)


@contextlib.contextmanager
def _signals_end_between_messages():
    """
    Yield ``running()``: False once SIGINT or SIGTERM came or the ROS context was shut down.

    Python's own SIGINT handler raises KeyboardInterrupt wherever the main thread is, for
    example between a publish and its count, so the summary could miss a message that went
    out. The handlers installed here only record the signal (rclpy, initialised after them,
    still shuts its context down and then calls them); the playback loop looks between two
    messages. Off the main thread signals cannot be handled, and rclpy's shutdown alone ends it.
    """
    import rclpy

    received = []
    if threading.current_thread() is not threading.main_thread():
        yield lambda: rclpy.ok()
        return
    previous = {number: signal.signal(number, lambda number, frame: received.append(number))
                for number in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield lambda: not received and rclpy.ok()
    finally:
        for number, handler in previous.items():
            signal.signal(number, handler)


def _wait_for_subscribers(running, publisher, count, timeout_s):
    """Wait until ``publisher`` matched ``count`` subscriptions, ``timeout_s`` or a signal."""
    deadline = time.monotonic() + timeout_s
    while (running() and time.monotonic() < deadline
           and publisher.get_subscription_count() < count):
        time.sleep(0.05)
    return publisher.get_subscription_count()


def _publish(publisher, message, counts):
    """Publish: 'sent', 'failed' (counted, its reason kept) or 'shutdown' (SIGINT/SIGTERM)."""
    # rclpy is imported when playing, not with this module: the offline replay imports it.
    from rclpy.subscription import RCLError
    try:
        publisher.publish(message)
    except RCLError as exc:
        if is_shutdown_error(exc):
            return 'shutdown'
        counts['failed'] += 1
        counts['last_failure'] = (str(exc).strip().splitlines() or [''])[0][:200]
        return 'failed'
    return 'sent'


def _sleep_until(running, wall):
    """Sleep until monotonic time ``wall`` in short steps, so that a signal ends it soon."""
    while running():
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


def _play_pass(running, publishers, samples, options, counts, progress):
    """Publish one pass; return False when interrupted (the context was shut down)."""
    joint_states, clock = publishers
    data = samples['data']
    start_wall = time.monotonic()
    for wall_s, kind, value in pass_events(samples['play_ns'], options['rate'],
                                           options['clock_hz'], options['clock_per_message']):
        _sleep_until(running, start_wall + wall_s)
        if not running():
            return False
        outcome = _publish(*((clock, _clock_message(value)) if kind == CLOCK
                             else (joint_states, data[value])), counts)
        if outcome == 'shutdown':
            return False
        if kind == CLOCK:
            counts['clock_messages'] += outcome == 'sent'
            continue
        counts['published'] += outcome == 'sent'
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


def _wait_for_matches(running, publishers, options, counts):
    """Wait for the subscriptions asked for (a note if too few came); /clock's briefly."""
    wanted = options.get('subscribers', 1)
    timeout_s = options.get('discovery_timeout_s', DISCOVERY_TIMEOUT_S)
    counts['matched'] = _wait_for_subscribers(running, publishers[0], wanted, timeout_s)
    if counts['matched'] < wanted and running():
        counts['notes'].append(f"{counts['matched']} of {wanted} subscriptions matched "
                               f"{counts['topic']} within {timeout_s:g} s: played anyway")
    if publishers[1] is not None:    # /clock listeners, if any, are found by now
        _wait_for_subscribers(running, publishers[1], 1, CLOCK_DISCOVERY_S)


def publish_recording(samples, topic, options, progress=None):
    """
    Republish recorded JointState bytes with their recorded timing (log time deltas).

    Parameters
    ----------
    samples : dict
        'data' (CDR payloads), 'log_ns' (log times [ns]) and optionally 'stamps_ns' (header
        stamps, used where the log times go back), as read_crank_samples gives.
    topic : str
        The recorded topic (published relative to the node's namespace).
    options : dict
        'rate' (playback speed factor, > 0), 'clock_hz' (fixed /clock frequency [Hz], 0:
        none, at most MAX_CLOCK_HZ), 'clock_per_message' (bool), 'passes' (0: until
        interrupted), 'ros_args' (list of str, the arguments after ``--ros-args``),
        optionally 'subscribers' (matched subscriptions to wait for, default 1) and
        'discovery_timeout_s' (how long to wait for them).
    progress : callable, optional
        ``progress(n)`` after each message and ``progress(n, force=True)`` at the end.

    Returns
    -------
    dict
        'published', 'failed' (publishes the middleware refused) and 'last_failure' (its
        reason), 'clock_messages', 'passes' (started), 'pass_position' (messages into the
        last pass), 'interrupted', 'topic' (the resolved, remapped name), 'node' (its fully
        qualified name), 'matched' (subscriptions when playback began), 'notes' (one line
        each: timing replaced, too few subscriptions), 'publish_s' (wall time).

    """
    import rclpy
    from rclpy.duration import Duration
    from rclpy.executors import ExternalShutdownException

    counts = {'published': 0, 'failed': 0, 'last_failure': '', 'clock_messages': 0,
              'passes': 0, 'pass_position': 0, 'interrupted': True, 'topic': None,
              'node': None, 'matched': 0, 'notes': [], 'publish_s': 0.0}
    play_ns, note = playback_times(samples['log_ns'], samples.get('stamps_ns'))
    samples = {**samples, 'play_ns': play_ns}
    counts['notes'] += [note] if note else []
    start = time.monotonic()
    try:
        with (_signals_end_between_messages() as running,
              rclpy.init(args=['--ros-args', *options.get('ros_args', ())])):
            node = rclpy.create_node('flexlink_replay')
            publishers = _create_publishers(node, topic, options)
            counts.update(topic=publishers[0].topic_name,
                          node=node.get_fully_qualified_name())
            _wait_for_matches(running, publishers, options, counts)
            start = time.monotonic()
            passes = options['passes']
            for _ in (itertools.count() if passes == 0 else range(passes)):
                counts['passes'] += 1
                if not _play_pass(running, publishers, samples, options, counts, progress):
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
