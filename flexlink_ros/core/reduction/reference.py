"""
Full-order reference response of a mechanism, the reduced model's yardstick.

:func:`reference_response` is core/fe/simulate.py's full-order shooting at given crank angles
(its test checks the reduced model's tables with every DOF kept, integrated as the reduced
model is, against it).
"""

import dataclasses

import numpy as np

from .cells import CELL_POWERS, periodic_cell_coefficients
from .mechanism_model import fe_mechanism
from ..fe import linkage as assembly
from ..fe import simulate
from ..fe.second_order_full import corrected_response

# Grid points and steps per revolution of the full-order reference.
REFERENCE_GRID = 256
REFERENCE_STEPS = 1440
REFERENCE_POINT_STRIDE = 4
_REFERENCE_CACHE = {}


def reference_response(mechanism, options, speed, angles, steps=REFERENCE_STEPS):
    """
    Full-order periodic response at constant crank speed, at given crank angles.

    The reference is core/fe/simulate.py's full-order shooting (every FE DOF, coefficient
    matrices assembled at every Radau stage) with ``steps`` steps and one output per
    REFERENCE_POINT_STRIDE steps, interpolated to ``angles`` by a periodic cubic spline.
    Where core/fe/simulate.py is not in the checkout, the same equations are solved here without
    reduction (identity basis, tables on a REFERENCE_GRID-point grid): the two agree to
    4e-5 (flexible bearings) and 1e-6 (rigid) relative RMS at 269 and 391 rpm.

    Parameters
    ----------
    mechanism : Mechanism
        The linkage.
    options : ModelOptions
        Only the physical options (elements, rigid crank, bearings, geometric stiffness) and
        the order (2: plus the second-order outputs of the full-order response,
        :func:`core.fe.second_order_full.corrected_response`).
    speed : float
        Crank speed [rad/s], non-zero.
    angles : ndarray, shape (m,)
        Crank angles [rad].
    steps : int
        Steps per revolution.

    Returns
    -------
    dict
        'lever_tip', 'coupler_mid': ndarray (m, 2) [m]; 'source': str.

    """
    key = (mechanism.key(), dataclasses.astuple(options), float(speed), steps)
    if key not in _REFERENCE_CACHE:
        _REFERENCE_CACHE.clear()
        _REFERENCE_CACHE[key] = _reference_revolution(mechanism, options, speed, steps)
    outputs, source = _REFERENCE_CACHE[key]
    points = outputs.shape[0]
    coef = periodic_cell_coefficients(outputs)
    phase = np.mod(np.asarray(angles, dtype=float) * np.sign(speed), 2.0 * np.pi) \
        / (2.0 * np.pi) * points
    k = np.minimum(np.floor(phase).astype(int), points - 1)
    t = phase - k
    values = np.einsum('mp,mpc->mc', t[:, None] ** np.arange(CELL_POWERS), coef[k])
    return {'lever_tip': values[:, :2], 'coupler_mid': values[:, 2:], 'source': source}


def _reference_revolution(mechanism, options, speed, steps):
    """Return the outputs (points, 4) over one revolution from crank angle 0, and their source."""
    linkage = assembly.FlexibleLinkage(fe_mechanism(mechanism, options), options)
    result = simulate.periodic_response(linkage, speed, method='full', steps=steps,
                                        points=steps // REFERENCE_POINT_STRIDE)
    if options.order == 2:
        return corrected_response(linkage, result)['total'], 'core.simulate full order + 2nd'
    return result.outputs, 'core.simulate full order'
