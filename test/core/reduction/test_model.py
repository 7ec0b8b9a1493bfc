"""The reduced model's tables: arrays round trip, link shapes."""

from flexlink_ros.core.reduction.build import reduce_samples
from flexlink_ros.core.reduction.model import ReducedModel
import numpy as np
from toy_system import toy_samples, ZETA


def test_round_trip_through_arrays():
    model = reduce_samples(toy_samples(grid=16), modes=3, speed_max=20.0, zeta=ZETA)
    arrays, meta = model.to_arrays()
    again = ReducedModel.from_arrays(arrays, meta)
    np.testing.assert_array_equal(again.table, model.table)
    assert again.speed_max == model.speed_max and again.info == model.info
    assert model.nbytes > 0


def test_shapes_interpolate_positions_and_deflections():
    samples = toy_samples(grid=32)
    model = reduce_samples(samples, modes=3, speed_max=20.0, zeta=ZETA)
    q = np.array([1e-3, -2e-3, 5e-4])
    positions, deflections = model.shapes(2 * np.pi * 5 / 32, q)
    np.testing.assert_allclose(positions, samples.shape_positions[5], atol=1e-14)
    np.testing.assert_allclose(deflections, samples.shape_operator[5] @ model.basis @ q,
                               atol=1e-15)
