"""Monomials and periodic cubic splines over the grid cells."""

from flexlink_ros.core.reduction.cells import monomial_values, MONOMIALS
from flexlink_ros.core.reduction.cells import periodic_cell_coefficients
import numpy as np
import pytest
import scipy.interpolate


def test_periodic_cubic_spline_is_accurate_and_smooth():
    count = 64
    theta = 2 * np.pi * np.arange(count) / count
    values = np.stack([np.cos(3 * theta), np.sin(theta) ** 3], axis=1)
    coef = periodic_cell_coefficients(values)
    assert coef.shape == (count, 4, 2)
    np.testing.assert_allclose(coef[:, 0], values, atol=1e-14)        # nodes
    ends = coef.sum(axis=1)                                           # t = 1
    np.testing.assert_allclose(ends, np.roll(values, -1, axis=0), atol=1e-13)
    slopes_end = coef[:, 1] + 2 * coef[:, 2] + 3 * coef[:, 3]
    np.testing.assert_allclose(slopes_end, np.roll(coef[:, 1], -1, axis=0), atol=1e-12)
    mid = coef[:, 0] + coef[:, 1] / 2 + coef[:, 2] / 4 + coef[:, 3] / 8
    exact = np.stack([np.cos(3 * (theta + np.pi / count)),
                      np.sin(theta + np.pi / count) ** 3], axis=1)
    assert np.max(np.abs(mid - exact)) < 2e-5  # O(h^4) with h = 2 pi / 64


def scipy_cell_coefficients(values):
    """Per-cell coefficients from scipy's periodic CubicSpline (what the tables were made of)."""
    count = values.shape[0]
    closed = np.concatenate([values, values[:1]], axis=0)
    spline = scipy.interpolate.CubicSpline(np.arange(count + 1.0), closed, axis=0,
                                           bc_type='periodic')
    return np.moveaxis(spline.c[::-1], 0, 1)


@pytest.mark.parametrize('shape', [(3,), (8,), (32, 5), (128, 3, 4), (9, 2, 2, 2)])
def test_periodic_spline_has_the_bits_of_scipys(shape):
    rng = np.random.default_rng(sum(shape))
    values = rng.standard_normal(shape) * 10.0 ** rng.integers(-6, 6, shape)
    coef = periodic_cell_coefficients(values)
    expected = scipy_cell_coefficients(values)
    assert coef.shape == expected.shape
    np.testing.assert_array_equal(coef, expected)


def test_monomials_follow_their_names():
    w, a = 3.0, -2.0
    values = dict(zip(MONOMIALS, monomial_values(w, a)))
    assert values == {'a': a, '1': 1.0, 'w2': w ** 2, 'w': w, 'w4': w ** 4, 'wa': w * a,
                      'w3': w ** 3}
