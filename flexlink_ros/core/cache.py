"""
Versioned, verified cache files for precomputed models (no pickle anywhere).

A cache file is a NumPy ``.npz`` archive of plain numeric arrays plus one ``uint8`` array,
``__header__``, holding a UTF-8 JSON header::

    {"format": "flexlink_ros.model_cache", "version": FORMAT_VERSION, "key": "<hex>",
     "arrays": {"name": {"dtype": "<f8", "shape": [..]}, ...},
     "sha256": "<hex of the arrays>", "meta": {...}}

Loading uses ``allow_pickle=False`` and rejects anything that is not exactly what the header
announces: another format or version, another key (stale: a different mechanism or model
options), missing or extra arrays, object or non-numeric dtypes, other shapes, a checksum
mismatch (corrupt bytes), or an unreadable archive (truncated, not a zip, a pickle renamed
``.npz``). Each raises :class:`CacheError`; :func:`load_or_build` then logs a warning and
rebuilds. Writes go to a temporary file in the same directory and are moved into place with
``os.replace``, so a reader never sees a half-written file.
"""

import hashlib
import json
import logging
import os
import pathlib
import tempfile
import zipfile

import numpy as np

from .errors import CacheError

LOGGER = logging.getLogger(__name__)

FORMAT_NAME = 'flexlink_ros.model_cache'
# Bump when the file layout changes; files of another version are rebuilt.
FORMAT_VERSION = 1
HEADER_NAME = '__header__'
# dtype kinds a cache may hold: bool, signed/unsigned integer, float, complex.
ALLOWED_KINDS = 'biufc'
# Refuse headers larger than this [bytes] (a foreign archive could announce anything).
MAX_HEADER_BYTES = 1 << 20


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
        digest.update(array.tobytes())
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
        Destination file (parent directories are created).
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
    path.parent.mkdir(parents=True, exist_ok=True)
    handle, temp_name = tempfile.mkstemp(prefix=path.name + '.', suffix='.tmp',
                                         dir=path.parent)
    try:
        with os.fdopen(handle, 'wb') as stream:
            np.savez(stream, **{HEADER_NAME: header_bytes}, **arrays)
            stream.flush()
            os.fsync(stream.fileno())
        os.replace(temp_name, path)
    except BaseException:
        try:
            os.unlink(temp_name)
        except FileNotFoundError:
            pass
        raise


def load_cache(path, key):
    """
    Read and verify a cache file.

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
        If the file is missing, unreadable, foreign, of another version or key, or corrupt.

    """
    path = pathlib.Path(path)
    if not path.is_file():
        raise CacheError(f'{path}: no cache file')
    try:
        with np.load(path, allow_pickle=False) as archive:
            names = set(archive.files)
            if HEADER_NAME not in names:
                raise CacheError(f'{path}: not a flexlink_ros cache (no header)')
            raw = archive[HEADER_NAME]
            if raw.dtype != np.uint8 or raw.ndim != 1 or raw.size > MAX_HEADER_BYTES:
                raise CacheError(f'{path}: malformed header')
            header = json.loads(raw.tobytes().decode())
            if not isinstance(header, dict):
                raise CacheError(f'{path}: malformed header')
            if header.get('format') != FORMAT_NAME:
                raise CacheError(f'{path}: not a flexlink_ros cache '
                                 f'(format {header.get("format")!r})')
            if header.get('version') != FORMAT_VERSION:
                raise CacheError(f'{path}: cache format version {header.get("version")!r}, '
                                 f'this code reads {FORMAT_VERSION}')
            if header.get('key') != key:
                raise CacheError(f'{path}: stale cache (key {str(header.get("key"))[:12]}..., '
                                 f'need {key[:12]}...)')
            announced = header.get('arrays')
            if not isinstance(announced, dict) or set(announced) != names - {HEADER_NAME}:
                raise CacheError(f'{path}: arrays differ from the header')
            arrays = {}
            for name, spec in announced.items():
                array = archive[name]
                _check_array(name, array)
                if array.dtype.str != spec.get('dtype') or list(array.shape) != spec.get('shape'):
                    raise CacheError(f'{path}: array {name!r} is {array.dtype.str} '
                                     f'{list(array.shape)}, header says {spec}')
                arrays[name] = array
    except CacheError:
        raise
    except (OSError, EOFError, ValueError, KeyError, TypeError, AttributeError,
            UnicodeDecodeError, zipfile.BadZipFile, zipfile.LargeZipFile) as exc:
        # ValueError covers pickled/object arrays refused by allow_pickle=False and bad JSON.
        raise CacheError(f'{path}: unreadable cache ({type(exc).__name__}: {exc})') from exc
    if _array_digest(arrays) != header.get('sha256'):
        raise CacheError(f'{path}: checksum mismatch (corrupt cache)')
    meta = header.get('meta')
    return arrays, meta if isinstance(meta, dict) else {}


def load_or_build(path, key, build):
    """
    Load a verified cache, or build the content, save it and return it.

    Parameters
    ----------
    path : str, Path or None
        Cache file; None disables caching (always build, never write).
    key : str
        Key of the wanted content.
    build : callable
        ``build() -> (arrays, meta)``, called when the cache is missing or refused.

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
    if path.exists():
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
