"""Model cache: round trip, and refusal (then rebuild) of every kind of bad file."""

import io
import json
import logging
import mmap
import os
import pickle
import struct
import tracemalloc
import zipfile

from flexlink_ros.core.mechanism_file import load_mechanism
from flexlink_ros.core.reduction import store as cache
from flexlink_ros.errors import CacheError
import numpy as np
import pytest

KEY = cache.cache_key('mechanism-key', {'modes': 6})


def content():
    rng = np.random.default_rng(0)
    return {'basis': rng.normal(size=(12, 4)), 'grid': np.linspace(0, 1, 9),
            'flags': np.array([True, False]), 'count': np.arange(3)}, {'modes': 6}


def assert_same(arrays, expected):
    assert set(arrays) == set(expected)
    for name in expected:
        np.testing.assert_array_equal(arrays[name], expected[name])
        assert arrays[name].dtype == expected[name].dtype


def test_round_trip(tmp_path):
    arrays, meta = content()
    path = tmp_path / 'sub' / 'model.npz'
    cache.save_cache(path, KEY, arrays, meta)
    loaded, loaded_meta = cache.load_cache(path, KEY)
    assert_same(loaded, arrays)
    assert loaded_meta == meta
    assert not list(path.parent.glob('*.tmp'))  # the temporary file was moved into place


def maps_the_file(array):
    """Whether ``array``'s memory is a map of a file (a view, at the end, of an mmap)."""
    while isinstance(array.base, np.ndarray):
        array = array.base
    memory = array.base
    return isinstance(memory, memoryview) and isinstance(memory.obj, mmap.mmap)


def test_loaded_arrays_are_aligned_read_only_views_of_the_file(tmp_path):
    """No copy and no fresh memory: a new process faults fresh pages in slower than it reads."""
    arrays, meta = content()
    arrays['odd'] = np.arange(7, dtype=np.int16)       # sizes that shift the next member
    arrays['table'] = np.random.default_rng(1).normal(size=(5, 3, 3))
    path = tmp_path / 'model.npz'
    cache.save_cache(path, KEY, arrays, meta)
    loaded, _ = cache.load_cache(path, KEY)
    assert_same(loaded, arrays)
    for name, array in loaded.items():
        assert maps_the_file(array) and array.flags.aligned, name
        assert not array.flags.writeable, name
    with np.load(path, allow_pickle=False) as independent:   # still a plain .npz
        assert_same({n: independent[n] for n in arrays}, arrays)


def test_a_cache_numpy_wrote_unaligned_loads_as_copies(tmp_path):
    """Files of the earlier writer (``np.savez``: data at any offset) still load."""
    arrays, meta = content()
    path = tmp_path / 'model.npz'
    cache.save_cache(path, KEY, arrays, meta)
    with np.load(path, allow_pickle=False) as saved:
        members = {name: saved[name] for name in saved.files}
    np.savez(path, **members)
    loaded, loaded_meta = cache.load_cache(path, KEY)
    assert_same(loaded, arrays)
    assert loaded_meta == meta
    assert not all(maps_the_file(array) for array in loaded.values())   # some were copied out
    assert all(array.flags.aligned and not array.flags.writeable for array in loaded.values())


def test_key_depends_on_mechanism_and_options(config_dir):
    mech = load_mechanism(config_dir / 'cho1992.yaml')
    other = load_mechanism(config_dir / 'kang1990.yaml')
    assert cache.cache_key(mech.key(), {'modes': 6}) != cache.cache_key(other.key(),
                                                                        {'modes': 6})
    assert cache.cache_key(mech.key(), {'modes': 6}) != cache.cache_key(mech.key(),
                                                                        {'modes': 7})
    assert cache.cache_key(mech.key(), {'modes': 6}) == cache.cache_key(mech.key(),
                                                                        {'modes': 6})


def corrupt_bytes(path):
    data = bytearray(path.read_bytes())
    # Flip bytes inside the stored (uncompressed) data of the largest array.
    with zipfile.ZipFile(path) as archive:
        info = max(archive.infolist(), key=lambda i: i.file_size)
    start = info.header_offset + 30 + len(info.filename) + len(info.extra) + 200
    for k in range(start, start + 8):
        data[k] ^= 0x5A
    path.write_bytes(bytes(data))


def truncate(path):
    data = path.read_bytes()
    path.write_bytes(data[:len(data) // 2])


def stale_key(path):
    arrays, meta = content()
    cache.save_cache(path, cache.cache_key('another mechanism'), arrays, meta)


def other_version(path):
    arrays, _ = content()
    header = {'format': cache.FORMAT_NAME, 'version': cache.FORMAT_VERSION + 1, 'key': KEY,
              'arrays': {n: {'dtype': a.dtype.str, 'shape': list(a.shape)}
                         for n, a in arrays.items()},
              'sha256': cache._array_digest(arrays), 'meta': {}}
    np.savez(path.open('wb'), __header__=np.frombuffer(json.dumps(header).encode(), np.uint8),
             **arrays)


def pickle_renamed(path):
    path.write_bytes(pickle.dumps(content()))


def object_array(path):
    arrays, _ = content()
    arrays['basis'] = np.array([{'a': 1}, None], dtype=object)
    header = {'format': cache.FORMAT_NAME, 'version': cache.FORMAT_VERSION, 'key': KEY,
              'arrays': {n: {'dtype': a.dtype.str, 'shape': list(a.shape)}
                         for n, a in arrays.items()},
              'sha256': '0' * 64, 'meta': {}}
    with path.open('wb') as stream:
        np.savez(stream, __header__=np.frombuffer(json.dumps(header).encode(), np.uint8),
                 **arrays)


def foreign_npz(path):
    with path.open('wb') as stream:
        np.savez(stream, weights=np.ones(3))


def extra_array(path):
    arrays, meta = content()
    cache.save_cache(path, KEY, arrays, meta)
    with np.load(path) as archive:
        stored = {name: archive[name] for name in archive.files}
    stored['extra'] = np.zeros(2)
    with path.open('wb') as stream:
        np.savez(stream, **stored)


def tampered_array(path):
    # A valid archive whose array changed after the header was written.
    with np.load(path) as archive:
        stored = {name: archive[name] for name in archive.files}
    stored['basis'] = stored['basis'] + 1e-12
    with path.open('wb') as stream:
        np.savez(stream, **stored)


def empty_file(path):
    path.write_bytes(b'')


BAD_FILES = {
    'corrupt bytes': (corrupt_bytes, 'checksum|unreadable'),
    'truncated': (truncate, 'unreadable'),
    'wrong key': (stale_key, 'stale'),
    'wrong version': (other_version, 'version'),
    'pickle renamed .npz': (pickle_renamed, 'unreadable'),
    'object array': (object_array, 'unreadable|dtype'),
    'foreign npz': (foreign_npz, 'not a flexlink_ros cache'),
    'extra array': (extra_array, 'differ from the header'),
    'empty file': (empty_file, 'unreadable'),
    'tampered array': (tampered_array, 'checksum'),
}


@pytest.mark.parametrize('name', sorted(BAD_FILES))
def test_bad_file_is_refused_and_rebuilt(tmp_path, caplog, name):
    spoil, message = BAD_FILES[name]
    path = tmp_path / 'model.npz'
    arrays, meta = content()
    cache.save_cache(path, KEY, arrays, meta)
    spoil(path)
    with pytest.raises(CacheError, match=message):
        cache.load_cache(path, KEY)
    calls = []

    def build():
        calls.append(1)
        return content()

    with caplog.at_level(logging.WARNING, logger='flexlink_ros.core.reduction.store'):
        loaded, loaded_meta, from_cache = cache.load_or_build(path, KEY, build)
    assert calls == [1] and not from_cache
    assert 'rebuilding' in caplog.text
    assert_same(loaded, arrays)
    # The rebuilt file replaced the bad one and now verifies.
    reloaded, _, from_cache = cache.load_or_build(path, KEY, build)
    assert from_cache and calls == [1]
    assert_same(reloaded, arrays)


def age(path, seconds=3600.0):
    """Give ``path`` a modification time ``seconds`` ago (a cache written some time before)."""
    info = path.stat()
    past = info.st_mtime_ns - int(seconds * 1e9)
    os.utime(path, ns=(past, past))


def needs_extended_attributes(directory):
    """Skip where the file system keeps no user attributes (the check then always runs)."""
    probe = directory / 'xattr-probe'
    probe.write_bytes(b'')
    try:
        os.setxattr(probe, 'user.flexlink_ros.probe', b'1')
    except (OSError, AttributeError) as exc:
        pytest.skip(f'no user extended attributes here: {exc}')
    finally:
        probe.unlink()


def counted_digests(monkeypatch):
    """Count the checksums computed (the real function, counted)."""
    calls = []
    digest = cache._array_digest

    def counting(arrays):
        calls.append(1)
        return digest(arrays)

    monkeypatch.setattr(cache, '_array_digest', counting)
    return calls


def test_a_file_checked_once_is_mapped_again_without_reading_its_bytes(tmp_path, monkeypatch):
    needs_extended_attributes(tmp_path)
    arrays, meta = content()
    path = tmp_path / 'model.npz'
    cache.save_cache(path, KEY, arrays, meta)
    age(path)
    calls = counted_digests(monkeypatch)
    assert_same(cache.load_cache(path, KEY)[0], arrays)
    record = json.loads(os.getxattr(path, cache.VERIFIED_ATTRIBUTE))
    info = path.stat()
    assert record == {'identity': [info.st_dev, info.st_ino, info.st_size, info.st_mtime_ns],
                      'sha256': cache._array_digest(arrays)}
    calls.clear()
    assert_same(cache.load_cache(path, KEY)[0], arrays)
    assert calls == []


@pytest.mark.parametrize('name', ['corrupt bytes', 'tampered array'])
def test_a_write_after_the_check_is_caught(tmp_path, name):
    needs_extended_attributes(tmp_path)
    spoil, message = BAD_FILES[name]
    arrays, meta = content()
    path = tmp_path / 'model.npz'
    cache.save_cache(path, KEY, arrays, meta)
    age(path)
    cache.load_cache(path, KEY)
    assert os.getxattr(path, cache.VERIFIED_ATTRIBUTE)
    spoil(path)     # written in place: the same inode, a new modification time
    with pytest.raises(CacheError, match=message):
        cache.load_cache(path, KEY)


def test_a_file_written_just_now_is_checked_every_time(tmp_path, monkeypatch):
    """A coarse clock could give a write within the same tick the same modification time."""
    needs_extended_attributes(tmp_path)
    arrays, meta = content()
    path = tmp_path / 'model.npz'
    cache.save_cache(path, KEY, arrays, meta)
    calls = counted_digests(monkeypatch)
    cache.load_cache(path, KEY)
    cache.load_cache(path, KEY)
    assert len(calls) == 2
    assert cache.VERIFIED_ATTRIBUTE not in os.listxattr(path)


def test_a_record_of_another_file_is_not_taken(tmp_path, monkeypatch):
    needs_extended_attributes(tmp_path)
    arrays, meta = content()
    checked, other = tmp_path / 'model.npz', tmp_path / 'other.npz'
    for path in (checked, other):
        cache.save_cache(path, KEY, arrays, meta)
        age(path)
    cache.load_cache(checked, KEY)
    os.setxattr(other, cache.VERIFIED_ATTRIBUTE, os.getxattr(checked, cache.VERIFIED_ATTRIBUTE))
    calls = counted_digests(monkeypatch)
    cache.load_cache(other, KEY)
    assert calls == [1]


@pytest.mark.parametrize('record', [b'\xff\xfe not json', b'[1, 2]', b'{"identity": null}',
                                    b'x' * 3000])
def test_a_malformed_record_is_no_record(tmp_path, monkeypatch, record):
    needs_extended_attributes(tmp_path)
    arrays, meta = content()
    path = tmp_path / 'model.npz'
    cache.save_cache(path, KEY, arrays, meta)
    age(path)
    os.setxattr(path, cache.VERIFIED_ATTRIBUTE, record)
    calls = counted_digests(monkeypatch)
    assert_same(cache.load_cache(path, KEY)[0], arrays)
    assert calls == [1]           # checked in full, and the record made right
    assert json.loads(os.getxattr(path, cache.VERIFIED_ATTRIBUTE))['sha256'] == \
        cache._array_digest(arrays)


def test_missing_file_builds_without_warning(tmp_path, caplog):
    with caplog.at_level(logging.WARNING):
        _, _, from_cache = cache.load_or_build(tmp_path / 'new.npz', KEY, content)
    assert not from_cache and caplog.text == ''
    assert cache.load_or_build(tmp_path / 'new.npz', KEY, content)[2]


def test_no_cache_path_always_builds(tmp_path):
    arrays, meta, from_cache = cache.load_or_build(None, KEY, content)
    assert not from_cache and 'basis' in arrays


def test_refuses_to_save_non_numeric_arrays(tmp_path):
    with pytest.raises(CacheError, match='dtype'):
        cache.save_cache(tmp_path / 'x.npz', KEY, {'names': np.array(['a', 'b'])})
    with pytest.raises(CacheError, match='reserved'):
        cache.save_cache(tmp_path / 'x.npz', KEY, {'__header__': np.zeros(1)})
    assert not (tmp_path / 'x.npz').exists()


def test_unwritable_directory_still_returns_content(tmp_path, caplog):
    blocker = tmp_path / 'file'
    blocker.write_text('not a directory')
    with caplog.at_level(logging.WARNING, logger='flexlink_ros.core.reduction.store'):
        arrays, _, from_cache = cache.load_or_build(blocker / 'model.npz', KEY, content)
    assert not from_cache and 'basis' in arrays
    assert 'is not a directory' in caplog.text and 'built in memory' in caplog.text


# -- an array that announces 4 GiB: refused before allocation, then rebuilt ------------------

FOUR_GIB = 4 << 30


def _npy_header(dtype, shape):
    stream = io.BytesIO()
    np.lib.format.write_array_header_1_0(stream, {'descr': np.dtype(dtype).str,
                                                  'fortran_order': False, 'shape': shape})
    return stream.getvalue()


def _announcing_cache(path, zip_sizes_lie):
    """Write a cache with the right key and header whose 'basis' announces 4 GiB of float64."""
    arrays, meta = content()
    huge = (FOUR_GIB // 8,)
    header = {'format': cache.FORMAT_NAME, 'version': cache.FORMAT_VERSION, 'key': KEY,
              'arrays': {n: {'dtype': a.dtype.str, 'shape': list(huge if n == 'basis'
                                                                 else a.shape)}
                         for n, a in arrays.items()},
              'sha256': cache._array_digest(arrays), 'meta': meta}
    header_array = np.frombuffer(json.dumps(header).encode(), np.uint8)
    basis = _npy_header('<f8', huge) + arrays['basis'].tobytes()
    with zipfile.ZipFile(path, 'w', zipfile.ZIP_STORED) as archive:
        for name, array in [('__header__', header_array)] + [
                (n, a) for n, a in arrays.items() if n != 'basis']:
            stream = io.BytesIO()
            np.save(stream, array)
            archive.writestr(name + '.npy', stream.getvalue())
        archive.writestr('basis.npy', basis)
    if zip_sizes_lie:   # the zip's own size fields (local and central) claim the 4 GiB too
        data = bytearray(path.read_bytes())
        claimed = len(_npy_header('<f8', huge)) + FOUR_GIB - 1
        claimed = min(claimed, 0xFFFFFFFE)
        name = b'basis.npy'
        for signature, offset in ((b'PK\x03\x04', 18), (b'PK\x01\x02', 20)):
            start = 0
            while True:
                start = data.index(signature, start)
                name_at = start + (30 if signature == b'PK\x03\x04' else 46)
                if data[name_at:name_at + len(name)] == name:
                    break
                start += 4
            struct.pack_into('<II', data, start + offset, claimed, claimed)
        path.write_bytes(bytes(data))
    return header


@pytest.mark.parametrize('zip_sizes_lie', [False, True])
def test_array_announcing_4_gib_is_refused_before_allocation_and_rebuilt(tmp_path, caplog,
                                                                         zip_sizes_lie):
    path = tmp_path / 'model.npz'
    _announcing_cache(path, zip_sizes_lie)
    assert path.stat().st_size < 10_000
    with zipfile.ZipFile(path) as archive:   # the file does announce 4 GiB
        with archive.open('basis.npy') as member:
            np.lib.format.read_magic(member)
            shape, _, dtype = np.lib.format.read_array_header_1_0(member)
        assert shape[0] * dtype.itemsize == FOUR_GIB
        assert (archive.getinfo('basis.npy').file_size > FOUR_GIB - 1000) == zip_sizes_lie
    tracemalloc.start()
    try:
        # Zip sizes that lie run past the file's end: refused before the .npy header is read.
        reason = 'runs past the end of the file' if zip_sizes_lie else 'announces 4294967296 bytes'
        with pytest.raises(CacheError, match=reason):
            cache.load_cache(path, KEY)
        with caplog.at_level(logging.WARNING, logger='flexlink_ros.core.reduction.store'):
            loaded, _, from_cache = cache.load_or_build(path, KEY, content)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 10 << 20   # no 4 GiB buffer, not even briefly
    assert not from_cache and 'rebuilding' in caplog.text
    assert_same(loaded, content()[0])
    assert cache.load_or_build(path, KEY, content)[2]   # the rebuilt file verifies
