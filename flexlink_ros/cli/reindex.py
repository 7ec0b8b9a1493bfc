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
``metadata.yaml`` (written by a recorder that closed the bag) unless ``--force`` is given. It
refuses a bag still being recorded (its recorder holds the bag's lock, :mod:`..io.bag_lock`;
exit 2, ``--force`` or not). A last file without messages (a kill at a split) or a file that
is not MCAP at all is skipped with a note; a rewritten file keeps its original's mode; hidden
``.<file>.<pid>.salvage`` files of a reindex stopped mid-rewrite are removed.
Only files named as rosbag2 names them (``<dir>/<dir>_<N>.mcap``) are taken; any other file is
left out and untouched.
"""

import os
import pathlib
import re
import stat

from .main import emit
from ..errors import FlexlinkError, McapFileError
from ..io.bag_files import bag_files
from ..io.bag_index import bag_topics, rewrite_complete, scan_bag_file
from ..io.bag_lock import lock_bag, unlock_bag
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
    lock = lock_bag(bag)    # refuses a bag still being recorded, whatever `force` says
    try:
        return _reindex_locked(bag, force)
    finally:
        unlock_bag(lock)


def _reindex_locked(bag, force):
    """Reindex ``bag`` while holding its lock (see :func:`reindex_bag`)."""
    removed = remove_stale_salvage(bag)
    unsafe = []
    files = bag_files(bag, unsafe, rosbag2_names=True)
    if not files:
        raise FlexlinkError(f'{bag} holds no {bag.resolve().name}_<N>.mcap file (as rosbag2 '
                            'names them): not a bag directory')
    metadata = bag / 'metadata.yaml'
    if os.path.lexists(metadata) and not force:
        raise FlexlinkError(f'{metadata} exists (the recording was closed, and rosbags and '
                            'ros2 bag open it as it is); --force rebuilds it from the files')
    scans = []
    skipped = [{'path': str(path), 'reason': reason} for path, reason in unsafe]
    for n, path in enumerate(files):
        scan = _scan_or_none(path, skipped)
        if scan is None:
            continue
        # Without messages and cut short (a kill as the recorder started it, at a split):
        # nothing to keep; the last file is left alone, not listed, as is an unreadable one.
        last_and_empty = n == len(files) - 1 and not scan['complete']
        if scan['message_count'] or (scan['header'] and not last_and_empty):
            scans.append(scan)
        else:
            skipped.append({'path': str(path),
                            'reason': f"no message ({scan['end_reason']})"})
    if not scans:
        raise FlexlinkError(f'{bag}: no readable MCAP file (' + '; '.join(
            f"{entry['path']}: {entry['reason']}" for entry in skipped[:3]) + ')')
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
            'skipped': skipped, 'removed': removed,
            'topics': {t.name: t.message_count for t in topics.values()}}


def _scan_or_none(path, skipped):
    """Scan one file; None (noted in ``skipped``) if it is not an MCAP file at all."""
    try:
        return scan_bag_file(path)
    except McapFileError as exc:      # 0 bytes, or not even the magic
        skipped.append({'path': str(path), 'reason': f'no message ({exc})'})
        return None


def remove_stale_salvage(bag):
    """
    Remove the ``.<file>.<pid>.salvage`` files that a reindex killed mid-rewrite left behind.

    Only regular files named exactly so after one of the bag's files, whose process is gone.

    Parameters
    ----------
    bag : pathlib.Path
        The bag directory (its lock held).

    Returns
    -------
    list of str
        The removed files.

    """
    pattern = re.compile(r'\.(' + re.escape(bag.resolve().name) + r'_\d+\.mcap)\.(\d+)\.salvage')
    removed = []
    for entry in os.scandir(bag):
        match = pattern.fullmatch(entry.name)
        if (match and entry.is_file(follow_symlinks=False)
                and not _process_alive(int(match.group(2)))):
            _remove(entry.path)
            removed.append(entry.path)
    return removed


def _process_alive(pid):
    if pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:     # alive, another user's
        return True
    return True


def _salvage(scans, n, provenance):
    """Rewrite file ``n`` complete in place; keep the original as ``.truncated``."""
    path = scans[n]['path']
    kept = path.with_name(path.name + '.truncated')
    if os.path.lexists(kept):
        raise FlexlinkError(f'{kept} exists (an earlier salvage?): move it away first')
    # The rosbag2 records the recorder would have written: this file alone, at open empty,
    # at close with its messages.
    empty = {'path': path, 'message_count': 0, 'first_log_ns': None, 'last_log_ns': None}
    topics = bag_topics(scans[:n + 1])
    counts = {name: topic.message_count for name, topic in bag_topics([scans[n]]).items()}
    extra = custom_data(provenance)    # as the recorder writes them
    opening = serialized_metadata([empty], topics, UNSET_NS, counts={}, custom_data=extra)
    closing = serialized_metadata([scans[n]], topics, counts=counts, custom_data=extra)
    temporary = path.with_name(f'.{path.name}.{os.getpid()}.salvage')
    mode = stat.S_IMODE(os.stat(path).st_mode)     # a 0600 recording stays 0600
    try:
        rewrite_complete(path, temporary, opening, closing, mode,   # refuses an existing file
                         provenance)
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
    lines += [f"  skipped {entry['path']}: {entry['reason']}; left in place, not listed"
              for entry in result['skipped']]
    lines += [f'  removed {path}: left by a reindex that was stopped mid-rewrite'
              for path in result['removed']]
    return emit(result, '\n'.join(lines), args.json)
