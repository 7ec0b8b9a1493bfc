"""
The joint reactions and Earles-Wu criteria of many estimated rows at once (the offline run).

The same tabulated quantities as the streaming step's per-sample criteria
(:func:`.step.joint_criteria`), vectorised over rows.
"""

import numpy as np

from .step import REACTION_FLOOR_FRACTION
from .streaming import DEFAULT_NEAR_ZERO_FRACTION
from ...names import JOINT_NAMES


def criteria_batch(model, angles, speeds, accels,
                   near_zero_fraction=DEFAULT_NEAR_ZERO_FRACTION, blocks=None):
    """
    Compute joint reactions, direction rates and Earles-Wu criteria at many crank states.

    The same tabulated quantities as StreamingEstimator._criteria, vectorised.

    Parameters
    ----------
    model : ReducedModel
        The model (its joint-reaction tables).
    angles, speeds, accels : ndarray, shape (m,)
        Crank state as the model sees it (speed and acceleration clipped).
    near_zero_fraction : float
        A reaction below this fraction of its cycle RMS is flagged near zero.
    blocks : dict, optional
        'force', 'force_dot' (m, joints, 2) and 'rms2' (m, joints) at these states, if
        already evaluated (core.estimation.segment_replay.replay returns them); else the table is
        evaluated.

    Returns
    -------
    reaction_n, gamma_dot, criterion : ndarray, shape (m, 4)
    near_zero : ndarray of bool, shape (m, 4)
    available : bool
        False if the model has no joint-reaction data (all zeros then).

    """
    count = len(angles)
    zeros = np.zeros((count, len(JOINT_NAMES)))
    if not np.any(model.force_moments):
        return zeros, zeros, zeros, zeros.astype(bool), False
    if blocks is None:
        rows = model.evaluate(angles, speeds, accels)
        blocks = {name: model.layout.block(rows, name)
                  for name in ('force', 'force_dot', 'rms2')}
    force, rate, rms2 = blocks['force'], blocks['force_dot'], blocks['rms2']
    r2 = np.sum(force ** 2, axis=2)
    # Below REACTION_FLOOR_FRACTION of the cycle RMS the reaction is clamped (finite criterion).
    clamped = np.maximum(r2, REACTION_FLOOR_FRACTION ** 2 * rms2)
    positive = clamped > 0.0
    safe = np.where(positive, clamped, 1.0)
    gamma_dot = np.where(positive, (force[..., 0] * rate[..., 1]
                                    - force[..., 1] * rate[..., 0]) / safe, 0.0)
    criterion = np.where(positive, np.abs(gamma_dot) / np.sqrt(safe), 0.0)
    reaction = np.where(positive, np.sqrt(r2), 0.0)
    return reaction, gamma_dot, criterion, r2 < near_zero_fraction ** 2 * rms2, True
