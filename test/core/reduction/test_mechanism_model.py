"""Reduced models of a mechanism: FE pieces, the veering, cache keys."""

import dataclasses
import pathlib

from flexlink_ros.core.estimation.tables import kf_groups
from flexlink_ros.core.fe import stiffness_damping as sd
from flexlink_ros.core.fe.linkage import FlexibleLinkage
from flexlink_ros.core.fe.modes import solve_frozen_modes
from flexlink_ros.core.mechanism_file import load_mechanism
from flexlink_ros.core.options import ModelOptions
from flexlink_ros.core.reduction import mechanism_model
from flexlink_ros.core.reduction.basis import frozen_modes
from flexlink_ros.core.reduction.build import reduce_samples
from flexlink_ros.core.reduction.mechanism_model import (fe_mechanism, frozen_samples_for,
                                                         model_for_mechanism, model_key)
from flexlink_ros.core.reduction.model import system_blocks
from flexlink_ros.core.reduction.second_order_dynamic_tables import ARRAY_NAMES as \
    DYNAMIC_ARRAY_NAMES
from flexlink_ros.core.reduction.second_order_tables import ARRAY_NAMES
from flexlink_ros.studies import flex_events, flex_frequencies
import numpy as np
import scipy.linalg

CONFIG = pathlib.Path(__file__).resolve().parents[3] / 'config'


def test_fe_pieces_of_cho1992():
    mechanism = load_mechanism(CONFIG / 'cho1992.yaml')
    options = ModelOptions.linear(bearings='rigid', geometric_stiffness=False, grid_size=16)
    samples = frozen_samples_for(mechanism, options)
    # Lowest link bending modes near 34 and 41 Hz (papers.md), coupler and lever.
    omega, _ = frozen_modes(samples.frozen_at(0, 0.0), samples.mass[0], 2)
    np.testing.assert_allclose(omega / (2 * np.pi), [34.5, 41.1], rtol=0.02)
    # The modal damping gives zeta on every frozen mode.
    damping = samples.damping(3, 30.0)
    omega, shapes = frozen_modes(samples.frozen_at(3, 30.0), samples.mass[3], samples.dofs)
    np.testing.assert_allclose(np.diag(shapes.T @ damping @ shapes),
                               2 * mechanism.damping_ratio * omega, rtol=1e-8)
    model = reduce_samples(samples, 4, 2, speed_max=60.0, zeta=mechanism.damping_ratio)
    rows = model.evaluate(2 * np.pi * 5 / 16, 40.0, 3.0)
    stiffness = system_blocks(model, rows)[2][0]
    expected = model.basis.T @ samples.stiffness_at(5, 40.0, 3.0) @ model.basis
    np.testing.assert_allclose(stiffness, expected, rtol=1e-9, atol=1e-9 * np.abs(expected).max())


def test_constant_basis_resolves_the_veering_where_per_angle_mode_interpolation_fails():
    # Cho 1992 at 391 rpm (rigid bearings): where the coupler and lever modes swap order,
    # sorted frozen modes interpolated over a grid cell miss; the constant basis V does not.
    mechanism = load_mechanism(CONFIG / 'cho1992.yaml')
    speed = 391 * np.pi / 30
    # Node defaults but rigid bearings: with the default flexible bearings the two modes only
    # approach to 2.3 Hz near 58 deg, flex_study reports no event and interpolation over a
    # grid cell still has MAC > 0.9999; with rigid bearings it detects two sharp swaps.
    options = ModelOptions.linear(bearings='rigid')
    model = model_for_mechanism(mechanism, options, use_cache=False)
    step = 2 * np.pi / options.grid_size
    linkage = FlexibleLinkage(fe_mechanism(mechanism, options),
                              options)
    # 1. The library's detection on the model's grid, refined to the closest approach.
    case = flex_frequencies.FrequencyCase('veering', 'rigid crank and bearings, K_G at 391 rpm',
                                          options, speed)
    sweep = flex_frequencies.sweep_case(fe_mechanism(mechanism, options), case,
                                        np.degrees(step * np.arange(options.grid_size)), 2)
    assert sweep.events and all(e.modes == (0, 1) for e in sweep.events)
    basis = model.basis
    for event in sweep.events:
        assert event.refined_gap < 0.01       # Hz, at ~38.4 Hz: a near-crossing
        # 2. Bracket: the model's grid cell (2 pi / 128) holding the closest approach.
        k = int(np.floor(np.radians(event.refined_parameter) / step))
        angles = step * np.array([k, k + 0.5, k + 1.0])
        system = linkage.assemble(angles)
        frozen = solve_frozen_modes(system, 2, speed)
        mass = system.mass
        left, right = frozen.shapes[0], frozen.shapes[2]
        # Sorted by frequency, signs aligned across the cell (the naive method's best case).
        signs = np.sign(np.einsum('im,ij,jm->m', left, mass[0], right))
        naive = 0.5 * (left + signs * right)
        naive_mac = np.diag(flex_events.mac(naive, frozen.shapes[1], mass[1]))
        assert naive_mac.max() < 0.8, naive_mac          # measured 0.52 and 0.57
        # 3. Every true mode of the pair, at both ends and the midpoint, lies in span(V):
        # mass-weighted residual of the M(theta)-orthogonal projection (shapes M-normalised).
        for j in range(3):
            shapes = frozen.shapes[j]
            reduced_mass = basis.T @ mass[j] @ basis
            residual = shapes - basis @ np.linalg.solve(reduced_mass,
                                                        basis.T @ mass[j] @ shapes)
            norms = np.sqrt(np.einsum('im,ij,jm->m', residual, mass[j], residual))
            assert norms.max() < 1e-3, norms             # measured <= 1.5e-4
        # The reduced system interpolated from the tables matches the full frozen
        # frequencies. Its K holds the rotating-frame terms, so the like-for-like full problem
        # is the frozen one with the centrifugal part (the paper's omits it: 0.35 % apart).
        full = solve_frozen_modes(system, 2, speed, centrifugal=True).frequencies_hz
        mass_r, _, stiffness_r, _ = system_blocks(model, model.evaluate(angles, speed, 0.0))
        for j in range(3):
            values = scipy.linalg.eigh(0.5 * (stiffness_r[j] + stiffness_r[j].T), mass_r[j],
                                       eigvals_only=True)[:2]
            error = np.abs(np.sqrt(values) / (2 * np.pi) / full[j] - 1.0)
            assert error.max() < 1e-3, error             # measured <= 2.3e-5


# model_key(cho1992, options) computed before the reduced model was split into modules: a
# cache written by an earlier version must still be found (the key bytes are the file name).
PINNED_KEYS = [
    (ModelOptions.linear(), '40c1da2cef355000da1b9509d518ea309436fd0d9c350c56bd3c078732b71bae'),
    (ModelOptions.linear(rigid_crank=False, elements_per_link=4),
     'a0b7923af86413aae9ef02bfa47585143185d20f4095781ea6d78eb143aabb63'),
    (ModelOptions.linear(bearings='rigid', grid_size=64),
     'a3cbbed807311a5944d834c27d191dced965f02078c1c6f8574744ca62e7de99'),
    # the node's default model, before it became ModelOptions(): its cache files still load
    (ModelOptions(), '7ba3325b01276d155c234f843eff8622652a8e3d9315363a970e59fe0d30c4fc'),
]


def test_model_keys_are_pinned():
    mechanism = load_mechanism('cho1992')
    for options, key in PINNED_KEYS:
        assert model_key(mechanism, options) == key, options


# model_key of cho1992 with the default options before stiffness damping existed.
DEFAULT_KEY_BEFORE_BETA = '40c1da2cef355000da1b9509d518ea309436fd0d9c350c56bd3c078732b71bae'


def test_stiffness_damping_keys_only_when_set():
    mechanism = load_mechanism(CONFIG / 'cho1992.yaml')
    assert model_key(mechanism, ModelOptions.linear()) == DEFAULT_KEY_BEFORE_BETA
    assert model_key(mechanism,
                     ModelOptions.linear(stiffness_damping=0.0)) == DEFAULT_KEY_BEFORE_BETA
    assert 'stiffness_damping' not in ModelOptions.linear().cache_fields()
    keys = {model_key(mechanism, ModelOptions.linear(stiffness_damping=beta))
            for beta in (1e-4, 2e-4)}
    assert len(keys) == 2 and DEFAULT_KEY_BEFORE_BETA not in keys


def test_stiffness_damping_tables_are_the_projected_c_beta_and_d_beta():
    """C gains V^T beta K V, K gains w V^T Kb1 V (monomial w); beta = 0 adds no piece."""
    mechanism = load_mechanism(CONFIG / 'cho1992.yaml')
    beta, grid, k, w = 1e-4, 16, 5, 40.0
    options = {'grid_size': grid, 'gravity': False, 'elements_per_link': 3}
    plain = frozen_samples_for(mechanism, ModelOptions.linear(**options))
    damped = frozen_samples_for(mechanism, ModelOptions.linear(stiffness_damping=beta, **options))
    assert set(plain.stiffness) == {'1', 'a', 'w2'}
    linkage = FlexibleLinkage(fe_mechanism(mechanism, ModelOptions.linear(**options)),
                              ModelOptions.linear(**options))
    theta = np.array([2 * np.pi * k / grid])
    c_beta, d_beta = sd.stiffness_damping_terms(linkage, theta, w, beta)
    np.testing.assert_allclose(w * damped.stiffness['w'][k], d_beta[0], rtol=1e-12, atol=0.0)
    np.testing.assert_allclose(damped.damping(k, w) - plain.damping(k, w), c_beta[0],
                               rtol=1e-9, atol=1e-9 * np.abs(c_beta).max())
    models = [reduce_samples(s, 4, 2, speed_max=60.0, zeta=mechanism.damping_ratio)
              for s in (plain, damped)]
    # The basis does not see the damping: the same V, so the tables differ by the projections.
    np.testing.assert_array_equal(models[0].basis, models[1].basis)
    basis = models[0].basis
    blocks = [system_blocks(m, m.evaluate(theta[0], w, 0.0)) for m in models]
    expected_c = basis.T @ c_beta[0] @ basis
    expected_k = basis.T @ d_beta[0] @ basis
    np.testing.assert_allclose(blocks[1][1][0] - blocks[0][1][0], expected_c,
                               rtol=1e-6, atol=1e-6 * np.abs(expected_c).max())
    np.testing.assert_allclose(blocks[1][2][0] - blocks[0][2][0], expected_k,
                               rtol=1e-6, atol=1e-6 * np.abs(expected_k).max())
    assert np.abs(expected_k).max() > 0.0
    assert kf_groups(models[0]) == 3 and kf_groups(models[1]) == 4


def test_order_2_has_its_own_key_and_order_1_keeps_the_pinned_ones():
    # Order 1 leaves the key as it was before the field (existing caches load); order 2 adds
    # tables, so it needs a key of its own.
    mechanism = load_mechanism('cho1992')
    for options, key in PINNED_KEYS:
        if options.order == 2:
            continue
        assert model_key(mechanism, dataclasses.replace(options, order=1)) == key
        assert model_key(mechanism, dataclasses.replace(options, order=2)) != key


def test_order_2_model_round_trips_through_the_cache_and_order_1_has_no_tables(tmp_path):
    mechanism = load_mechanism('cho1992')
    options = ModelOptions.linear(bearings='rigid', grid_size=16, order=2)
    built = model_for_mechanism(mechanism, options, cache_dir=tmp_path)
    assert built.order == 2 and set(built.second_order) == set(ARRAY_NAMES)
    loaded = model_for_mechanism(mechanism, options, cache_dir=tmp_path)
    assert loaded.order == 2
    for name in ARRAY_NAMES:
        np.testing.assert_array_equal(loaded.second_order[name], built.second_order[name])
        assert loaded.second_order[name].dtype == built.second_order[name].dtype
    linear = model_for_mechanism(mechanism, dataclasses.replace(options, order=1),
                                 cache_dir=tmp_path)
    assert linear.order == 1 and linear.second_order is None
    # The linear tables are the same bits whatever the order.
    np.testing.assert_array_equal(linear.table, loaded.table)
    np.testing.assert_array_equal(linear.basis, loaded.basis)
    models = [p for p in tmp_path.glob('*.npz') if not p.stem.endswith(('-nonlinearity', '-soft'))]
    assert len(models) == 2     # one per order (each beside its validity-indicator tables)


def test_dynamic_second_order_has_its_own_key_and_tables_and_round_trips(tmp_path):
    # quasi-static (the default) keeps the pinned keys; dynamic needs a key of its own
    mechanism = load_mechanism('cho1992')
    for options, key in PINNED_KEYS:
        quasi = dataclasses.replace(options, order=2, second_order='quasi-static')
        assert model_key(mechanism, quasi) == model_key(
            mechanism, dataclasses.replace(options, order=2))
        assert model_key(mechanism, dataclasses.replace(quasi, second_order='dynamic')) != \
            model_key(mechanism, quasi)
    options = ModelOptions.linear(bearings='rigid', grid_size=16, order=2, elements_per_link=3,
                                  second_order='dynamic', modes=5, static=3)
    built = model_for_mechanism(mechanism, options, cache_dir=tmp_path)
    assert set(built.dynamic_second_order) == set(DYNAMIC_ARRAY_NAMES)
    loaded = model_for_mechanism(mechanism, options, cache_dir=tmp_path)
    for name in DYNAMIC_ARRAY_NAMES:
        np.testing.assert_array_equal(loaded.dynamic_second_order[name],
                                      built.dynamic_second_order[name])
    assert model_for_mechanism(mechanism, dataclasses.replace(
        options, second_order='quasi-static'), use_cache=False).dynamic_second_order is None


def test_soft_tables_are_cached_beside_the_model_and_come_back_bit_for_bit(
        tmp_path, monkeypatch):
    """A cached model's load builds no soft tables (eigenproblems, logm, expm per node)."""
    mechanism = load_mechanism('cho1992')
    options = ModelOptions(bearings='flexible', grid_size=16, soft_modes=-1)
    built = model_for_mechanism(mechanism, options, cache_dir=tmp_path)
    assert built.info['soft']['used']
    key = model_key(mechanism, options)
    assert (tmp_path / f'cho1992-{key[:16]}-soft.npz').is_file()
    calls, original = [], mechanism_model.soft_tables
    monkeypatch.setattr(mechanism_model, 'soft_tables',
                        lambda *args: calls.append(args) or original(*args))
    loaded = model_for_mechanism(mechanism, options, cache_dir=tmp_path)
    assert calls == [] and loaded.info['soft'] == built.info['soft']
    assert set(loaded.soft) == set(built.soft)
    for name, table in built.soft.items():
        assert loaded.soft[name].dtype == table.dtype
        assert loaded.soft[name].tobytes() == table.tobytes()
