"""Model cache files: trusted only when the user alone could have written them; paths inside."""

import dataclasses
import logging
import os
import shutil

from flexlink_ros.core.estimation.streaming import StreamingEstimator
from flexlink_ros.core.mechanism import Mechanism
from flexlink_ros.core.mechanism_file import load_mechanism
from flexlink_ros.core.options import ModelOptions
from flexlink_ros.core.reduction import cache_location, mechanism_model, store
from flexlink_ros.errors import CacheError
import numpy as np
import pytest

OTHER_UID = 65534       # nobody: a local user other than the one running the tests
# A model small enough to build in about a second.
OPTIONS = ModelOptions(grid_size=16, order=1, elements_per_link=2, modes=4, static=2)
LOGGER = 'flexlink_ros.core.reduction.store'

pytestmark = pytest.mark.skipif(os.geteuid() != 0, reason='chown to another uid needs root')


def deflections(model):
    """Lever-tip deflections of the model over a revolution at 30 rad/s."""
    estimator = StreamingEstimator(model)
    out = []
    for k in range(200):
        t = k * 1e-3
        out.append(estimator.update(1_000_000_000 + k * 1_000_000, 30.0 * t, 30.0).lever_tip)
    return np.array(out)


def planted_cache(source_dir, target_dir, scale=1.3):
    """Copy the model's cache files to target_dir, its table scaled, checksum recomputed."""
    target_dir.mkdir(exist_ok=True)
    for source in source_dir.iterdir():
        target = target_dir / source.name
        shutil.copyfile(source, target)
        if source.name.endswith(('-nonlinearity.npz', '-soft.npz')):
            continue
        key = mechanism_model.model_key(load_mechanism('cho1992'), OPTIONS)
        arrays, meta = store.load_cache(source, key)
        arrays['table'] = arrays['table'] * scale
        store.save_cache(target, key, arrays, meta)
    return sorted(target_dir.iterdir())


@pytest.fixture
def reference(tmp_path):
    """Give the untouched model's cache directory and its deflections."""
    good = tmp_path / 'good'
    model = mechanism_model.model_for_mechanism(load_mechanism('cho1992'), OPTIONS, cache_dir=good)
    return good, deflections(model)


def load(cache_dir, caplog):
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger=LOGGER):
        model = mechanism_model.model_for_mechanism(load_mechanism('cho1992'), OPTIONS,
                                                    cache_dir=cache_dir)
    return deflections(model), caplog.text


def test_a_planted_table_in_a_trusted_place_loads(tmp_path, reference, caplog):
    # The control: the same planted file, owned by the user in a private directory, loads
    # (the checksum matches), and the deflections are 30 % larger.
    good, expected = reference
    mine = tmp_path / 'mine'
    planted_cache(good, mine)
    got, log = load(mine, caplog)
    np.testing.assert_allclose(np.abs(got).max(), 1.3 * np.abs(expected).max(), rtol=0.05)
    assert log == ''


@pytest.mark.parametrize('mode, owner, why', [
    (0o777, 0, 'writable by group or others (mode 0777)'),
    (0o1777, OTHER_UID, f'owned by uid {OTHER_UID}'),
    (0o1777, 'self', None),         # sticky and the user's: the file's owner decides
    (0o755, OTHER_UID, f'owned by uid {OTHER_UID}'),
    (0o775, 0, 'writable by group or others (mode 0775)'),
])
def test_a_cache_planted_by_another_user_is_refused_and_the_model_built_fresh(
        tmp_path, reference, caplog, mode, owner, why):
    good, expected = reference
    planted = tmp_path / 'planted'
    files = planted_cache(good, planted)
    for path in files:
        os.chown(path, OTHER_UID, OTHER_UID)
    os.chmod(planted, mode)
    os.chown(planted, os.geteuid() if owner == 'self' else owner, 0)
    before = {p.name: p.stat().st_mtime_ns for p in files}
    got, log = load(planted, caplog)
    np.testing.assert_array_equal(got, expected)
    assert len(log.strip().splitlines()) == (1 if why else len(files)), log   # one a file
    if why:         # the directory: nothing read, nothing written there
        assert why in log and 'built in memory' in log
        assert {p.name: p.stat().st_mtime_ns for p in planted.iterdir()} == before
    else:           # a trusted directory, the files another user's: refused, replaced
        assert f'owned by uid {OTHER_UID}, not {os.geteuid()}' in log
        assert all(p.stat().st_uid == os.geteuid() for p in planted.iterdir())


def test_a_group_writable_file_or_a_link_is_not_read(tmp_path, reference, caplog):
    good, expected = reference
    planted = tmp_path / 'planted'
    model_file = [p for p in planted_cache(good, planted)
                  if not p.name.endswith(('-nonlinearity.npz', '-soft.npz'))][0]
    os.chmod(model_file, 0o666)
    got, log = load(planted, caplog)
    np.testing.assert_array_equal(got, expected)
    assert 'writable by group or others (mode 0666)' in log
    # A link to a planted file elsewhere: not followed.
    elsewhere = tmp_path / 'elsewhere'
    planted_cache(good, elsewhere)
    target = model_file
    target.unlink()
    target.symlink_to(elsewhere / target.name)
    got, log = load(planted, caplog)
    np.testing.assert_array_equal(got, expected)
    assert 'cannot open the cache' in log
    assert not target.is_symlink()      # replaced by a file of the user's


def test_the_default_cache_directory_is_created_private(tmp_path, monkeypatch):
    monkeypatch.setenv('XDG_CACHE_HOME', str(tmp_path / 'xdg'))
    old = os.umask(0)
    try:
        mechanism_model.model_for_mechanism(load_mechanism('cho1992'), OPTIONS)
    finally:
        os.umask(old)
    for directory in (tmp_path / 'xdg', tmp_path / 'xdg' / 'flexlink_ros'):
        assert directory.stat().st_mode & 0o777 == 0o700
    assert len(list((tmp_path / 'xdg' / 'flexlink_ros').glob('*.npz'))) == 3   # with -soft


def test_rule_of_one_directory(tmp_path):
    directory = tmp_path / 'd'
    directory.mkdir()
    assert cache_location.directory_problem(directory) == ''
    os.chmod(directory, 0o1777)
    assert cache_location.directory_problem(directory) == ''     # sticky, the user's
    os.chown(directory, OTHER_UID, 0)
    assert 'owned by uid' in cache_location.directory_problem(directory)
    os.chown(directory, 0, 0)
    os.chmod(directory, 0o777)
    assert 'mode 0777' in cache_location.directory_problem(directory)


@pytest.mark.parametrize('name', ['../../../escape/dir/x', '/etc/passwd', '..', '.hidden',
                                  'a/../../b', 'x' * 300, ''])
def test_a_cache_path_never_leaves_the_cache_directory(tmp_path, name):
    directory = tmp_path / 'cache'
    path = cache_location.cache_file(directory, name, 'ab' * 32)
    assert path.parent == directory and path.resolve().parent == directory.resolve()
    assert not path.name.startswith('.') and len(path.name) <= 64 + 1 + 16 + 4


def test_a_mechanism_named_as_a_path_writes_only_inside_the_cache(tmp_path):
    mechanism = dataclasses.replace(load_mechanism('cho1992'), name='../../../escape/dir/x')
    assert isinstance(mechanism, Mechanism)
    cache = tmp_path / 'a' / 'b' / 'c' / 'cache'
    mechanism_model.model_for_mechanism(mechanism, OPTIONS, cache_dir=cache)
    written = sorted(p.relative_to(tmp_path) for p in tmp_path.rglob('*') if p.is_file())
    assert len(written) == 3 and all(p.parent == cache.relative_to(tmp_path) for p in written)
    assert not (tmp_path / 'escape').exists()


def test_a_refused_file_is_a_cache_error(tmp_path):
    path = tmp_path / 'model.npz'
    store.save_cache(path, 'k' * 64, {'a': np.zeros(3)})
    os.chown(path, OTHER_UID, OTHER_UID)
    with pytest.raises(CacheError, match='not trusted'):
        store.load_cache(path, 'k' * 64)
