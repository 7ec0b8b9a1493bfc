"""
Versioned, verified cache files for precomputed models (no pickle anywhere).

A cache file is a NumPy ``.npz`` archive of plain numeric arrays plus one ``uint8`` array,
``__header__``, holding a UTF-8 JSON header::

    {"format": "flexlink_ros.model_cache", "version": FORMAT_VERSION, "key": "<hex>",
     "arrays": {"name": {"dtype": "<f8", "shape": [..]}, ...},
     "sha256": "<hex of the arrays>", "meta": {...}}

Loading never unpickles (it reads the zip and the .npy headers itself) and rejects anything that
is not exactly what the header announces: another format or version, another key (stale: a
different mechanism or model options), missing or extra arrays, object or non-numeric dtypes,
other shapes, an array whose .npy header announces more (or fewer) bytes than its zip member
stores or more than :data:`MAX_CACHE_BYTES` in all (checked before anything is allocated),
compressed members, a checksum mismatch (corrupt bytes), or an unreadable archive (truncated,
not a zip, a pickle renamed ``.npz``). Each raises :class:`CacheError`; :func:`load_or_build`
then logs a warning and rebuilds. A file whose checksum was found right carries a record of
it (an extended attribute with the file's inode, size and modification time): while those are
unchanged, a load maps the file without reading every byte of it. Writes go to a temporary
file in the same directory and are moved into place with ``os.replace``, so a reader never
sees a half-written file.

Before any of that a file must be trusted (:mod:`.cache_location`: owned by the user, not
writable by others, in directories only the user can change): an untrusted file is never
read, and into an untrusted directory nothing is written (the model is built in memory).
"""

import hashlib
import io
import json
import logging
import mmap
import os
import pathlib
import tempfile
import time
import zipfile

import numpy as np

from .cache_location import make_private_directory, open_trusted, untrusted_reason
from ...errors import CacheError

LOGGER = logging.getLogger(__name__)

FORMAT_NAME = 'flexlink_ros.model_cache'
# Bump when the file layout changes; files of another version are rebuilt.
FORMAT_VERSION = 1
HEADER_NAME = '__header__'
# dtype kinds a cache may hold: bool, signed/unsigned integer, float, complex.
ALLOWED_KINDS = 'biufc'
# Refuse headers larger than this [bytes] (a foreign archive could announce anything).
MAX_HEADER_BYTES = 1 << 20
# Refuse caches whose arrays together exceed this [bytes]: the node's default model is about
# 30 MB; nothing a build can make in reasonable time comes near it.
MAX_CACHE_BYTES = 2 << 30
# Bytes of a member read to parse its .npy header (numpy refuses headers over 10 000 bytes).
NPY_HEADER_READ = 1 << 16
# Array data start at a multiple of this in the file, so a load maps them without a copy.
ARRAY_ALIGNMENT = 64
# The extended attribute recording a file's checksum as found right (its identity with it),
# so that the next load maps the file without reading all of it; and how long after the
# file's last write a check is recorded (longer than any file system's timestamp tick).
VERIFIED_ATTRIBUTE = 'user.flexlink_ros.verified'
VERIFIED_AGE_S = 2.0


def default_cache_dir():
    """``$XDG_CACHE_HOME/flexlink_ros`` or ``~/.cache/flexlink_ros``."""
    base = os.environ.get('XDG_CACHE_HOME') or os.path.join(os.path.expanduser('~'), '.cache')
    return pathlib.Path(base) / 'flexlink_ros'


def cache_key(*parts):
    """
    SHA-256 hex digest of the JSON form of ``parts`` (mechanism key, options, versions).

    Parameters
    ----------
    *parts : JSON-serialisable values
        Everything the cached content depends on.

    """
    payload = json.dumps(parts, sort_keys=True, default=repr, separators=(',', ':'))
    return hashlib.sha256(payload.encode()).hexdigest()


def _array_digest(arrays):
    """SHA-256 over names, dtypes, shapes and bytes of the arrays, in name order."""
    digest = hashlib.sha256()
    for name in sorted(arrays):
        array = np.ascontiguousarray(arrays[name])
        digest.update(name.encode())
        digest.update(array.dtype.str.encode())
        digest.update(repr(tuple(array.shape)).encode())
        digest.update(memoryview(array.reshape(-1)).cast('B'))   # the bytes, not a copy
    return digest.hexdigest()


def _check_array(name, array):
    if not isinstance(array, np.ndarray):
        raise CacheError(f'cache array {name!r} is a {type(array).__name__}, not an ndarray')
    if array.dtype.kind not in ALLOWED_KINDS or array.dtype.hasobject:
        raise CacheError(f'cache array {name!r} has dtype {array.dtype}, not a plain number')


def save_cache(path, key, arrays, meta=None):
    """
    Write arrays and metadata to ``path`` atomically.

    Parameters
    ----------
    path : str or Path
        Destination file (missing parent directories are created 0700).
    key : str
        Cache key the content belongs to (see :func:`cache_key`).
    arrays : dict of str to ndarray
        Numeric arrays (bool, int, float, complex); names must not start with ``__``.
    meta : dict or None
        JSON-serialisable metadata stored in the header.

    Raises
    ------
    CacheError
        If an array is not a plain numeric array or a name is reserved.

    """
    path = pathlib.Path(path)
    arrays = {name: np.ascontiguousarray(array) for name, array in arrays.items()}
    for name, array in arrays.items():
        if name.startswith('__'):
            raise CacheError(f'cache array name {name!r} is reserved')
        _check_array(name, array)
    header = {
        'format': FORMAT_NAME, 'version': FORMAT_VERSION, 'key': key,
        'arrays': {name: {'dtype': a.dtype.str, 'shape': list(a.shape)}
                   for name, a in sorted(arrays.items())},
        'sha256': _array_digest(arrays), 'meta': meta or {},
    }
    header_bytes = np.frombuffer(json.dumps(header, sort_keys=True).encode(), dtype=np.uint8)
    make_private_directory(path.parent)
    handle, temp_name = tempfile.mkstemp(prefix=path.name + '.', suffix='.tmp',
                                         dir=path.parent)
    try:
        with os.fdopen(handle, 'wb') as stream:
            _write_archive(stream, {HEADER_NAME: header_bytes, **arrays})
            stream.flush()
            os.fsync(stream.fileno())
        os.replace(temp_name, path)
    except BaseException:
        try:
            os.unlink(temp_name)
        except FileNotFoundError:
            pass
        raise


def _write_archive(stream, arrays):
    """
    Write a zip of ``<name>.npy`` members (as ``np.savez`` does) with each array's data aligned.

    Each member's local header gets an extra field of padding (id 0xD935, as Android's
    zipalign uses; zip readers skip unknown extra fields) so that its data, after the .npy
    header that numpy pads to 64 bytes, starts at a multiple of :data:`ARRAY_ALIGNMENT`.
    """
    with zipfile.ZipFile(stream, 'w', zipfile.ZIP_STORED) as archive:
        for name, array in arrays.items():
            npy = io.BytesIO()
            np.lib.format.write_array(npy, array, allow_pickle=False)
            info = zipfile.ZipInfo(name + '.npy', date_time=(1980, 1, 1, 0, 0, 0))
            info.compress_type = zipfile.ZIP_STORED
            before_data = stream.tell() + 30 + len(info.filename.encode()) + 4
            info.extra = _padding_field(-before_data % ARRAY_ALIGNMENT)
            archive.writestr(info, npy.getbuffer())


def _padding_field(size):
    """Return a zip extra field of ``size`` zero bytes after its 4-byte id and length."""
    return (0xD935).to_bytes(2, 'little') + size.to_bytes(2, 'little') + bytes(size)


def _read_npy_header(member, name, path):
    """Dtype, shape, Fortran order of one .npy member; the stream is left at the data."""
    version = np.lib.format.read_magic(member)
    if version == (1, 0):
        shape, fortran_order, dtype = np.lib.format.read_array_header_1_0(member)
    elif version == (2, 0):
        shape, fortran_order, dtype = np.lib.format.read_array_header_2_0(member)
    else:
        raise CacheError(f'{path}: array {name!r} has .npy version {version}')
    if dtype.kind not in ALLOWED_KINDS or dtype.hasobject:
        raise CacheError(f'{path}: cache array {name!r} has dtype {dtype}, not a plain number')
    return dtype, shape, fortran_order


def _member_data_offset(mapped, info, path):
    """
    Where the bytes of a stored zip member start in the file.

    The local file header (zip APPNOTE 4.3.7: 30 bytes, then the name and the extra field)
    precedes them; its lengths may differ from the central directory's, so they are read here.
    """
    local = mapped[info.header_offset:info.header_offset + 30]
    if len(local) != 30 or local[:4] != b'PK\x03\x04':
        raise CacheError(f'{path}: member {info.filename[:80]!r} has no local header')
    start = info.header_offset + 30 + int.from_bytes(local[26:28], 'little') \
        + int.from_bytes(local[28:30], 'little')
    if start + info.file_size > len(mapped):
        raise CacheError(f'{path}: member {info.filename[:80]!r} runs past the end of the file')
    return start


def _read_member(mapped, info, name, path, budget):
    """
    One array of the file mapped read-only in ``mapped``, after checking its announced size.

    The .npy header announces dtype and shape; their product must be exactly the bytes the
    zip member stores (uncompressed, as :func:`save_cache` writes) and fit the remaining
    ``budget``. The array is a read-only view of the mapped file where its bytes are aligned
    (as :func:`save_cache` places them): no copy, and no fresh memory to fault in, which in a
    new process costs more than reading the file. Otherwise (a file written by an older
    version) it is copied out.
    """
    if info.compress_type != zipfile.ZIP_STORED or info.compress_size != info.file_size:
        raise CacheError(f'{path}: array {name!r} is compressed (not written by this code)')
    start = _member_data_offset(mapped, info, path)
    npy = io.BytesIO(mapped[start:start + min(info.file_size, NPY_HEADER_READ)])
    dtype, shape, fortran_order = _read_npy_header(npy, name, path)
    count = 1
    for extent in shape:
        count *= extent
    announced = count * dtype.itemsize
    stored = info.file_size - npy.tell()
    if announced != stored:
        raise CacheError(f'{path}: array {name!r} announces {announced} bytes '
                         f'({dtype.str} {list(shape)}), the file holds {stored}')
    if announced > budget:
        raise CacheError(f'{path}: array {name!r} announces {announced} bytes, more than '
                         f'the file holds or {MAX_CACHE_BYTES} bytes in all')
    offset = start + npy.tell()
    flat = np.frombuffer(mapped, dtype=dtype, count=count, offset=offset)
    if offset % dtype.alignment:
        flat = flat.copy()
        flat.flags.writeable = False
    return flat.reshape(shape, order='F' if fortran_order else 'C'), announced


def _read_header(mapped, members, path):
    info = members.get(HEADER_NAME)
    if info is None:
        raise CacheError(f'{path}: not a flexlink_ros cache (no header)')
    if info.file_size > MAX_HEADER_BYTES + 1024:
        raise CacheError(f'{path}: malformed header (larger than {MAX_HEADER_BYTES} bytes)')
    raw, _ = _read_member(mapped, info, HEADER_NAME, path, min(MAX_HEADER_BYTES, len(mapped)))
    if raw.dtype != np.uint8 or raw.ndim != 1:
        raise CacheError(f'{path}: malformed header')
    header = json.loads(raw.tobytes().decode())
    if not isinstance(header, dict):
        raise CacheError(f'{path}: malformed header')
    return header


def _check_header(header, key, path):
    if header.get('format') != FORMAT_NAME:
        raise CacheError(f'{path}: not a flexlink_ros cache (format {header.get("format")!r})')
    if header.get('version') != FORMAT_VERSION:
        raise CacheError(f'{path}: cache format version {header.get("version")!r}, '
                         f'this code reads {FORMAT_VERSION}')
    if header.get('key') != key:
        raise CacheError(f'{path}: stale cache (key {str(header.get("key"))[:12]}..., '
                         f'need {key[:12]}...)')


def _members(archive, path):
    """Zip members by array name; refuses duplicates and anything but ``<name>.npy``."""
    members = {}
    for info in archive.infolist():
        name = info.filename[:-4]
        if not info.filename.endswith('.npy') or name in members:
            raise CacheError(f'{path}: unexpected archive member {info.filename[:80]!r}')
        members[name] = info
    return members


def load_cache(path, key):
    """
    Read and verify a cache file.

    Every size is checked before anything is allocated: each array's .npy header (dtype,
    shape) must match the cache header and the bytes its zip member stores, and all arrays
    together stay below :data:`MAX_CACHE_BYTES`.

    Parameters
    ----------
    path : str or Path
        Cache file.
    key : str
        The key the caller needs; another key means the file is stale.

    Returns
    -------
    arrays : dict of str to ndarray
        The stored arrays.
    meta : dict
        The stored metadata.

    Raises
    ------
    CacheError
        If the file is missing, not trusted (:func:`.cache_location.open_trusted`: owned by
        another user, writable by others, not a regular file), unreadable, foreign, of
        another version or key, announces more than it holds, or is corrupt (its checksum
        is checked unless the file carries the record of an earlier check and has not been
        written since: :func:`_verified_before`).

    """
    path = pathlib.Path(path)
    if not os.path.lexists(path):
        raise CacheError(f'{path}: no cache file')
    try:
        with open_trusted(path) as stream, zipfile.ZipFile(stream) as archive:
            mapped = mmap.mmap(stream.fileno(), 0, access=mmap.ACCESS_READ)
            header, arrays = _read_archive(mapped, archive, path, key)
            if not _verified_before(stream, header.get('sha256')):
                if _array_digest(arrays) != header.get('sha256'):
                    raise CacheError(f'{path}: checksum mismatch (corrupt cache)')
                _note_verified(stream, header['sha256'])
    except CacheError:
        raise
    except (OSError, EOFError, ValueError, KeyError, TypeError, AttributeError, RuntimeError,
            NotImplementedError, UnicodeDecodeError, zipfile.BadZipFile,
            zipfile.LargeZipFile) as exc:
        # ValueError covers bad .npy headers and bad JSON; RuntimeError an encrypted member.
        raise CacheError(f'{path}: unreadable cache ({type(exc).__name__}: {exc})') from exc
    meta = header.get('meta')
    return arrays, meta if isinstance(meta, dict) else {}


def _file_identity(stream):
    """Return the open file's device, inode, size and modification time [ns]."""
    info = os.fstat(stream.fileno())
    return [info.st_dev, info.st_ino, info.st_size, info.st_mtime_ns]


def _verified_before(stream, digest):
    """
    Tell whether this very file's checksum was found right before and it is unchanged since.

    The record (:func:`_note_verified`) names the file's identity and checksum; any write to
    the file since changes its modification time, a replacement its inode.
    """
    try:
        record = json.loads(os.getxattr(stream.fileno(), VERIFIED_ATTRIBUTE))
    except (OSError, AttributeError, ValueError):    # none, or no xattrs on this system
        return False
    return record == {'identity': _file_identity(stream), 'sha256': digest}


def _note_verified(stream, digest):
    """
    Record on the file (an extended attribute) that its checksum was just found right.

    Only for a file last written at least :data:`VERIFIED_AGE_S` ago: a later write then gets
    a later modification time even where the clock's tick is coarse, so the record cannot
    outlive a change. Where the file system keeps no attributes the check simply runs again.
    """
    identity = _file_identity(stream)
    if identity[3] > time.time_ns() - int(VERIFIED_AGE_S * 1e9):
        return
    record = json.dumps({'identity': identity, 'sha256': digest}).encode()
    try:
        os.setxattr(stream.fileno(), VERIFIED_ATTRIBUTE, record)
    except (OSError, AttributeError):
        pass


def _read_archive(mapped, archive, path, key):
    """Header and arrays of an open cache archive, each checked against the header."""
    members = _members(archive, path)
    header = _read_header(mapped, members, path)
    _check_header(header, key, path)
    announced = header.get('arrays')
    if not isinstance(announced, dict) or set(announced) != set(members) - {HEADER_NAME}:
        raise CacheError(f'{path}: arrays differ from the header')
    # The arrays are stored uncompressed in this file: together they fit in it.
    arrays, budget = {}, min(MAX_CACHE_BYTES, len(mapped))
    for name, spec in sorted(announced.items()):
        array, size = _read_member(mapped, members[name], name, path, budget)
        budget -= size
        if not isinstance(spec, dict) or (array.dtype.str, list(array.shape)) != (
                spec.get('dtype'), spec.get('shape')):
            raise CacheError(f'{path}: array {name!r} is {array.dtype.str} '
                             f'{list(array.shape)}, header says {spec!r:.200}')
        arrays[name] = array
    return header, arrays


def usable_cache_dir(directory):
    """
    Create the cache directory (0700) if missing; None with one warning if it is not trusted.

    Parameters
    ----------
    directory : str or Path
        The cache directory (:mod:`.cache_location` says when it is trusted).

    Returns
    -------
    pathlib.Path or None

    """
    directory = pathlib.Path(directory)
    try:
        make_private_directory(directory)
    except OSError:     # then it is missing: the reason given below
        pass
    problem = untrusted_reason(directory / 'file', directory)
    if problem:
        LOGGER.warning('model cache not used (%s): the model is built in memory, not cached',
                       problem)
        return None
    return directory


def load_or_build(path, key, build, root=None):
    """
    Load a verified cache, or build the content, save it and return it.

    Nothing is read from or written to a directory that :mod:`.cache_location` does not
    trust: one warning says why and the content is built in memory.

    Parameters
    ----------
    path : str, Path or None
        Cache file; None disables caching (always build, never write).
    key : str
        Key of the wanted content.
    build : callable
        ``build() -> (arrays, meta)``, called when the cache is missing or refused.
    root : str, Path or None
        The cache directory whose trust is checked down to the file (None: the file's).

    Returns
    -------
    arrays : dict of str to ndarray
    meta : dict
    from_cache : bool
        True if the content came from a verified file.

    """
    if path is None:
        arrays, meta = build()
        return arrays, meta, False
    path = pathlib.Path(path)
    if usable_cache_dir(path.parent if root is None else root) is None or untrusted_reason(
            path, path.parent if root is None else root):
        arrays, meta = build()
        return arrays, meta, False
    if os.path.lexists(path):
        try:
            arrays, meta = load_cache(path, key)
            return arrays, meta, True
        except CacheError as exc:
            LOGGER.warning('rebuilding the precomputed model: %s', exc)
    arrays, meta = build()
    try:
        save_cache(path, key, arrays, meta)
    except OSError as exc:  # a read-only cache directory must not stop the estimator
        LOGGER.warning('could not write the model cache %s: %s', path, exc)
    return arrays, meta, False
