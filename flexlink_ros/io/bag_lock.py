"""
The lock that marks a bag directory as being recorded.

The recorder holds an advisory lock (``flock``, exclusive) on its bag directory from the moment
it creates it until ``metadata.yaml`` is written or the recording fails. ``flexlink reindex``
takes the same lock without waiting for the whole of its work, so it refuses a bag that is
still being written (rewriting a file under a live recorder would split the recording), and
two reindex runs never rewrite one bag at once. The lock goes with its process: a killed
recorder holds none, so its bag can be reindexed at once. Advisory locks bind only those that
take them; a directory on a file system without ``flock`` (some network mounts) is not locked.
"""

import fcntl
import os

from ..errors import BagInUse


def lock_bag(directory):
    """
    Take the bag's lock without waiting; return its descriptor (give it to :func:`unlock_bag`).

    Parameters
    ----------
    directory : os.PathLike
        The bag directory.

    Returns
    -------
    int or None
        The locked descriptor; None where the file system has no ``flock``.

    Raises
    ------
    BagInUse
        Another process (a recorder, or a reindex) holds the lock.

    """
    descriptor = os.open(directory, os.O_RDONLY | os.O_DIRECTORY | os.O_CLOEXEC)
    try:
        fcntl.flock(descriptor, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        os.close(descriptor)
        raise BagInUse(f'{directory} is being recorded (its recorder holds a lock on it): '
                       'reindex it once the recording has ended') from None
    except OSError:     # no flock here (ENOLCK, EINVAL on some network file systems)
        os.close(descriptor)
        return None
    return descriptor


def unlock_bag(descriptor):
    """
    Release a lock from :func:`lock_bag` (None: nothing to release).

    Parameters
    ----------
    descriptor : int or None
        What :func:`lock_bag` returned.

    """
    if descriptor is not None:
        os.close(descriptor)     # closing the only descriptor releases the flock
