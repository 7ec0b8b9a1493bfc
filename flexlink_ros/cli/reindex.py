"""
``flexlink reindex BAG``: rebuild the ``metadata.yaml`` of a bag directory whose recorder died.

A recorder killed (SIGKILL, power cut of the process) leaves its bag directory without
``metadata.yaml`` and its last file without summary and footer, so ``rosbags`` and
``ros2 bag`` refuse the folder. This reads every ``*.mcap`` file of the directory (bounded,
salvaging reader), rewrites a file cut short into a complete one holding all its intact
messages and the ``rosbag2`` metadata records (the original is kept beside it as
``<file>.truncated``), and writes ``metadata.yaml``
as the recorder's ``close`` would have (rosbag2 version 9). Like ``ros2 bag reindex`` it takes
what the files say: topics, types, offered QoS and type hashes from their channels.

It refuses a path that is not a directory of MCAP files, and never replaces an existing
``metadata.yaml`` (written by a recorder that closed the bag) unless ``--force`` is given.
Only files named as rosbag2 names them (``<dir>/<dir>_<N>.mcap``) are taken; any other file is
left out and untouched.
"""

import os
import pathlib

from .main import emit
from ..errors import FlexlinkError
from ..io.bag_index import bag_files, bag_topics, rewrite_complete, scan_bag_file
from ..io.bag_metadata import serialized_metadata, UNSET_NS, write_bag_metadata
from ..io.provenance import custom_data, ProvenanceError, read_entries


def register(subparsers):
    """
    Add the reindex subcommand.

    Parameters
    ----------
    subparsers : argparse._SubParsersAction
        The ``flexlink`` subcommands.

    """
    parser = subparsers.add_parser(
        'reindex', help='rebuild metadata.yaml of a bag directory whose recorder was killed')
    parser.add_argument('bag', help='the bag directory (holding <name>_0.mcap, ...)')
    parser.add_argument('--force', action='store_true',
                        help='replace an existing metadata.yaml')
    parser.add_argument('--json', action='store_true', help='one JSON object on stdout')
    parser.set_defaults(func=_reindex_command)


def reindex_bag(bag, force=False):
    """
    Rebuild ``metadata.yaml`` of a bag directory from its MCAP files.

    Parameters
    ----------
    bag : str or os.PathLike
        The bag directory.
    force : bool
        Replace an existing ``metadata.yaml``.

    Returns
    -------
    dict
        ``bag``, ``files`` (per file: ``path``, ``message_count``, ``end_reason``,
        ``salvaged_from``), ``skipped`` (files with nothing readable: ``path``, ``reason``),
        ``message_count``, ``topics`` (name -> count).

    Raises
    ------
    FlexlinkError
        Not a bag directory, or ``metadata.yaml`` exists and ``force`` is False.

    """
    bag = pathlib.Path(bag)
    if not bag.is_dir():
        raise FlexlinkError(f'{bag} is not a directory: reindex takes a bag directory')
    files = bag_files(bag)
    if not files:
        raise FlexlinkError(f'{bag} holds no {bag.resolve().name}_<N>.mcap file (as rosbag2 '
                            'names them): not a bag directory')
    metadata = bag / 'metadata.yaml'
    if os.path.lexists(metadata) and not force:
        raise FlexlinkError(f'{metadata} exists (the recording was closed, and rosbags and '
                            'ros2 bag open it as it is); --force rebuilds it from the files')
    scans, skipped = [], []
    for path in files:
        scan = scan_bag_file(path)
        if scan['header'] or scan['message_count']:
            scans.append(scan)
        else:   # nothing readable: left alone, not listed
            skipped.append({'path': str(path), 'reason': scan['end_reason']})
    if not scans:
        raise FlexlinkError(f'{bag}: no readable MCAP file')
    topics = bag_topics(scans)
    try:     # what made the bag, kept in custom_data
        provenance = read_entries(bag)
    except ProvenanceError:
        provenance = None
    for n, scan in enumerate(scans):
        if not scan['complete']:
            scan['salvaged_from'] = str(_salvage(scans, n, provenance))
    write_bag_metadata(bag, scans, topics, custom_data(provenance))
    return {'bag': str(bag), 'message_count': sum(s['message_count'] for s in scans),
            'files': [{'path': str(s['path']), 'message_count': s['message_count'],
                       'end_reason': s['end_reason'], 'salvaged_from': s.get('salvaged_from')}
                      for s in scans],
            'skipped': skipped,
            'topics': {t.name: t.message_count for t in topics.values()}}


def _salvage(scans, n, provenance):
    """Rewrite file ``n`` complete in place; keep the original as ``.truncated``."""
    path = scans[n]['path']
    kept = path.with_name(path.name + '.truncated')
    if os.path.lexists(kept):
        raise FlexlinkError(f'{kept} exists (an earlier salvage?): move it away first')
    # The rosbag2 records the recorder would have written: at open, the files before this
    # one and this one empty; at close, the bag up to this file.
    empty = {'path': path, 'message_count': 0, 'first_log_ns': None, 'last_log_ns': None}
    opening = serialized_metadata(scans[:n] + [empty], bag_topics(scans[:n]), UNSET_NS)
    closing = serialized_metadata(scans[:n + 1], bag_topics(scans[:n + 1]))
    temporary = path.with_name(f'.{path.name}.{os.getpid()}.salvage')
    try:
        rewrite_complete(path, temporary, opening, closing, provenance)   # never overwrites
    except FileExistsError:
        raise
    except BaseException:
        _remove(temporary)
        raise
    try:
        os.link(path, kept)     # fails rather than replace anything at `kept`
    except BaseException:
        _remove(temporary)
        raise
    os.replace(temporary, path)
    return kept


def _remove(path):
    try:
        os.unlink(path)
    except FileNotFoundError:
        pass


def _reindex_command(args):
    result = reindex_bag(args.bag, force=args.force)
    lines = [f"{result['bag']}/metadata.yaml: {len(result['files'])} files, "
             f"{result['message_count']} messages"]
    lines += [f'  {name}: {count}' for name, count in result['topics'].items()]
    for entry in result['files']:
        if entry['salvaged_from']:
            lines.append(f"  {entry['path']} was cut short ({entry['end_reason']}); rewritten "
                         f"with its {entry['message_count']} intact messages, original kept "
                         f"as {entry['salvaged_from']}")
    lines += [f"  skipped {entry['path']}: {entry['reason']}" for entry in result['skipped']]
    return emit(result, '\n'.join(lines), args.json)
