"""
Where model cache files live, and when one may be read (a rule after OpenSSH's StrictModes).

Paths stay inside the cache directory. A cache file is only as good as whoever could have
written it: another local user who can write the file, or replace it in its directory, can
make the node publish wrong deflections with a valid checksum. So a cache file is read only
when all of this holds (the rule, :func:`untrusted_reason`; docs/model-cache.md says the same):

1. the file is a regular file (not a symbolic link, FIFO or device), owned by the effective
   uid running the code, and not writable by group or others (mode & 0o022 == 0);
2. every directory from the file's up to the cache root (``model.cache_dir``, or the default
   ``~/.cache/flexlink_ros``) is a real directory owned by that uid or by root, and not
   writable by group or others, except a directory with the sticky bit set (mode 1777, as
   /tmp) that is owned by that uid: there others may add files but not replace or remove
   the user's (the file itself must still pass 1).

Anything else is refused with one line saying why; the caller builds the model in memory and
writes no file (an untrusted directory) or replaces the refused file (a trusted directory).
The directories this code creates are created 0700.

Every file name comes from :func:`cache_file`: a label cut to letters, digits and ``_ . -``
and the key's hex, checked to resolve inside the cache directory whatever the label says.
"""

import os
import pathlib
import re
import stat

from ...errors import CacheError

# Mode bits that let group or others write.
GROUP_OTHER_WRITE = stat.S_IWGRP | stat.S_IWOTH
# Characters a label keeps in a file name; anything else becomes '_'.
UNSAFE_LABEL_CHARS = re.compile(r'[^A-Za-z0-9_.-]')
MAX_LABEL_CHARS = 64
KEY_CHARS = 16      # hex characters of the key in a file name
PRIVATE_DIRECTORY_MODE = 0o700


def cache_file(directory, label, key, suffix='.npz'):
    """
    Return the path of a cache file in ``directory``; it cannot name a place outside it.

    Parameters
    ----------
    directory : str or Path
        The cache directory.
    label : str
        Readable part of the name (a mechanism's name): characters other than letters,
        digits and ``_ . -`` become ``_``, leading dots go, at most 64 characters are kept.
    key : str
        Hex key of the content (its first 16 characters end the name).
    suffix : str
        File name ending (``.npz``, ``-nonlinearity.npz``).

    Raises
    ------
    CacheError
        If the name would resolve outside ``directory`` (it cannot: checked all the same).

    """
    safe = UNSAFE_LABEL_CHARS.sub('_', str(label)).lstrip('.')[:MAX_LABEL_CHARS] or 'model'
    name = f'{safe}-{UNSAFE_LABEL_CHARS.sub("_", str(key))[:KEY_CHARS]}{suffix}'
    directory = pathlib.Path(directory)
    if (directory.resolve() / name).parent != directory.resolve():
        raise CacheError(f'cache file name {name!r} leaves {directory}')
    return directory / name


def make_private_directory(directory):
    """Create ``directory`` and its missing parents with mode 0700 (existing ones unchanged)."""
    directory = pathlib.Path(directory)
    missing = []
    while not os.path.lexists(directory) and directory != directory.parent:
        missing.append(directory)
        directory = directory.parent
    for path in reversed(missing):
        try:
            path.mkdir(mode=PRIVATE_DIRECTORY_MODE)
        except FileExistsError:
            pass


def _owner_text(info):
    return f'owned by uid {info.st_uid}, not {os.geteuid()}'


def file_problem(info, path):
    """Why an opened cache file's ``os.stat_result`` is not trusted ('' if it is): rule 1."""
    if not stat.S_ISREG(info.st_mode):
        return f'{path} is not a regular file'
    if info.st_uid != os.geteuid():
        return f'{path} is {_owner_text(info)}'
    if info.st_mode & GROUP_OTHER_WRITE:
        return f'{path} is writable by group or others (mode {stat.S_IMODE(info.st_mode):04o})'
    return ''


def directory_problem(path):
    """Why directory ``path`` is not trusted ('' if it is): rule 2 for one directory."""
    try:
        info = os.lstat(path)
    except OSError as exc:
        return f'{path}: {exc.strerror}'
    if not stat.S_ISDIR(info.st_mode):
        return f'{path} is not a directory'
    if info.st_uid not in (os.geteuid(), 0):
        return f'directory {path} is {_owner_text(info)}' + (' or root' if os.geteuid() else '')
    mode = stat.S_IMODE(info.st_mode)
    if mode & GROUP_OTHER_WRITE and not (mode & stat.S_ISVTX and info.st_uid == os.geteuid()):
        return (f'directory {path} is writable by group or others (mode {mode:04o}'
                + (', sticky but not owned by this user)' if mode & stat.S_ISVTX else ')'))
    return ''


def untrusted_reason(path, root):
    """
    Say why the directories of cache file ``path`` up to cache ``root`` are not trusted.

    The file's own test (rule 1) is made on the open file (:func:`file_problem`), so it
    cannot be swapped between the test and the read.

    Parameters
    ----------
    path : str or Path
        A cache file (from :func:`cache_file`; it need not exist).
    root : str or Path
        The cache directory given (its parents are not checked: they may be /tmp).

    Returns
    -------
    str
        '' if every directory passes rule 2, else the first reason found.

    """
    root = pathlib.Path(os.path.realpath(root))
    directory = pathlib.Path(os.path.realpath(pathlib.Path(path).parent))
    if directory != root and root not in directory.parents:
        return f'{path} is not inside the cache directory {root}'
    while True:
        problem = directory_problem(directory)
        if problem or directory == root:
            return problem
        directory = directory.parent


def open_trusted(path):
    """
    Open cache file ``path`` for reading (links not followed) if rule 1 trusts it.

    Returns
    -------
    file object (binary, to close)

    Raises
    ------
    CacheError
        If it cannot be opened or is not trusted.

    """
    try:
        handle = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK)
    except OSError as exc:
        raise CacheError(f'{path}: cannot open the cache ({exc.strerror})') from None
    stream = os.fdopen(handle, 'rb')
    problem = file_problem(os.fstat(stream.fileno()), path)
    if problem:
        stream.close()
        raise CacheError(f'cache file not trusted: {problem}')
    return stream
