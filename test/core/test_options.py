"""Modelling options (core/options.py): defaults, the full-model defaults, the cache key."""

import dataclasses

from flexlink_ros.core.options import DEFAULT_SIZES, ModelOptions
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


def test_cache_fields_exclude_gravity_and_keep_the_declaration_order():
    options = ModelOptions(gravity=False, grid_size=64)
    fields = options.cache_fields()
    names = [f.name for f in dataclasses.fields(ModelOptions)]
    assert list(fields) == [n for n in names if n not in ('gravity', 'order')]
    # order 1 (the default) leaves the key as before the field; order 2 is part of it
    assert list(ModelOptions(order=2).cache_fields()) == [n for n in names if n != 'gravity']
    assert 'gravity' not in fields and fields['grid_size'] == 64
    # gravity alone does not change the key; any other field does
    assert ModelOptions(gravity=True).cache_fields() == ModelOptions(gravity=False).cache_fields()
    assert ModelOptions(speed_max=30.0).cache_fields() != ModelOptions().cache_fields()


@pytest.mark.parametrize('changes', [
    {'bearings': 'springs'}, {'modes': 0}, {'static': -1}, {'grid_size': 7},
    {'speed_max': 0.0}, {'speed_max': -5.0}, {'speed_max': float('nan')}, {'order': 0},
    {'order': 3}])
def test_invalid_values_are_refused(changes):
    with pytest.raises(ValueError):
        ModelOptions(**changes)


def test_options_are_frozen():
    with pytest.raises(dataclasses.FrozenInstanceError):
        ModelOptions().modes = 3
