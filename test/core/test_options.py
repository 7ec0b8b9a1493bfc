"""Modelling options (core/options.py): defaults, the full-model defaults, the cache key."""

import dataclasses

from flexlink_ros.core.options import DEFAULT_SIZES, DYNAMIC_SIZES, ModelOptions
import pytest


def test_defaults_are_the_nodes_rigid_crank_and_flexible_bearings():
    options = ModelOptions()
    assert options.rigid_crank is True and options.bearings == 'flexible'
    assert (options.modes, options.static) == DEFAULT_SIZES['flexible', True] == (16, 2)
    assert options.grid_size == 128 and options.elements_per_link is None
    assert options.geometric_stiffness is True and options.gravity is True
    assert options.speed_max == 65.0


def test_full_model_is_flexible_crank_on_pins_and_keeps_changes():
    options = ModelOptions.full_model()
    assert options.rigid_crank is False and options.bearings == 'rigid'
    assert (options.modes, options.static) == (8, 4)
    changed = ModelOptions.full_model(rigid_crank=True, gravity=False, modes=3)
    assert changed.rigid_crank is True and changed.bearings == 'rigid'
    assert changed.gravity is False and changed.modes == 3
    # static follows the (bearings, crank) default when not given
    assert changed.static == DEFAULT_SIZES['rigid', True][1]


@pytest.mark.parametrize('bearings, rigid_crank, sizes', [
    ('rigid', True, (4, 2)), ('flexible', True, (16, 2)), ('rigid', False, (8, 4)),
    ('flexible', False, (24, 2))])
def test_sizes_default_per_bearings_and_crank(bearings, rigid_crank, sizes):
    options = ModelOptions(bearings=bearings, rigid_crank=rigid_crank)
    assert (options.modes, options.static) == sizes


def test_given_sizes_are_kept_as_ints():
    options = ModelOptions(modes=5.0, static=0)
    assert options.modes == 5 and isinstance(options.modes, int) and options.static == 0


def test_cache_fields_keep_the_declaration_order_and_name_gravity_only_when_off():
    options = ModelOptions(grid_size=64)
    fields = options.cache_fields()
    # soft_modes is never in the key: the soft tables are made from the cached model
    names = [f.name for f in dataclasses.fields(ModelOptions) if f.name != 'soft_modes']
    optional = ('gravity', 'stiffness_damping', 'order', 'second_order')
    assert list(fields) == [n for n in names if n not in optional]
    assert fields['grid_size'] == 64
    # a model without gravity has other loads: its own key; the default's key is unchanged
    weightless = ModelOptions(gravity=False, grid_size=64).cache_fields()
    assert weightless['gravity'] is False and weightless != fields
    assert list(weightless) == [n for n in names if n not in optional[1:]]
    # order 1 (the default) leaves the key as before the field; order 2 is part of it
    assert list(ModelOptions(order=2).cache_fields()) == [
        n for n in names if n not in optional[:2] + optional[3:]]
    assert ModelOptions(speed_max=30.0).cache_fields() != ModelOptions().cache_fields()
    assert ModelOptions(soft_modes=0).cache_fields() == ModelOptions().cache_fields()


def test_stiffness_damping_is_in_the_cache_fields_only_when_set():
    # beta = 0 keeps the fields (and the cache keys) of the options before beta existed
    assert 'stiffness_damping' not in ModelOptions(stiffness_damping=0.0).cache_fields()
    fields = ModelOptions(stiffness_damping=1e-4).cache_fields()
    assert fields['stiffness_damping'] == 1e-4 and list(fields)[-1] == 'stiffness_damping'
    assert ModelOptions(stiffness_damping=1).stiffness_damping == 1.0


@pytest.mark.parametrize('changes', [
    {'bearings': 'springs'}, {'modes': 0}, {'static': -1}, {'grid_size': 7},
    {'speed_max': 0.0}, {'speed_max': -5.0}, {'speed_max': float('nan')},
    {'stiffness_damping': -1e-4}, {'stiffness_damping': float('nan')},
    {'stiffness_damping': float('inf')}, {'order': 0}, {'order': 3},
    {'order': 2, 'second_order': 'full'}, {'order': 1, 'second_order': 'dynamic'}])
def test_invalid_values_are_refused(changes):
    with pytest.raises(ValueError):
        ModelOptions(**changes)


def test_options_are_frozen():
    with pytest.raises(dataclasses.FrozenInstanceError):
        ModelOptions().modes = 3


def test_dynamic_second_order_has_its_sizes_and_key_and_quasi_static_keeps_both():
    quasi = ModelOptions(bearings='rigid', order=2)
    assert ModelOptions(bearings='rigid', order=2, second_order='quasi-static') == quasi
    assert 'second_order' not in quasi.cache_fields() and (quasi.modes, quasi.static) == (4, 2)
    dynamic = ModelOptions(bearings='rigid', order=2, second_order='dynamic')
    # the pass needs more directions: the measured 8 + 4 with rigid bearings and crank
    assert (dynamic.modes, dynamic.static) == DYNAMIC_SIZES['rigid', True] == (8, 4)
    assert dynamic.cache_fields()['second_order'] == 'dynamic'
    assert list(dynamic.cache_fields())[-1] == 'second_order'
    # sizes given are kept
    given = ModelOptions(bearings='rigid', order=2, second_order='dynamic', modes=6, static=3)
    assert (given.modes, given.static) == (6, 3)
    for key, (modes, static) in DEFAULT_SIZES.items():
        assert DYNAMIC_SIZES[key][0] >= modes and DYNAMIC_SIZES[key][1] >= max(static, 4)
