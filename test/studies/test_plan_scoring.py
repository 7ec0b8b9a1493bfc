"""How ``plan`` scores a candidate (studies/plan_scoring.py): physics keys and shared signals."""

import math

from flexlink_ros.core.mechanism_file import load_mechanism
from flexlink_ros.core.options import ModelOptions
from flexlink_ros.studies.plan_scoring import physics_key, PlanSignals
import numpy as np


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
