"""
MCAP subcommands: ``mcap-info``, ``mcap-recover`` and ``mcap-record``.

- ``flexlink mcap-info FILE|BAG_DIR [--json]``: topics, types, counts, time range, whether the
  file is complete (has its summary).
- ``flexlink mcap-recover IN.mcap --out OUT.mcap [--json]``: read a truncated file (a recorder
  killed with SIGKILL, a full disk) record by record, keep every complete chunk and message,
  and write a proper file with summary and statistics.
- ``flexlink mcap-record BAG --topic NAME[:TYPE] ...``: record topics from the ROS graph as
  rosbag2 does (raw CDR, offered QoS, receive and send times), for machines without rosbag2.
"""

import io
import math
import os
import pathlib
import struct
import time

from mcap.data_stream import ReadDataStream
from mcap.exceptions import McapError
from mcap.opcode import Opcode
from mcap.reader import make_reader
from mcap.records import Channel, Chunk, Header, Message, Schema
from mcap.stream_reader import MAGIC_SIZE, breakup_chunk
from mcap.writer import LIBRARY_IDENTIFIER, Writer

from .cli import emit
from .core.errors import RecorderError

MCAP_MAGIC = b'\x89MCAP0\r\n'
RECORD_PREFIX_SIZE = 9  # opcode (1) + length (8)
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
    Describe an MCAP file, or every MCAP file of a bag directory.

    Parameters
    ----------
    path : str or os.PathLike

    Returns
    -------
    dict
        For a file: ``path``, ``profile``, ``library``, ``complete`` (summary present),
        ``message_count``, ``start_ns``, ``end_ns``, ``duration_s``, ``chunk_count``,
        ``topics`` (list of dicts: ``topic``, ``type``, ``encoding``, ``count``). For a
        directory: ``files`` (those dicts) and the totals.

    """
    path = pathlib.Path(path)
    if path.is_dir():
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
        return {'path': str(path), 'files': files,
                'complete': all(f['complete'] for f in files),
                'message_count': sum(f['message_count'] for f in files),
                'start_ns': min(starts) if starts else None,
                'end_ns': max(ends) if ends else None,
                'duration_s': (max(ends) - min(starts)) / 1e9 if starts else 0.0,
                'topics': sorted(topics.values(), key=lambda t: t['topic'])}
    summary = None
    with open(path, 'rb') as stream:
        if stream.read(MAGIC_SIZE) != MCAP_MAGIC:
            raise ValueError(f'{path} is not an MCAP file (bad magic)')
        stream.seek(0)
        try:
            reader = make_reader(stream)
            header = reader.get_header()
            summary = reader.get_summary()
        except (McapError, struct.error, ValueError, OSError):
            header = None
    if summary is not None and summary.statistics is not None:
        stats = summary.statistics
        schemas = summary.schemas
        topics = [{'topic': channel.topic,
                   'type': schemas[channel.schema_id].name if channel.schema_id in schemas else '',
                   'encoding': channel.message_encoding,
                   'count': stats.channel_message_counts.get(channel.id, 0)}
                  for channel in summary.channels.values()]
        count, start, end = stats.message_count, stats.message_start_time, stats.message_end_time
        chunks, complete = stats.chunk_count, True
    else:
        scan = scan_mcap(path)
        header = scan['header']
        topics, count = scan['topics'], scan['message_count']
        start, end, chunks, complete = scan['start_ns'], scan['end_ns'], scan['chunk_count'], False
    return {'path': str(path), 'profile': header.profile if header else None,
            'library': header.library if header else None, 'complete': complete,
            'message_count': count, 'start_ns': start if count else None,
            'end_ns': end if count else None,
            'duration_s': (end - start) / 1e9 if count else 0.0, 'chunk_count': chunks,
            'topics': sorted(topics, key=lambda t: t['topic'])}


def _info_text(info):
    lines = [f"{info['path']}: {info['message_count']} messages over "
             f"{info['duration_s']:.3f} s" + ('' if info['complete'] else
                                             '  (INCOMPLETE: no summary; run mcap-recover)')]
    for topic in info['topics']:
        lines.append(f"  {topic['topic']:<32} {topic['type']:<40} {topic['count']:>9}")
    return '\n'.join(lines)


def _info_command(args):
    info = mcap_info(args.path)
    return emit(info, _info_text(info), args.json)


# -- mcap-recover ---------------------------------------------------------------------------

def iter_complete_records(stream, size):
    """
    Yield the schemas, channels and messages of an MCAP stream up to its first damaged record.

    Parameters
    ----------
    stream : binary file object positioned at the start
    size : int
        Total byte count of the stream.

    Yields
    ------
    Header, Schema, Channel or Message, or the tuple ``('end', reason, offset)`` last.

    """
    if stream.read(MAGIC_SIZE) != MCAP_MAGIC:
        yield ('end', 'not an MCAP file (bad magic)', 0)
        return
    offset = MAGIC_SIZE
    while True:
        prefix = stream.read(RECORD_PREFIX_SIZE)
        if len(prefix) < RECORD_PREFIX_SIZE:
            yield ('end', 'truncated' if prefix else 'end of file without footer', offset)
            return
        opcode, length = struct.unpack('<BQ', prefix)
        if offset + RECORD_PREFIX_SIZE + length > size:
            yield ('end', f'truncated inside a {_opcode_name(opcode)} record', offset)
            return
        record_stream = ReadDataStream(io.BytesIO(stream.read(length)))
        try:
            if opcode == Opcode.HEADER:
                yield Header.read(record_stream)
            elif opcode == Opcode.SCHEMA:
                yield Schema.read(record_stream)
            elif opcode == Opcode.CHANNEL:
                yield Channel.read(record_stream)
            elif opcode == Opcode.MESSAGE:
                yield Message.read(record_stream, length)
            elif opcode == Opcode.CHUNK:
                yield from breakup_chunk(Chunk.read(record_stream), validate_crc=True)
            elif opcode in (Opcode.DATA_END, Opcode.FOOTER):
                yield ('end', 'complete', offset)
                return
        except Exception as exc:  # noqa: B902 - any decoding failure ends the readable part
            yield ('end', f'damaged {_opcode_name(opcode)} record ({exc})', offset)
            return
        offset += RECORD_PREFIX_SIZE + length


def _opcode_name(opcode):
    try:
        return Opcode(opcode).name
    except ValueError:
        return f'opcode {opcode:#x}'


def scan_mcap(path):
    """
    Count what a (possibly truncated) MCAP file holds by streaming it.

    Parameters
    ----------
    path : str or os.PathLike

    Returns
    -------
    dict
        ``header``, ``topics``, ``message_count``, ``start_ns``, ``end_ns``, ``chunk_count``
        (always 0: chunks are not counted when streaming), ``end_reason``, ``readable_bytes``.

    """
    return _stream_copy(path, None)


def recover_mcap(source, destination):
    """
    Rewrite every complete message of a (truncated) MCAP file into a complete MCAP file.

    Parameters
    ----------
    source, destination : str or os.PathLike

    Returns
    -------
    dict
        ``message_count``, ``topics`` (list: topic, type, encoding, count), ``start_ns``,
        ``end_ns``, ``end_reason`` (why reading stopped), ``readable_bytes`` and
        ``source_bytes``.

    """
    if pathlib.Path(source).resolve() == pathlib.Path(destination).resolve():
        raise ValueError('`--out` must differ from the input file')
    with open(destination, 'wb') as out:
        writer = Writer(out)
        result = _stream_copy(source, writer)
        writer.finish()
    result['output'] = str(destination)
    return result


def _stream_copy(source, writer):
    size = os.path.getsize(source)
    schemas, channels, schema_map, channel_map, counts = {}, {}, {}, {}, {}
    header, count, start, end = None, 0, None, None
    reason, readable = 'empty', 0
    with open(source, 'rb') as stream:
        for record in iter_complete_records(stream, size):
            if isinstance(record, tuple):
                _, reason, readable = record
            elif isinstance(record, Header):
                header = record
                if writer is not None:
                    writer.start(profile=header.profile, library=RECOVER_LIBRARY)
            elif isinstance(record, Schema):
                schemas[record.id] = record
            elif isinstance(record, Channel):
                channels[record.id] = record
            elif isinstance(record, Message):
                channel = channels.get(record.channel_id)
                if channel is None:
                    continue
                if writer is not None:
                    if channel.id not in channel_map:
                        schema = schemas.get(channel.schema_id)
                        new_schema = 0
                        if schema is not None:
                            if schema.id not in schema_map:
                                schema_map[schema.id] = writer.register_schema(
                                    schema.name, schema.encoding, schema.data)
                            new_schema = schema_map[schema.id]
                        channel_map[channel.id] = writer.register_channel(
                            channel.topic, channel.message_encoding, new_schema,
                            dict(channel.metadata))
                    writer.add_message(channel_map[channel.id], record.log_time, record.data,
                                       record.publish_time, record.sequence)
                counts[channel.id] = counts.get(channel.id, 0) + 1
                count += 1
                start = record.log_time if start is None else min(start, record.log_time)
                end = record.log_time if end is None else max(end, record.log_time)
    if header is None and writer is not None:
        raise RecorderError(f'{source}: no MCAP header could be read ({reason})')
    topics = []
    for channel_id, channel in channels.items():
        schema = schemas.get(channel.schema_id)
        topics.append({'topic': channel.topic, 'type': schema.name if schema else '',
                       'encoding': channel.message_encoding,
                       'count': counts.get(channel_id, 0)})
    return {'header': header, 'topics': topics, 'message_count': count, 'start_ns': start,
            'end_ns': end, 'chunk_count': 0, 'end_reason': reason, 'readable_bytes': readable,
            'source_bytes': size}


def _recover_command(args):
    result = recover_mcap(args.input, args.out)
    result.pop('header', None)
    result.pop('chunk_count', None)
    span = (result['end_ns'] - result['start_ns']) / 1e9 if result['message_count'] else 0.0
    lines = [f"recovered {result['message_count']} messages ({span:.3f} s) from "
             f"{args.input} into {args.out}; input ended: {result['end_reason']} "
             f"after {result['readable_bytes']} of {result['source_bytes']} bytes"]
    lines += [f"  {t['topic']:<32} {t['type']:<40} {t['count']:>9}" for t in result['topics']]
    return emit(result, '\n'.join(lines), args.json)


# -- mcap-record ----------------------------------------------------------------------------

def _record_command(args):
    from .recorder import McapRecorder
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

    from .crank_driver import spin_until_shutdown
    from .rosbag_schema import message_class

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
