"""The step's tables (core/estimation/tables.py): Hermite node tables read back, their sizes."""

import math

import estimation_toys as toys
from flexlink_ros.core.estimation import tables
from flexlink_ros.core.reduction import model as reduced
import numpy as np
import pytest


@pytest.fixture(scope='module')
def toy_model():
    return toys.toy_model()


def test_hermite_basis_interpolates_values_and_slopes_of_a_cubic():
    assert tables.hermite_basis(0.0) == (1.0, 0.0, 0.0, 0.0)
    assert tables.hermite_basis(1.0) == (0.0, 0.0, 1.0, 0.0)
    t = np.linspace(0.0, 1.0, 11)
    h00, h10, h01, h11 = tables.hermite_basis(t)
    assert np.allclose(h00 + h01, 1.0)
    # p(t) = 2 - t + 3 t^2 - 5 t^3: p(0) = 2, p'(0) = -1, p(1) = -1, p'(1) = -1 + 6 - 15
    cubic = 2.0 - t + 3.0 * t ** 2 - 5.0 * t ** 3
    assert np.allclose(2.0 * h00 - h10 - h01 - 10.0 * h11, cubic, rtol=0, atol=1e-14)


def test_system_blocks_from_the_step_tables_are_the_models(toy_model):
    """The Hermite node tables give back the model's power-form cubics, in every cell."""
    step = tables.step_tables(toy_model)
    assert step.mass.shape[0] == toy_model.grid_size
    theta = np.concatenate([np.linspace(-2.0, 9.0, 23), [0.0, 2.0 * math.pi - 1e-9]])
    ours = tables.system_blocks(toy_model, step, theta, 30.0, -4.0)
    theirs = reduced.system_blocks(toy_model, toy_model.evaluate(theta, 30.0, -4.0))
    # M and C are kept in float32 (6e-8 per entry), K and f in float64
    for mine, model, rtol in zip(ours, theirs, (1e-6, 1e-6, 1e-12, 1e-12)):
        assert mine.shape == model.shape
        np.testing.assert_allclose(mine, model, rtol=rtol, atol=rtol * np.abs(model).max())


def test_quasi_static_peak_is_the_largest_static_deflection_on_the_grid(toy_model):
    step = tables.step_tables(toy_model)
    theta = 2.0 * math.pi * np.arange(toy_model.grid_size) / toy_model.grid_size
    peak = 0.0
    for speed in np.linspace(0.0, toy_model.speed_max, tables.QUASI_STATIC_SPEEDS):
        rows = toy_model.evaluate(theta, speed, 0.0)
        _, _, stiffness, load = reduced.system_blocks(toy_model, rows)
        q = np.linalg.solve(stiffness, load[..., None])[..., 0]
        peak = max(peak, np.abs(reduced.output_values(toy_model, rows, q)).max())
    assert peak > 0.0
    assert tables.quasi_static_peak(toy_model, step) == pytest.approx(peak, rel=1e-9)


def test_step_coefficients_have_one_stack_per_slot_parity():
    stack = tables.build_step_coefficients()
    assert stack.shape == (2, len(tables.POWERS), 64)
    # the two parities hold the same coefficients in swapped slots
    assert np.allclose(np.sort(stack[0], axis=None), np.sort(stack[1], axis=None))
    assert not np.allclose(stack[0], stack[1])
