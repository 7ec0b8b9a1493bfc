"""``flexlink plan`` (studies/plan.py): candidates, the scene, physics keys and shared signals."""

import dataclasses
import math

from flexlink_ros.core.mechanism_file import load_mechanism
from flexlink_ros.core.options import ModelOptions
from flexlink_ros.studies import plan
from flexlink_ros.studies.plan import physics_key, PlanSignals
import numpy as np
import pytest


@pytest.fixture(scope='module')
def cho():
    return load_mechanism('cho1992')


def test_size_candidates_run_from_small_to_large():
    base = ModelOptions.linear(bearings='rigid')
    candidates = plan.plan_candidates(base)
    assert len(candidates) == len(plan.PLAN_MODES) * len(plan.PLAN_STATIC) * len(plan.PLAN_GRIDS)
    keys = [(o.modes + o.static, o.grid_size) for o in candidates]
    assert keys == sorted(keys)
    assert (candidates[0].modes, candidates[0].static, candidates[0].grid_size) == (2, 0, 64)
    assert (candidates[-1].modes, candidates[-1].static, candidates[-1].grid_size) == (24, 4, 256)
    assert all(o.bearings == 'rigid' for o in candidates)     # the physics is kept


def test_scene_is_the_richest_model_of_the_users_bearings(cho):
    scene = plan.scene_options(cho, ModelOptions.linear(bearings='rigid'))
    assert scene.elements_per_link == 2 * cho.elements_per_link
    assert scene.rigid_crank is False and scene.geometric_stiffness is True
    assert scene.bearings == 'rigid'
    given = plan.scene_options(cho, ModelOptions.linear(elements_per_link=5,
                                                        geometric_stiffness=False))
    assert given.elements_per_link == 5 and given.geometric_stiffness is True


def test_full_order_dofs_grow_by_an_interior_node_per_link_and_element(cho):
    def dofs(elements, rigid_crank):
        return plan.full_order_dofs(cho, ModelOptions.full_model(elements_per_link=elements,
                                                                 rigid_crank=rigid_crank))
    # one more element per link: one more interior node (u, v, phi) on each flexible link
    assert dofs(3, False) - dofs(2, False) == 9
    assert dofs(3, True) - dofs(2, True) == 6
    assert plan.full_order_dofs(None, ModelOptions.linear()) is None


def test_physics_candidates_are_cheapest_first_and_end_with_the_scene(cho):
    scene = plan.scene_options(cho, ModelOptions.linear(bearings='flexible'))
    candidates = plan.physics_candidates(cho, ModelOptions.linear(bearings='flexible'), scene)
    assert candidates[-1] == scene
    costs = [plan.full_order_dofs(cho, o) for o in candidates[:-1]]
    assert costs == sorted(costs)
    assert any(o.bearings == 'rigid' for o in candidates)          # the other bearing model
    assert all(o.elements_per_link < scene.elements_per_link for o in candidates[:-1])


def test_describe_physics():
    options = dataclasses.replace(ModelOptions.full_model(), elements_per_link=4)
    assert plan.describe_physics(options) == '4 el, flex crank, GS on, rigid bearings'


def test_physics_key_ignores_the_reduced_size():
    base = ModelOptions.linear(bearings='rigid', elements_per_link=4)
    assert physics_key(base) == physics_key(ModelOptions.linear(
        bearings='rigid', elements_per_link=4, modes=12, static=0, grid_size=64, speed_max=30.0))
    for changed in (ModelOptions.linear(bearings='flexible', elements_per_link=4),
                    ModelOptions.linear(bearings='rigid', elements_per_link=3),
                    ModelOptions.linear(bearings='rigid', elements_per_link=4, rigid_crank=False),
                    ModelOptions.linear(bearings='rigid', elements_per_link=4,
                                        geometric_stiffness=False)):
        assert physics_key(changed) != physics_key(base)


def test_signals_are_two_revolutions_with_the_last_one_marked():
    signals = PlanSignals(load_mechanism('cho1992'), [269.0, 391.0], 500.0)
    assert list(signals.signals) == [269.0, 391.0]
    for rpm, (stamps, angles, speeds, mask) in signals.signals.items():
        speed = rpm * 2.0 * math.pi / 60.0
        assert np.allclose(speeds, speed, rtol=1e-15) and np.all(np.diff(angles) > 0.0)
        assert 4.0 * math.pi - 2.0 * speed / 500.0 < np.ptp(angles) <= 4.0 * math.pi + 1e-9
        assert mask[-1] and not mask[0]
        assert np.ptp(angles[mask]) < 2.0 * math.pi <= np.ptp(angles[mask]) + speed / 500.0
    assert signals.references == {} and signals.reference_seconds(ModelOptions.linear()) == 0


def test_the_quick_plan_sizes_the_reduction_against_the_files_own_physics(cho):
    base = ModelOptions.linear(bearings='rigid', elements_per_link=8)
    quick = plan.quick_plan(cho, base, 391.0, fixed={'rigid_crank': True})
    scene = quick['scene']
    assert scene.elements_per_link == cho.elements_per_link       # not refined
    assert scene.rigid_crank is False and scene.geometric_stiffness is True
    assert scene.bearings == 'rigid'
    assert quick['speeds_rpm'] == [391.0] and quick['grids'] == plan.QUICK_GRIDS
    assert [physics_key(o) for o in quick['physics']] == [
        physics_key(dataclasses.replace(scene, rigid_crank=True))]     # the user's fixed crank
    sizes = plan.plan_candidates(scene, quick['grids'])
    assert {o.grid_size for o in sizes} == set(plan.QUICK_GRIDS)
    assert plan.size_steps(sizes) < plan.size_steps(plan.plan_candidates(scene)) / 2
