"""
MCAP subcommands: ``mcap-info``, ``mcap-recover`` and ``mcap-record``.

- ``flexlink mcap-info FILE|BAG_DIR [--json]``: topics, types, counts, time range, and whether
  the file is complete, checked: every chunk is decompressed (bounded) and CRC-checked, and
  damaged chunks are listed with their offsets rather than trusting the summary.
- ``flexlink mcap-recover IN.mcap --out OUT.mcap [--json]``: read a truncated or damaged file
  (a recorder killed with SIGKILL, a full disk, a bad sector) record by record, keep every
  intact chunk and message, skipping damaged chunks, and write a proper file with summary
  and statistics. Bounds and salvage rules: :mod:`flexlink_ros.io.mcap_reader`.
- ``flexlink mcap-record BAG --topic NAME[:TYPE] ...``: record topics from the ROS graph as
  rosbag2 does (raw CDR, offered QoS, receive and send times), for machines without rosbag2.
"""

import math
import pathlib
import time

from mcap.writer import LIBRARY_IDENTIFIER, Writer

from .main import emit
from ..errors import RecorderError
from ..io.mcap_reader import MESSAGE_HEAD, MESSAGE_HEAD_SIZE, Salvage, iter_messages, map_file

RECOVER_LIBRARY = f'flexlink mcap-recover; {LIBRARY_IDENTIFIER}'


def register(subparsers):
    """Add the mcap-info, mcap-recover and mcap-record subcommands."""
    info = subparsers.add_parser('mcap-info', help='topics, counts and time range of MCAP files')
    info.add_argument('path', help='an .mcap file or a bag directory')
    info.add_argument('--json', action='store_true', help='one JSON object on stdout')
    info.set_defaults(func=_info_command)

    recover = subparsers.add_parser(
        'mcap-recover', help='salvage every complete message of a truncated MCAP file')
    recover.add_argument('input', help='truncated .mcap file')
    recover.add_argument('--out', required=True, help='recovered .mcap file to write')
    recover.add_argument('--json', action='store_true', help='one JSON object on stdout')
    recover.set_defaults(func=_recover_command)

    record = subparsers.add_parser(
        'mcap-record', help='record ROS 2 topics to a rosbag2-compatible MCAP bag')
    record.add_argument('out', help='bag directory to create, or a file ending in .mcap')
    record.add_argument('--topic', action='append', required=True, metavar='NAME[:TYPE]',
                        help='topic to record, type pkg/msg/Type (default: from the graph)')
    record.add_argument('--duration-s', type=float, default=0.0,
                        help='stop after this many seconds (0: until SIGINT/SIGTERM)')
    record.add_argument('--discovery-timeout-s', type=float, default=10.0,
                        help='how long to wait for publishers of topics given without type')
    record.add_argument('--split-size-mb', type=float, default=0.0)
    record.add_argument('--split-duration-s', type=float, default=0.0)
    record.add_argument('--json', action='store_true', help='one JSON object on stdout')
    record.set_defaults(func=_record_command)


# -- mcap-info ------------------------------------------------------------------------------

def mcap_info(path):
    """
    Describe an MCAP file, or every MCAP file of a bag directory, from what is readable.

    Every chunk is decompressed (bounded) and its CRC and records checked; the counts are
    those of the intact chunks, not the summary's.

    Parameters
    ----------
    path : str or os.PathLike

    Returns
    -------
    dict
        For a file: ``path``, ``profile``, ``library``, ``complete`` (summary present, every
        chunk intact, counts as the summary says), ``status`` (one line: ``complete``,
        ``damaged: N chunks (offsets ...)`` or ``incomplete: ...``), ``damaged`` (list of
        ``offset``, ``reason``), ``damaged_count``, ``message_count``, ``start_ns``,
        ``end_ns``, ``duration_s``, ``chunk_count`` (intact chunks), ``topics`` (list of
        dicts: ``topic``, ``type``, ``encoding``, ``count``). For a directory: ``files``
        (those dicts) and the totals.

    """
    path = pathlib.Path(path)
    if path.is_dir():
        return _directory_info(path)
    scan = _stream_copy(path, None)
    summary = scan['summary']
    count, start, end = scan['message_count'], scan['start_ns'], scan['end_ns']
    complete = (summary is not None and scan['end_reason'] == 'complete'
                and not scan['damaged_count']
                and summary.get('message_count', count) == count)
    header = scan['header']
    return {'path': str(path), 'profile': header[0] if header else None,
            'library': header[1] if header else None, 'complete': complete,
            'status': _status(scan, complete), 'damaged': scan['damaged'],
            'damaged_count': scan['damaged_count'],
            'summary_message_count': summary.get('message_count') if summary else None,
            'message_count': count, 'start_ns': start if count else None,
            'end_ns': end if count else None,
            'duration_s': (end - start) / 1e9 if count else 0.0,
            'chunk_count': scan['chunk_count'],
            'topics': sorted(scan['topics'], key=lambda t: t['topic'])}


def _status(scan, complete):
    if complete:
        return 'complete'
    if scan['damaged_count']:
        offsets = ', '.join(str(d['offset']) for d in scan['damaged'][:10])
        more = ', ...' if scan['damaged_count'] > 10 else ''
        return f"damaged: {scan['damaged_count']} chunks (offsets {offsets}{more})"
    summary = scan['summary']
    if summary is None:
        return f"incomplete: no summary ({scan['end_reason']})"
    if scan['end_reason'] != 'complete':
        return f"incomplete: {scan['end_reason']}"
    return (f"damaged: the summary counts {summary.get('message_count')} messages, "
            f"{scan['message_count']} are readable")


def _directory_info(path):
    files = [mcap_info(p) for p in sorted(path.glob('*.mcap'))]
    if not files:
        raise ValueError(f'`path`: no .mcap files in {path}')
    topics = {}
    for entry in files:
        for topic in entry['topics']:
            merged = topics.setdefault(topic['topic'], dict(topic, count=0))
            merged['count'] += topic['count']
    starts = [f['start_ns'] for f in files if f['message_count']]
    ends = [f['end_ns'] for f in files if f['message_count']]
    complete = all(f['complete'] for f in files)
    damaged = sum(f['damaged_count'] for f in files)
    return {'path': str(path), 'files': files, 'complete': complete,
            'status': 'complete' if complete else (
                f'damaged: {damaged} chunks' if damaged else 'incomplete'),
            'damaged_count': damaged,
            'message_count': sum(f['message_count'] for f in files),
            'start_ns': min(starts) if starts else None,
            'end_ns': max(ends) if ends else None,
            'duration_s': (max(ends) - min(starts)) / 1e9 if starts else 0.0,
            'topics': sorted(topics.values(), key=lambda t: t['topic'])}


def _info_text(info):
    word, _, detail = info['status'].partition(':')
    state = '' if info['complete'] else f"  ({word.upper()}:{detail}; run mcap-recover)"
    lines = [f"{info['path']}: {info['message_count']} messages over "
             f"{info['duration_s']:.3f} s{state}"]
    lines += _damage_lines(info.get('damaged', []), info.get('damaged_count', 0))
    for topic in info['topics']:
        lines.append(f"  {topic['topic']:<32} {topic['type']:<40} {topic['count']:>9}")
    return '\n'.join(lines)


def _damage_lines(damaged, count, shown=5):
    lines = [f"  skipped at offset {d['offset']}: {d['reason']}" for d in damaged[:shown]]
    if count > shown:
        lines.append(f'  ... and {count - shown} more damaged places')
    return lines


def _info_command(args):
    info = mcap_info(args.path)
    return emit(info, _info_text(info), args.json)


# -- mcap-recover ---------------------------------------------------------------------------

def scan_mcap(path):
    """
    Count what a (possibly truncated or damaged) MCAP file holds by reading every chunk.

    Parameters
    ----------
    path : str or os.PathLike

    Returns
    -------
    dict
        ``header`` ((profile, library) or None), ``topics``, ``message_count``, ``start_ns``,
        ``end_ns``, ``chunk_count`` (intact chunks), ``damaged`` (list of ``offset``,
        ``reason``), ``damaged_count``, ``unknown_channel_messages``, ``summary`` (message and
        chunk counts of an intact summary, or None), ``end_reason``, ``readable_bytes``,
        ``source_bytes``.

    """
    return _stream_copy(path, None)


def recover_mcap(source, destination):
    """
    Rewrite every intact message of a truncated or damaged MCAP file into a complete file.

    Damaged chunks are skipped (``damaged`` says where and why) and reading goes on after
    them; a file cut short ends at its last complete chunk.

    Parameters
    ----------
    source, destination : str or os.PathLike

    Returns
    -------
    dict
        As :func:`scan_mcap`, plus ``output``.

    """
    if pathlib.Path(source).resolve() == pathlib.Path(destination).resolve():
        raise ValueError('`--out` must differ from the input file')
    map_file(source).close()    # not an MCAP file: refused before the output is created
    with open(destination, 'wb') as out:
        copier = _Copier(Writer(out))
        result = _stream_copy(source, copier)
        copier.finish(result['header'])
    if result['header'] is None and not result['message_count']:
        pathlib.Path(destination).unlink()      # nothing to keep: no empty output either
        raise RecorderError(f"{source}: nothing readable ({result['end_reason']})")
    result['output'] = str(destination)
    return result


class _Copier:
    """Writes salvaged messages with their schemas and channels into a new MCAP writer."""

    def __init__(self, writer):
        self.writer = writer
        self.started = False
        self.schema_ids, self.channel_ids = {}, {}

    def start(self, header):
        if not self.started:
            self.writer.start(profile=header[0] if header else '', library=RECOVER_LIBRARY)
            self.started = True

    def add(self, salvage, channel, sequence, log_time, publish_time, data):
        self.start((salvage.profile, salvage.library) if salvage.profile is not None else None)
        key = (channel.id, channel.topic, channel.schema_id)
        if key not in self.channel_ids:
            schema = salvage.schemas.get(channel.schema_id)
            new_schema = 0
            if schema is not None:
                schema_key = (schema.id, schema.name)
                if schema_key not in self.schema_ids:
                    self.schema_ids[schema_key] = self.writer.register_schema(
                        schema.name, schema.encoding, schema.data)
                new_schema = self.schema_ids[schema_key]
            self.channel_ids[key] = self.writer.register_channel(
                channel.topic, channel.message_encoding, new_schema, dict(channel.metadata))
        self.writer.add_message(self.channel_ids[key], log_time, data, publish_time, sequence)

    def finish(self, header):
        self.start(header)
        self.writer.finish()


def _stream_copy(source, copier):
    salvage = Salvage()
    counts, count, start, end, unknown = {}, 0, None, None, 0
    buffer = map_file(source)
    try:
        for records, body, stop in iter_messages(buffer, salvage):
            channel_id, sequence, log_time, publish_time = MESSAGE_HEAD.unpack_from(
                records, body)
            channel = salvage.channels.get(channel_id)
            if channel is None:
                unknown += 1
                continue
            if copier is not None:
                copier.add(salvage, channel, sequence, log_time, publish_time,
                           bytes(records[body + MESSAGE_HEAD_SIZE:stop]))
            counts[channel_id] = counts.get(channel_id, 0) + 1
            count += 1
            start = log_time if start is None or log_time < start else start
            end = log_time if end is None or log_time > end else end
    finally:
        buffer.close()
    topics = []
    for channel_id, number in counts.items():
        channel = salvage.channels[channel_id]
        schema = salvage.schemas.get(channel.schema_id)
        topics.append({'topic': channel.topic, 'type': schema.name if schema else '',
                       'encoding': channel.message_encoding, 'count': number})
    return {'header': (salvage.profile, salvage.library) if salvage.profile is not None
            else None, 'topics': topics, 'message_count': count, 'start_ns': start,
            'end_ns': end, 'chunk_count': salvage.chunk_count,
            'damaged': [{'offset': o, 'reason': r} for o, r in salvage.damaged],
            'damaged_count': salvage.damaged_count, 'unknown_channel_messages': unknown,
            'summary': salvage.summary, 'end_reason': salvage.end_reason,
            'readable_bytes': salvage.readable_bytes, 'source_bytes': salvage.size}


def _recover_command(args):
    result = recover_mcap(args.input, args.out)
    for key in ('header', 'chunk_count', 'summary'):
        result.pop(key, None)
    span = (result['end_ns'] - result['start_ns']) / 1e9 if result['message_count'] else 0.0
    lines = [f"recovered {result['message_count']} messages ({span:.3f} s) from "
             f"{args.input} into {args.out}; input ended: {result['end_reason']} "
             f"after {result['readable_bytes']} of {result['source_bytes']} bytes"]
    if result['damaged_count']:
        lines.append(f"  skipped {result['damaged_count']} damaged chunks")
    lines += _damage_lines(result['damaged'], result['damaged_count'])
    if result['unknown_channel_messages']:
        lines.append(f"  dropped {result['unknown_channel_messages']} messages of channels "
                     'whose definition was lost')
    lines += [f"  {t['topic']:<32} {t['type']:<40} {t['count']:>9}" for t in result['topics']]
    return emit(result, '\n'.join(lines), args.json)


# -- mcap-record ----------------------------------------------------------------------------

def _record_command(args):
    from ..io.recorder import McapRecorder
    recorder = McapRecorder(args.out, split_size_bytes=int(args.split_size_mb * 1e6),
                            split_duration_s=args.split_duration_s)
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
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    from ..ros.crank_driver import spin_until_shutdown
    from ..io.msg_schema import message_class

    try:
        with rclpy.init(args=args):
            node = rclpy.create_node('flexlink_mcap_record')
            # rclpy's EventsExecutor cannot deliver MessageInfo (the send time) to a callback.
            executor = SingleThreadedExecutor()
            executor.add_node(node)
            resolved = _resolve_types(node, executor, topics, discovery_timeout_s)
            recorder.open()
            clock = node.get_clock()
            for topic, type_name in resolved:
                offers = [info.qos_profile for info in node.get_publishers_info_by_topic(topic)]
                recorder.add_topic(topic, type_name, offers or None)
                reliable = all(p.reliability == ReliabilityPolicy.RELIABLE for p in offers)
                qos = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE if reliable
                                 else ReliabilityPolicy.BEST_EFFORT)
                node.create_subscription(message_class(type_name), topic,
                                         _raw_writer(recorder, topic, clock), qos, raw=True)
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
