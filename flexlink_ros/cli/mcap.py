"""
MCAP subcommands: ``mcap-info`` and ``mcap-recover`` (``mcap-record``: its own module).

- ``flexlink mcap-info FILE|BAG_DIR [--json]``: topics, types, counts, time range, and whether
  the file is complete, checked: every chunk is decompressed (bounded) and CRC-checked, and
  damaged chunks are listed with their offsets rather than trusting the summary; and what the
  recording says made it (producer, version, mechanism file, model options).
- ``flexlink mcap-recover IN.mcap [--out OUT.mcap] [--json]``: read a truncated or damaged file
  (a recorder killed with SIGKILL, a full disk, a bad sector) record by record, keep every
  intact chunk and message, skipping damaged chunks, and write a proper file with summary
  and statistics. Bounds and salvage rules: :mod:`flexlink_ros.io.mcap_reader`. Without
  ``--out`` it writes :func:`default_recovered_path` and refuses to overwrite it.
"""

import pathlib

from mcap.writer import LIBRARY_IDENTIFIER, Writer

from .main import emit
from ..errors import RecorderError
from ..io.bag_files import bag_files
from ..io.mcap_reader import iter_messages, map_file, Salvage
from ..io.mcap_records import MESSAGE_HEAD, MESSAGE_HEAD_SIZE
from ..io.provenance import PROVENANCE_RECORD, ProvenanceError, read_entries, read_provenance

RECOVER_LIBRARY = f'flexlink mcap-recover; {LIBRARY_IDENTIFIER}'


def register(subparsers):
    """
    Add the mcap-info and mcap-recover subcommands (mcap-record: :mod:`.mcap_record`).

    Parameters
    ----------
    subparsers : argparse._SubParsersAction
        The ``flexlink`` subcommands.

    """
    info = subparsers.add_parser('mcap-info', help='topics, counts and time range of MCAP files')
    info.add_argument('path', help='an .mcap file or a bag directory')
    info.add_argument('--json', action='store_true', help='one JSON object on stdout')
    info.set_defaults(func=_info_command)

    recover = subparsers.add_parser(
        'mcap-recover', help='salvage every complete message of a truncated MCAP file')
    recover.add_argument('input', help='truncated .mcap file')
    recover.add_argument('--out', help='recovered .mcap file to write (default: INPUT with '
                         'the suffix .recovered.mcap, beside the bag directory when INPUT is '
                         'one of its files; never overwritten)')
    recover.add_argument('--json', action='store_true', help='one JSON object on stdout')
    recover.set_defaults(func=_recover_command)


# -- mcap-info ------------------------------------------------------------------------------

def mcap_info(path):
    """
    Describe an MCAP file, or every MCAP file of a bag directory, from what is readable.

    Every chunk is decompressed (bounded) and its CRC and records checked; the counts are
    those of the intact chunks, not the summary's.

    Parameters
    ----------
    path : str or os.PathLike
        An .mcap file or a bag directory.

    Returns
    -------
    dict
        For a file: ``path``, ``profile``, ``library``, ``complete`` (summary present, every
        chunk intact, counts as the summary says), ``status`` (one line: ``complete``,
        ``damaged: N chunks (offsets ...)`` or ``incomplete: ...``), ``damaged`` (list of
        ``offset``, ``reason``), ``damaged_count``, ``message_count``, ``start_ns``,
        ``end_ns``, ``duration_s``, ``chunk_count`` (intact chunks), ``topics`` (list of
        dicts: ``topic``, ``type``, ``encoding``, ``count``). For a directory: ``files``
        (those dicts), the totals and ``skipped`` (entries that are not regular files inside
        it, :func:`..io.bag_files.bag_files`: ``path``, ``reason``).

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
    skipped = []
    files = [mcap_info(p) for p in bag_files(path, skipped)]
    if not files:
        raise ValueError(f'`path`: no .mcap files in {path}' + ''.join(
            f'; {entry} skipped: {reason}' for entry, reason in skipped[:3]))
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
            'skipped': [{'path': str(entry), 'reason': reason} for entry, reason in skipped],
            'topics': sorted(topics.values(), key=lambda t: t['topic'])}


def _info_text(info):
    word, _, detail = info['status'].partition(':')
    state = '' if info['complete'] else f'  ({word.upper()}:{detail}; run mcap-recover)'
    lines = [f"{info['path']}: {info['message_count']} messages over "
             f"{info['duration_s']:.3f} s{state}"]
    lines += _damage_lines(info.get('damaged', []), info.get('damaged_count', 0))
    lines += [f"  skipped {entry['path']}: {entry['reason']}" for entry in info.get('skipped', [])]
    for topic in info['topics']:
        lines.append(f"  {topic['topic']:<32} {topic['type']:<40} {topic['count']:>9}")
    return '\n'.join(lines)


def _damage_lines(damaged, count, shown=5):
    lines = [f"  skipped at offset {d['offset']}: {d['reason']}" for d in damaged[:shown]]
    if count > shown:
        lines.append(f'  ... and {count - shown} more damaged places')
    return lines


def made_with(path):
    """
    Say what a recording says made it (:mod:`io.provenance`): a dict and its lines of text.

    ``made_with`` is None for a recording that does not say (``ros2 bag record``, an older
    version), ``{'error': reason}`` for a record that cannot be used.
    """
    try:
        recorded = read_provenance(path)
    except ProvenanceError as exc:
        return {'error': str(exc)}, [f'  made with: unusable provenance record: {exc}']
    if recorded is None:
        return None, ['  made with: not recorded (no flexlink_ros record: replay needs '
                      '--mechanism)']
    lines = recorded.summary()
    result = {'producer': recorded.producer, 'version': recorded.version,
              'mechanism_file': recorded.mechanism_file or None,
              'mechanism_sha256': recorded.mechanism_sha256 or None,
              'damping_ratio': recorded.damping_ratio,
              'model_options': recorded.model_options}
    return result, [f'  made with: {lines[0][len("made by "):]}'] + [f'    {x}' for x in lines[1:]]


def _info_command(args):
    info = mcap_info(args.path)
    info['made_with'], lines = made_with(args.path)
    return emit(info, '\n'.join([_info_text(info)] + lines), args.json)


# -- mcap-recover ---------------------------------------------------------------------------

def scan_mcap(path):
    """
    Count what a (possibly truncated or damaged) MCAP file holds by reading every chunk.

    Parameters
    ----------
    path : str or os.PathLike
        The .mcap file.

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
    source : str or os.PathLike
        The damaged or truncated .mcap file.
    destination : str or os.PathLike
        The .mcap file to write (must differ from ``source``).

    Returns
    -------
    dict
        As :func:`scan_mcap`, plus ``output``.

    """
    if pathlib.Path(source).resolve() == pathlib.Path(destination).resolve():
        raise ValueError('`--out` must differ from the input file')
    map_file(source).close()    # not an MCAP file: refused before the output is created
    try:     # what made the recording goes into the copy too
        provenance = read_entries(source)
    except ProvenanceError:
        provenance = None
    with open(destination, 'wb') as out:
        copier = _Copier(Writer(out), provenance)
        result = _stream_copy(source, copier)
        copier.finish(result['header'])
    if result['header'] is None and not result['message_count']:
        pathlib.Path(destination).unlink()      # nothing to keep: no empty output either
        raise RecorderError(f"{source}: nothing readable ({result['end_reason']})")
    result['output'] = str(destination)
    return result


class _Copier:
    """Writes salvaged messages with their schemas and channels into a new MCAP writer."""

    def __init__(self, writer, provenance=None):
        self.writer = writer
        self.provenance = provenance
        self.started = False
        self.schema_ids, self.channel_ids = {}, {}

    def start(self, header):
        if not self.started:
            self.writer.start(profile=header[0] if header else '', library=RECOVER_LIBRARY)
            if self.provenance:
                self.writer.add_metadata(PROVENANCE_RECORD, self.provenance)
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


def default_recovered_path(source):
    """
    Where ``mcap-recover`` writes without ``--out``: ``NAME.recovered.mcap`` beside the input.

    A file of a rosbag2 bag directory (``BAG/BAG_0.mcap``) is recovered beside the directory
    (``BAG_0.recovered.mcap``), so the bag keeps only its own files (mcap-info, reindex and
    rosbag2 read every .mcap in it).

    Parameters
    ----------
    source : str or os.PathLike
        The damaged or truncated .mcap file.

    Returns
    -------
    pathlib.Path

    """
    source = pathlib.Path(source)
    stem = source.name[:-len('.mcap')] if source.name.endswith('.mcap') else source.name
    folder = source.parent
    if folder.name and stem.startswith(folder.name + '_'):
        folder = folder.parent
    return folder / f'{stem}.recovered.mcap'


def _recover_command(args):
    if args.out is None:
        args.out = str(default_recovered_path(args.input))
        if pathlib.Path(args.out).exists():
            raise ValueError(f'{args.out} exists (the default output is never overwritten); '
                             'remove it or choose another file with --out')
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
