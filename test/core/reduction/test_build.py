"""Reduced model built from full-order samples: tables, residual flexibility."""

from flexlink_ros.core.reduction.build import reduce_samples
from flexlink_ros.core.reduction.model import output_values, system_blocks
from flexlink_ros.core.reduction.periodic import periodic_response
import numpy as np
from toy_system import full_periodic_outputs, toy_samples, ZETA


def test_tables_reproduce_projected_matrices_at_grid_angles():
    samples = toy_samples()
    model = reduce_samples(samples, modes=4, static=1, speed_max=40.0, zeta=ZETA)
    basis = model.basis
    layout = model.layout
    w, a = 23.0, -7.0
    for k in (0, 5, 31):
        theta = 2 * np.pi * k / samples.grid_size
        rows = model.evaluate(theta, w, a)
        mass, damping, stiffness, load = (b[0] for b in system_blocks(model, rows))
        np.testing.assert_allclose(mass, basis.T @ samples.mass[k] @ basis, atol=1e-15)
        np.testing.assert_allclose(stiffness, basis.T @ samples.stiffness_at(k, w, a) @ basis,
                                   rtol=1e-10, atol=1e-9)
        np.testing.assert_allclose(load, samples.load_at(k, w, a) @ basis, atol=1e-15)
        exact_damping = w * basis.T @ samples.gyroscopic[k] @ basis \
            + basis.T @ samples.damping(k, w) @ basis
        # The damping is fitted in w^2 through 4 speeds: close, not exact, between them.
        assert np.max(np.abs(damping - exact_damping)) < 1e-3 * np.max(np.abs(exact_damping))
        np.testing.assert_allclose(layout.block(rows, 'out')[0], samples.outputs[k] @ basis,
                                   atol=1e-14)


def test_residual_correction_restores_the_static_outputs():
    samples = toy_samples()
    model = reduce_samples(samples, modes=2, static=0, speed_max=40.0, zeta=ZETA)
    for k in (3, 17):
        theta = 2 * np.pi * k / samples.grid_size
        rows = model.evaluate(theta, 0.0, 0.0)
        _, _, stiffness, load = (b[0] for b in system_blocks(model, rows))
        q = np.linalg.solve(stiffness, load)
        exact = samples.outputs[k] @ np.linalg.solve(samples.stiffness['1'][k],
                                                     samples.load['1'][k])
        truncated = samples.outputs[k] @ model.basis @ q
        corrected = output_values(model, rows, q[None])[0]
        np.testing.assert_allclose(corrected, exact, rtol=1e-9, atol=1e-15)
        assert np.max(np.abs(truncated - exact)) > 1e-3 * np.max(np.abs(exact))


def test_truncated_model_approaches_the_full_response():
    samples = toy_samples()
    speed = 30.0
    _, exact = full_periodic_outputs(samples, speed, steps=360)
    errors = []
    for modes in (2, 4, 6):
        model = reduce_samples(samples, modes=modes, static=1, speed_max=40.0, zeta=ZETA)
        angles, q, _ = periodic_response(model, speed, steps=360)
        out = output_values(model, model.evaluate(angles, speed, 0.0), q)
        errors.append(np.sqrt(np.mean((out - exact) ** 2) / np.mean(exact ** 2)))
    assert errors[-1] < errors[0]
    assert errors[-1] < 0.01, errors
