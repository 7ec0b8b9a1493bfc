"""Republish recorded JointState bytes with their recorded timing, for live subscribers."""

import time

from sensor_msgs.msg import JointState


def _wait_for_subscribers(publisher, timeout_s):
    """Return once ``publisher`` has a subscriber, or after ``timeout_s``."""
    deadline = time.monotonic() + timeout_s
    while publisher.get_subscription_count() == 0 and time.monotonic() < deadline:
        time.sleep(0.05)


def publish_recording(samples, topic, speed=1.0, discovery_timeout_s=10.0, progress=None):
    """
    Republish recorded JointState bytes with their recorded timing (log time deltas).

    Parameters
    ----------
    samples : dict
        'data' (CDR payloads) and 'log_ns' (log times [ns]), as read_crank_samples gives.
    topic : str
        Topic to publish on.
    speed : float
        Time scale (2 = twice as fast).
    discovery_timeout_s : float
        Longest wait for a subscriber before publishing [s].
    progress : callable, optional
        ``progress(n)`` after each message and ``progress(count, force=True)`` at the end.

    Returns
    -------
    int
        Messages published.

    """
    import rclpy
    from rclpy.executors import ExternalShutdownException

    published = 0
    try:
        with rclpy.init():
            node = rclpy.create_node('flexlink_replay')
            publisher = node.create_publisher(JointState, topic, 100)
            _wait_for_subscribers(publisher, discovery_timeout_s)
            log_ns = samples['log_ns']
            start_wall = time.monotonic()
            for n, payload in enumerate(samples['data']):
                delay = start_wall + (log_ns[n] - log_ns[0]) * 1e-9 / speed - time.monotonic()
                if delay > 0:
                    time.sleep(delay)
                if not rclpy.ok():
                    break
                publisher.publish(payload)
                published += 1
                if progress is not None:
                    progress(n)
            if progress is not None:
                progress(len(samples['data']), force=True)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    return published
