"""
``flexlink mcap-record BAG --topic NAME[:TYPE] ...``: record ROS 2 topics as rosbag2 does.

Raw CDR, the QoS rosbag2 would request, receive and send times; for machines without rosbag2.
"""

import math
import time

from .main import emit
from ..errors import RecorderError
from ..io.msg_schema import message_class
from ..io.provenance import provenance_entries
from ..io.recorder import McapRecorder
from ..io.recorder_files import MIN_SPLIT_BYTES, MIN_SPLIT_DURATION_S, split_refusal
from ..ros.runtime import spin_until_shutdown


def register(subparsers):
    """
    Add the mcap-record subcommand.

    Parameters
    ----------
    subparsers : argparse._SubParsersAction
        The ``flexlink`` subcommands.

    """
    record = subparsers.add_parser(
        'mcap-record', help='record ROS 2 topics to a rosbag2-compatible MCAP bag')
    record.add_argument('out', help='bag directory to create, or a file ending in .mcap')
    record.add_argument('--topic', action='append', required=True, metavar='NAME[:TYPE]',
                        help='topic to record, type pkg/msg/Type (default: from the graph)')
    record.add_argument('--duration-s', type=float, default=0.0,
                        help='stop after this many seconds (0: until SIGINT/SIGTERM)')
    record.add_argument('--discovery-timeout-s', type=float, default=10.0,
                        help='how long to wait for publishers of topics given without type')
    record.add_argument('--split-size-mb', type=float, default=0.0,
                        help='split at this size [MB] (0: never; else at least 1 MiB)')
    record.add_argument('--split-duration-s', type=float, default=0.0,
                        help='split after this long [s] (0: never; else at least 1 s)')
    record.add_argument('--json', action='store_true', help='one JSON object on stdout')
    record.set_defaults(func=_record_command)


def _record_command(args):
    for reason in (split_refusal('--split-size-mb', args.split_size_mb, MIN_SPLIT_BYTES / 1e6,
                                 f'{MIN_SPLIT_BYTES / 1e6:g} (1 MiB)'),
                   split_refusal('--split-duration-s', args.split_duration_s,
                                 MIN_SPLIT_DURATION_S, f'{MIN_SPLIT_DURATION_S:g} s')):
        if reason is not None:
            raise ValueError(reason)
    recorder = McapRecorder(args.out, split_size_bytes=int(args.split_size_mb * 1e6),
                            split_duration_s=args.split_duration_s,
                            provenance=provenance_entries('flexlink mcap-record'))
    status = record_topics(recorder, [_parse_topic(t) for t in args.topic],
                           duration_s=args.duration_s,
                           discovery_timeout_s=args.discovery_timeout_s)
    text = (f"recorded {status['message_count']} messages to {status['path']} "
            f"({status['state']}, {len(status['files'])} file(s))")
    emit(status, text, args.json)
    return 0 if status['state'] == 'closed' else 1


def _parse_topic(text):
    name, _, type_name = text.partition(':')
    if not name:
        raise ValueError(f'`--topic`: expected NAME[:TYPE], got {text!r}')
    return ('' if name.startswith('/') else '/') + name, type_name or None


def record_topics(recorder, topics, duration_s=0.0, discovery_timeout_s=10.0, args=None):
    """
    Record topics from the ROS graph until the duration ends or the process is signalled.

    Raw (already serialised) messages are recorded with the receive time as ``log_time`` and
    the sender's source timestamp as ``publish_time``; the QoS requested follows rosbag2
    (reliable only if every publisher offers it) and the offered profiles are stored.

    Parameters
    ----------
    recorder : McapRecorder
        Not yet opened.
    topics : list of (str, str or None)
        Topic names with ``pkg/msg/Type`` or None (taken from the graph).
    duration_s : float
        Stop after this long (0: until SIGINT/SIGTERM).
    discovery_timeout_s : float
        How long to wait for the publishers of topics given without a type.
    args : list of str, optional
        ROS arguments for ``rclpy.init``.

    Returns
    -------
    dict
        The recorder's final status.

    """
    import rclpy
    from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor

    try:
        with rclpy.init(args=args):
            node = rclpy.create_node('flexlink_mcap_record')
            # rclpy's EventsExecutor cannot deliver MessageInfo (the send time) to a callback.
            executor = SingleThreadedExecutor()
            executor.add_node(node)
            resolved = _resolve_types(node, executor, topics, discovery_timeout_s)
            recorder.open()
            _subscribe(node, recorder, resolved)
            end = time.monotonic() + duration_s if duration_s > 0 else math.inf
            spin_until_shutdown(executor, lambda: time.monotonic() >= end)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        try:
            recorder.close()
        except RecorderError:
            pass
    return recorder.status()


def _subscribe(node, recorder, resolved):
    """Add each topic to the recorder with its offered QoS and subscribe to it raw."""
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    clock = node.get_clock()
    for topic, type_name in resolved:
        offers = [info.qos_profile for info in node.get_publishers_info_by_topic(topic)]
        recorder.add_topic(topic, type_name, offers or None)
        # As rosbag2: reliable only if every publisher offers it.
        reliable = all(p.reliability == ReliabilityPolicy.RELIABLE for p in offers)
        qos = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE if reliable
                         else ReliabilityPolicy.BEST_EFFORT)
        node.create_subscription(message_class(type_name), topic,
                                 _raw_writer(recorder, topic, clock), qos, raw=True)


def _raw_writer(recorder, topic, clock):
    def write(data, info):
        try:
            recorder.write(topic, data, clock.now().nanoseconds,
                           info.get('source_timestamp') or None)
        except RecorderError as exc:
            print(f'flexlink mcap-record: {exc}', flush=True)
    return write


def _resolve_types(node, executor, topics, timeout_s):
    deadline = time.monotonic() + timeout_s
    resolved = []
    for topic, type_name in topics:
        while type_name is None:
            known = dict(node.get_topic_names_and_types())
            if topic in known and known[topic]:
                type_name = known[topic][0]
            elif time.monotonic() > deadline:
                raise ValueError(f'`--topic` {topic}: no publisher found within {timeout_s} s; '
                                 'give the type as NAME:pkg/msg/Type')
            else:
                executor.spin_once(timeout_sec=0.1)
        resolved.append((topic, type_name))
    return resolved
