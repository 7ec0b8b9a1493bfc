"""Modelling options (core/options.py): defaults, the full-model defaults, the cache key."""

import dataclasses

import math

from flexlink_ros.core.options import (DEFAULT_SIZES, DEFAULT_SPEED_MAX, DYNAMIC_SIZES,
                                       ModelOptions, SPEED_MARGIN, speed_range)
import pytest


def test_defaults_are_the_nodes_flexible_crank_flexible_bearings_and_order_2():
    options = ModelOptions()
    assert options.rigid_crank is False and options.bearings == 'flexible'
    assert (options.modes, options.static) == DEFAULT_SIZES['flexible', False] == (24, 2)
    assert options.grid_size == 128 and options.elements_per_link == 4
    assert options.geometric_stiffness is True and options.gravity is True
    assert options.speed_max == DEFAULT_SPEED_MAX == 65.0 and options.order == 2


def test_linear_is_the_papers_linear_model_on_the_files_elements():
    options = ModelOptions.linear()
    assert (options.rigid_crank, options.elements_per_link, options.order) == (True, None, 1)
    assert (options.modes, options.static) == DEFAULT_SIZES['flexible', True] == (16, 2)
    assert ModelOptions.linear(order=2, bearings='rigid').order == 2


def test_speed_range_takes_the_asked_range_else_the_files_speed_with_a_margin():
    assert speed_range() == speed_range(None, 0.0) == DEFAULT_SPEED_MAX
    # a slow machine keeps the default range (and the default model's cache key)
    assert speed_range(200.0 * math.pi / 30.0) == DEFAULT_SPEED_MAX
    assert speed_range(3000.0 * math.pi / 30.0) == pytest.approx(
        SPEED_MARGIN * 3000.0 * math.pi / 30.0)
    assert speed_range(3000.0 * math.pi / 30.0, 700.0) == pytest.approx(700.0 * math.pi / 30)


def test_full_model_is_flexible_crank_on_pins_and_keeps_changes():
    options = ModelOptions.full_model()
    assert options.rigid_crank is False and options.bearings == 'rigid'
    assert (options.modes, options.static) == (8, 4)
    assert options.elements_per_link is None and options.order == 1
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
    options = ModelOptions.linear(grid_size=64)
    fields = options.cache_fields()
    # soft_modes is never in the key: the soft tables are made from the cached model
    names = [f.name for f in dataclasses.fields(ModelOptions) if f.name != 'soft_modes']
    optional = ('gravity', 'stiffness_damping', 'order', 'second_order')
    assert list(fields) == [n for n in names if n not in optional]
    assert fields['grid_size'] == 64
    # a model without gravity has other loads: its own key; the default's key is unchanged
    weightless = ModelOptions.linear(gravity=False, grid_size=64).cache_fields()
    assert weightless['gravity'] is False and weightless != fields
    assert list(weightless) == [n for n in names if n not in optional[1:]]
    # order 1 (the default) leaves the key as before the field; order 2 is part of it
    assert list(ModelOptions.linear(order=2).cache_fields()) == [
        n for n in names if n not in optional[:2] + optional[3:]]
    assert (ModelOptions.linear(speed_max=30.0).cache_fields()
            != ModelOptions.linear().cache_fields())
    assert ModelOptions.linear(soft_modes=0).cache_fields() == ModelOptions.linear().cache_fields()


def test_stiffness_damping_is_in_the_cache_fields_only_when_set():
    # beta = 0 keeps the fields (and the cache keys) of the options before beta existed
    assert 'stiffness_damping' not in ModelOptions(stiffness_damping=0.0).cache_fields()
    fields = ModelOptions.linear(stiffness_damping=1e-4).cache_fields()
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
    quasi = ModelOptions.linear(bearings='rigid', order=2)
    assert ModelOptions.linear(bearings='rigid', order=2,
                               second_order='quasi-static') == quasi
    assert 'second_order' not in quasi.cache_fields() and (quasi.modes, quasi.static) == (4, 2)
    dynamic = ModelOptions.linear(bearings='rigid', order=2, second_order='dynamic')
    # the pass needs more directions: the measured 8 + 4 with rigid bearings and crank
    assert (dynamic.modes, dynamic.static) == DYNAMIC_SIZES['rigid', True] == (8, 4)
    assert dynamic.cache_fields()['second_order'] == 'dynamic'
    assert list(dynamic.cache_fields())[-1] == 'second_order'
    # sizes given are kept
    given = ModelOptions.linear(bearings='rigid', order=2, second_order='dynamic',
                                modes=6, static=3)
    assert (given.modes, given.static) == (6, 3)
    for key, (modes, static) in DEFAULT_SIZES.items():
        assert DYNAMIC_SIZES[key][0] >= modes and DYNAMIC_SIZES[key][1] >= max(static, 4)
