"""
The files of a bag directory that a reader may open: regular files inside the bag, in order.

Every reader of a bag directory (``mcap-info``, ``replay``, ``reindex``) lists its files here.
A ``*.mcap`` entry is taken only if it is a regular file, or a symbolic link that resolves to a
regular file inside the bag; anything else (a FIFO, which would block a reader for ever, a
device such as ``/dev/zero``, a directory, a link leading out of the bag) is skipped with a
warning naming it and why, never opened. :func:`.mcap_reader.map_file` opens without blocking
and checks again that it has a regular file, so an entry swapped after the listing is refused
too. Order: split order (``<name>_2.mcap`` before ``<name>_10.mcap``).
"""

import logging
import os
import pathlib
import re
import stat

LOGGER = logging.getLogger(__name__)
MAX_BAG_FILES = 100_000   # files of one bag directory read at most


def bag_files(bag, skipped=None, rosbag2_names=False):
    """
    Return the MCAP files of a bag directory that are safe to open, in split order.

    Parameters
    ----------
    bag : str or os.PathLike
        The bag directory.
    skipped : list, optional
        Receives ``(path, reason)`` of every ``*.mcap`` entry left out (each also logged as a
        warning).
    rosbag2_names : bool
        Take only the files as rosbag2 names them, ``<dir>_<N>.mcap`` (a directory that
        merely holds some MCAP file is then not taken for a bag); else every ``*.mcap``.

    Returns
    -------
    list of pathlib.Path
        The entry's path for a regular file, the resolved path for a link inside the bag;
        each file once.

    Raises
    ------
    ValueError
        More than ``MAX_BAG_FILES`` such files.

    """
    bag = pathlib.Path(bag)
    root = bag.resolve()
    pattern = re.compile(re.escape(root.name) + r'_(\d+)\.mcap' if rosbag2_names
                         else r'.*\.mcap')
    found = []
    for entry in os.scandir(bag):
        match = pattern.fullmatch(entry.name)
        if not match:
            continue
        path, reason = _regular_inside(bag / entry.name, root)
        if reason is not None:
            _skip(skipped, bag / entry.name, reason)
            continue
        stem = entry.name[:-len('.mcap')]
        found.append(((int(match.group(1)),) if rosbag2_names
                      else (len(stem.rsplit('_', 1)[-1]), stem), path, bag / entry.name))
        if len(found) > MAX_BAG_FILES:
            raise ValueError(f'{bag} holds more than {MAX_BAG_FILES} .mcap files')
    files, seen = [], set()
    for _, path, entry_path in sorted(found):
        real = path.resolve()
        if real in seen:
            _skip(skipped, entry_path, 'the same file as another entry of the bag')
            continue
        seen.add(real)
        files.append(path)
    return files


def _regular_inside(path, root):
    """(path to open, None), or (None, why not) for one directory entry (links resolved)."""
    try:
        info = os.lstat(path)
        if stat.S_ISLNK(info.st_mode):
            target = path.resolve()
            if not target.is_relative_to(root):
                return None, f'a link to {target}, outside the bag'
            info, path = os.stat(target), target
    except (OSError, RuntimeError) as exc:     # gone meanwhile, a dangling or looping link
        return None, f'cannot be read ({exc})'
    if stat.S_ISREG(info.st_mode):
        return path, None
    kind = ('a FIFO' if stat.S_ISFIFO(info.st_mode) else
            'a directory' if stat.S_ISDIR(info.st_mode) else
            'a device' if stat.S_ISCHR(info.st_mode) or stat.S_ISBLK(info.st_mode) else
            'a socket')
    return None, f'{kind}, not a regular file'


def _skip(skipped, path, reason):
    LOGGER.warning('%s skipped: %s', path, reason)
    if skipped is not None:
        skipped.append((path, reason))
