"""
Warn and error thresholds of the Earles-Wu criterion for any machine, from its own cycle.

The criterion |gamma_dot / R| [rad/(s N)] of a joint (:mod:`core.criteria`) is how fast the
joint's reaction turns per newton that holds the pin against the bearing: where it is large
the pin crosses the clearance (contact loss, impact) more easily. Its size depends on the
machine (masses, speed, loads): the paper's 100 / 1000 rad/(s N) mean nothing for another
linkage, so :func:`suggest_thresholds` takes them from the mechanism's own healthy cycle at
its speed: WARN at :data:`WARN_MARGIN` times the cycle's true maximum over the joints,
ERROR at :data:`ERROR_FACTOR` times it. A WARN then says the joint left anything the design
cycle shows (a faster crank, a changed load, a lost spring); an ERROR that it is far beyond.

The true maxima are refined (:func:`core.criteria.evaluate_criteria`); the node sees the
cycle only at its samples, so the maxima sampled at the input rate are reported beside them
(they can only be lower). A joint whose reaction nearly vanishes in the cycle (its minimum
below :data:`VANISHING_FRACTION` of its RMS) has a criterion peak set only by how close R
comes to zero (a degree wide, thousands of times the others): that joint is at risk of
contact loss in the healthy cycle itself. It is named, and left out of the thresholds (which
it would make blind for the other joints); the node will flag it when its samples meet the
peak, which is the truth about that joint.
"""

import math

import numpy as np

from .criteria import criterion_curves, evaluate_criteria
from ..names import JOINT_NAMES

WARN_MARGIN = 1.5      # WARN above the healthy cycle's maximum by half again
ERROR_FACTOR = 3.0     # ERROR at three times it
VANISHING_FRACTION = 0.01   # a reaction whose minimum is below 1 % of its RMS nearly vanishes


def sampled_maxima(mechanism, crank_speed, rate_hz, revolutions=1):
    """
    Return each joint's largest criterion among samples at ``rate_hz`` [rad/(s N)].

    Parameters
    ----------
    mechanism : Mechanism
        The linkage.
    crank_speed : float
        [rad/s].
    rate_hz : float
        Sample rate of the crank's JointState.
    revolutions : int
        Revolutions sampled (the samples of later revolutions fall between the first's).

    """
    period = 2.0 * math.pi / abs(crank_speed)
    count = min(int(math.ceil(revolutions * period * rate_hz)), 10 ** 6)
    angles = np.mod(crank_speed * np.arange(count) / rate_hz, 2.0 * math.pi)
    ratio = criterion_curves(mechanism, angles, crank_speed)['ratio']
    return dict(zip(JOINT_NAMES, ratio.max(axis=1).tolist()))


def suggest_thresholds(mechanism, crank_speed, rate_hz=1000.0):
    """
    Derive the node's criterion thresholds from the mechanism's cycle at ``crank_speed``.

    Parameters
    ----------
    mechanism : Mechanism
        The linkage (with its spring, if any).
    crank_speed : float
        The machine's crank speed [rad/s].
    rate_hz : float
        The input's sample rate (for the sampled maxima).

    Returns
    -------
    dict
        'warn', 'error' [rad/(s N)], 'basis' (the largest true maximum they are made from),
        'joints' (per joint: 'true_max', 'sampled_max', 'min_over_rms' (the reaction's
        minimum over its RMS), 'used' (False where the reaction nearly vanishes)),
        'warn_margin', 'error_factor', 'rpm', 'rate_hz'.

    """
    found = evaluate_criteria(mechanism, crank_speed)
    sampled = sampled_maxima(mechanism, crank_speed, rate_hz)
    joints = {j: {'true_max': c.max_ratio, 'sampled_max': sampled[j],
                  'min_over_rms': c.min_force / c.rms_force,
                  'used': c.min_force >= VANISHING_FRACTION * c.rms_force}
              for j, c in found.items()}
    used = [v['true_max'] for v in joints.values() if v['used']] or \
        [v['true_max'] for v in joints.values()]
    basis = max(used)
    return {'warn': WARN_MARGIN * basis, 'error': ERROR_FACTOR * basis, 'basis': basis,
            'joints': joints, 'warn_margin': WARN_MARGIN, 'error_factor': ERROR_FACTOR,
            'rpm': crank_speed * 30.0 / math.pi, 'rate_hz': rate_hz}
