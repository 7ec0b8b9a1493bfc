"""
Tabulation over the cells of a periodic crank-angle grid: monomials and cubic splines.

Every tabulated quantity of the reduced model is a periodic cubic spline in theta; per grid
cell it is stored as the coefficients of ``t^p`` (t in [0, 1) across the cell) times each
monomial of :data:`MONOMIALS`.

The spline is scipy's ``CubicSpline(..., bc_type='periodic')`` on unit knot spacing, written
out with ``scipy.linalg.solve_banded`` (the same steps in the same order, so the same bits):
``scipy.interpolate`` would add about 25 MB to the node's resident size.
"""

import numpy as np
import scipy   # scipy.linalg loads on first use: a replay from the cache never needs it

# Monomials of (w, a) that multiply the tabulated pieces, in table-row order ('w4': damping
# fit; 'wa', 'w3': time derivative of the joint reactions).
# The order puts each matrix block's monomials next to each other (K: a, 1, w2; M: 1;
# C: 1, w2, w, w4), so the streaming step reads only the rows a block uses.
MONOMIALS = ('a', '1', 'w2', 'w', 'w4', 'wa', 'w3')
# Polynomial degree of the spline in each cell (cubic).
CELL_POWERS = 4


def monomial_values(w, a):
    """
    Evaluate :data:`MONOMIALS` at a speed and an acceleration.

    Parameters
    ----------
    w : float or ndarray
        Crank speed [rad/s].
    a : float or ndarray
        Crank acceleration [rad/s^2].

    Returns
    -------
    tuple of float
        One value per monomial.

    """
    w2 = w * w
    return (a, 1.0, w2, w, w2 * w2, w * a, w2 * w)


def _periodic_slopes(closed):
    """
    Knot slopes of the periodic cubic spline through ``closed`` (unit spacing, rows 2-D).

    The cyclic tridiagonal system is condensed to a tridiagonal one and a rank-one correction,
    as ``scipy.interpolate.CubicSpline`` does for ``bc_type='periodic'``.
    """
    n = closed.shape[0]
    slope = np.diff(closed, axis=0)
    banded = np.zeros((3, n))
    banded[1, 1:-1] = 4.0
    banded[0, 2:] = 1.0
    banded[-1, :-2] = 1.0
    rhs = np.empty_like(closed)
    rhs[1:-1] = 3 * (slope[:-1] + slope[1:])
    banded = banded[:, 0:-1]
    banded[1, 0] = 4.0
    banded[0, 1] = 1.0
    rhs = rhs[:-1]
    rhs[0] = 3 * (slope[-1] + slope[0])
    rhs[-1] = 3 * (slope[-2] + slope[-1])
    condensed = banded[:, :-1]
    first = rhs[:-1]
    second = np.zeros_like(first)
    second[0] = -1.0
    second[-1] = -1.0
    s1 = scipy.linalg.solve_banded((1, 1), condensed, first, overwrite_ab=False,
                                   overwrite_b=False, check_finite=False)
    s2 = scipy.linalg.solve_banded((1, 1), condensed, second, overwrite_ab=False,
                                   overwrite_b=False, check_finite=False)
    last = (rhs[-1] - 1.0 * s1[0] - 1.0 * s1[-1]) / (4.0 + 1.0 * s2[0] + 1.0 * s2[-1])
    slopes = np.empty_like(closed)
    slopes[:-2] = s1 + last * s2
    slopes[-2] = last
    slopes[-1] = slopes[0]
    return slopes, slope


def periodic_cell_coefficients(values):
    """
    Per-cell coefficients of the periodic cubic spline through samples on a uniform grid.

    Parameters
    ----------
    values : ndarray, shape (N, ...)
        Samples at theta_k = 2 pi k / N (N >= 3).

    Returns
    -------
    ndarray, shape (N, 4, ...)
        ``c[k, p]`` such that the spline on cell k is ``sum_p c[k, p] t^p``, t in [0, 1).

    """
    values = np.asarray(values, dtype=float)
    count = values.shape[0]
    closed = np.concatenate([values, values[:1]], axis=0).reshape(count + 1, -1)
    slopes, slope = _periodic_slopes(closed)
    # Cubic Hermite form on each cell of width 1 (scipy's CubicHermiteSpline).
    cubic = slopes[:-1] + slopes[1:] - 2 * slope
    coef = np.stack((closed[:-1], slopes[:-1], (slope - slopes[:-1]) - cubic, cubic), axis=1)
    return coef.reshape((count, CELL_POWERS) + values.shape[1:])
