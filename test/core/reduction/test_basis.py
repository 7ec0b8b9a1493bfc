"""Constant POD basis of the frozen system."""

from flexlink_ros.core.reduction.basis import build_basis, frozen_modes
import numpy as np
from toy_system import toy_samples


def test_basis_is_mass_orthonormal_and_spans_frozen_modes():
    samples = toy_samples()
    basis, singular = build_basis(samples, modes=4, static=2, speeds=[0.0, 30.0])
    mass_ref = samples.mass.mean(axis=0)
    np.testing.assert_allclose(basis.T @ mass_ref @ basis, np.eye(6), atol=1e-10)
    assert np.all(np.diff(singular['modes']) <= 1e-12)
    # The two lowest frozen modes anywhere on the cycle (and between the sampled speeds)
    # lie in the basis to within a small mass-weighted residual.
    for k in range(0, samples.grid_size, 7):
        _, shapes = frozen_modes(samples.stiffness_at(k, 15.0), samples.mass[k], 2)
        for shape in shapes.T:
            residual = shape - basis @ (basis.T @ (mass_ref @ shape))
            assert np.sqrt(residual @ mass_ref @ residual) < 0.05
