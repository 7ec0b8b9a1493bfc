"""
Tables of the validity indicator (core/reduction/nonlinearity_tables.py).

Each piece against the full-order function it tabulates: the link-mean axial operator against
the FE element forces, the affine rigid-body pieces against the rigid-body axial force at
another speed and acceleration, the reference table against core.validity.mode_reference; the
spline passes through the grid values; the tables go through the cache file as plain arrays and
the cache key carries their version.
"""

import math

from flexlink_ros.core import validity
from flexlink_ros.core.fe import linkage as assembly
from flexlink_ros.core.mechanism_file import load_mechanism
from flexlink_ros.core.options import ModelOptions
from flexlink_ros.core.reduction import mechanism_model, nonlinearity_tables as nl, store
from flexlink_ros.core.reduction.model import ReducedModel
import numpy as np
import pytest

OPTIONS = ModelOptions.linear(bearings='rigid', rigid_crank=True, elements_per_link=3,
                              grid_size=16, speed_max=40.0)


@pytest.fixture(scope='module')
def mech():
    return load_mechanism('cho1992')


@pytest.fixture(scope='module')
def linkage(mech):
    return assembly.FlexibleLinkage(mechanism_model.fe_mechanism(mech, OPTIONS), OPTIONS)


@pytest.fixture(scope='module')
def model(mech, tmp_path_factory):
    return mechanism_model.model_for_mechanism(mech, OPTIONS,
                                               cache_dir=tmp_path_factory.mktemp('c'))


def test_axial_operator_is_the_link_mean_of_the_element_forces(linkage):
    rng = np.random.default_rng(3)
    angles = np.array([0.2, 2.5])
    displacement = rng.normal(size=(2, linkage.size)) * 1e-4
    operator = nl.axial_operator(linkage, angles, validity.INDICATOR_LINKS)
    forces = linkage.element_axial_forces(displacement, angles)
    for i, link in enumerate(validity.INDICATOR_LINKS):
        np.testing.assert_allclose(np.einsum('kn,kn->k', operator[:, i], displacement),
                                   forces[link].mean(axis=1), rtol=1e-10)


def test_rigid_pieces_are_affine_in_acceleration_and_speed_squared(linkage):
    angles = np.array([0.4, 3.0, 5.1])
    pieces = nl.rigid_axial_pieces(linkage, angles, validity.INDICATOR_LINKS)
    speed, accel = 37.0, -120.0
    direct = validity.rigid_element_axial_forces(linkage, angles, speed, accel)
    combined = pieces['1'] + accel * pieces['a'] + speed ** 2 * pieces['w2']
    for i, link in enumerate(validity.INDICATOR_LINKS):
        np.testing.assert_allclose(combined[:, i], direct[link].mean(axis=1), rtol=1e-9,
                                   atol=1e-9)


def test_reference_table_against_mode_reference(linkage):
    speeds, omega, share = nl.reference_table(linkage, 40.0, speeds=3)
    np.testing.assert_allclose(speeds ** 2, [0.0, 800.0, 1600.0])     # uniform in w^2
    direct = validity.mode_reference(linkage, speeds[1])
    np.testing.assert_allclose(omega[1], direct['omega'], rtol=1e-12)
    np.testing.assert_allclose(share[1], direct['share'][:, list(validity.INDICATOR_LINKS)],
                               rtol=1e-12)


def test_table_passes_through_the_grid_values(model):
    table = model.nonlinearity['nonlinearity_table']
    count, powers, links, width = table.shape
    assert (count, powers, links, width) == (16, 4, 2, 7 * model.size + 3)
    # t = 1 of cell k is t = 0 of cell k + 1 (the spline is continuous across cells)
    end = table.sum(axis=1)
    np.testing.assert_allclose(end, np.roll(table[:, 0], -1, axis=0), rtol=1e-9, atol=1e-12)


def test_tables_survive_a_cache_file_as_plain_arrays(model, tmp_path):
    arrays, meta = model.to_arrays()
    assert set(nl.TABLE_NAMES) <= set(arrays)
    path = tmp_path / 'model.npz'
    store.save_cache(path, 'k', arrays, meta)
    loaded = ReducedModel.from_arrays(*store.load_cache(path, 'k'))
    for name in nl.TABLE_NAMES:
        np.testing.assert_array_equal(loaded.nonlinearity[name], model.nonlinearity[name])
    plain = ReducedModel.from_arrays({k: v for k, v in arrays.items()
                                      if k not in nl.TABLE_NAMES}, meta)
    assert plain.nonlinearity is None
    assert math.isfinite(float(model.nonlinearity['nonlinearity_omega'][0, 0]))


def test_tables_cached_beside_the_model_under_their_own_key(mech, model, tmp_path):
    """The model's file and key are unchanged by the tables (test_mechanism_model pins keys)."""
    again = mechanism_model.model_for_mechanism(mech, OPTIONS, cache_dir=tmp_path)
    files = sorted(path.name for path in tmp_path.iterdir() if '-soft' not in path.name)
    key = mechanism_model.model_key(mech, OPTIONS)
    assert files == [f'cho1992-{key[:16]}-nonlinearity.npz', f'cho1992-{key[:16]}.npz']
    arrays, _ = store.load_cache(tmp_path / files[0], store.cache_key(
        'nonlinearity-tables', nl.NONLINEARITY_VERSION, key))
    assert set(arrays) == set(nl.TABLE_NAMES)
    model_arrays, _ = store.load_cache(tmp_path / files[1], key)
    assert not set(nl.TABLE_NAMES) & set(model_arrays)
    loaded = mechanism_model.model_for_mechanism(mech, OPTIONS, cache_dir=tmp_path)   # from files
    for name in nl.TABLE_NAMES:
        np.testing.assert_array_equal(loaded.nonlinearity[name], again.nonlinearity[name])
