"""Periodic response of the reduced model."""

from flexlink_ros.core.integrators import RadauIIA
from flexlink_ros.core.reduction.build import reduce_samples
from flexlink_ros.core.reduction.model import system_blocks
from flexlink_ros.core.reduction.periodic import periodic_response
import numpy as np
from toy_system import toy_samples, ZETA


def test_periodic_response_is_periodic_and_matches_time_integration():
    samples = toy_samples()
    model = reduce_samples(samples, modes=4, static=1, speed_max=40.0, zeta=ZETA)
    speed = 35.0
    angles, q, v = periodic_response(model, speed, start_angle=0.4, steps=360)
    np.testing.assert_allclose(q[-1], q[0], atol=1e-9 * np.max(np.abs(q)))
    np.testing.assert_allclose(angles[-1] - angles[0], 2 * np.pi)
    # Integrating from rest for many revolutions converges to the same cycle.
    method = RadauIIA(2)
    h = (2 * np.pi / speed) / 360
    state_q, state_v = np.zeros(model.size), np.zeros(model.size)
    for i in range(360 * 40):
        stage_angles = 0.4 + speed * h * (i + method.c)
        rows = model.evaluate(stage_angles, speed, 0.0)
        state_q, state_v, _ = method.step(state_q, state_v, h,
                                          *system_blocks(model, rows))
    np.testing.assert_allclose(state_q, q[0], atol=1e-4 * np.max(np.abs(q)))
