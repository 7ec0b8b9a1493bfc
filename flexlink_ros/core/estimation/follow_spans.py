"""
The nonlinear follower over spans of a recording at once, each started a warm-up earlier.

:class:`.nonlinear_follow.NonlinearFollower` is sequential in time: each step starts from the
last one's state. The model is damped, so the state's memory of where it started fades: a
follower started a warm-up span before a span's first sample (at its quasi-static deflection,
as after a gap) reaches, by that sample, the state of the follower that ran from the start, to
rounding. :func:`warm_up_s` takes the warm-up from the model's slowest decay rate
(:func:`slowest_decay_rate`: the least damped frozen mode over the crank-angle grid), long
enough that a start as far off as the whole deflection range has faded below ``tolerance`` of
it. Spans of a recording can then be followed in parallel threads (the compiled step releases
the GIL; :func:`follow_span` is one span's work) with the same outputs and counts as one
follower, to rounding; a gap in the warm-up restarts both alike.
"""

import math

import numpy as np

from .nonlinear_follow import NonlinearFollower
from .nonlinear_stream import linear_part

# The fraction of the deflection range a start's error fades to over the warm-up.
WARM_UP_TOLERANCE = 1e-12


def slowest_decay_rate(tables, speeds):
    """
    Return the smallest decay rate [1/s] of the model's frozen modes, over the angle grid.

    The linear part of the model (:func:`.nonlinear_stream.linear_part`, the deflection's own
    stiffening left out) at every grid angle and each crank speed of ``speeds`` [rad/s]: the
    least ``-Re(lambda)`` of ``M x'' + C x' + K x = 0``.
    """
    theta = 2.0 * math.pi * np.arange(tables.grid_size) / tables.grid_size
    fields = tables.at(theta)
    return min(least_decay_rate(*linear_part(tables, fields, np.full(theta.size, speed),
                                             0.0)[:3])
               for speed in speeds)


def least_decay_rate(mass, damping, stiffness):
    """
    Return the least ``-Re(lambda)`` [1/s] of ``M x'' + C x' + K x = 0`` over a stack.

    ``mass``, ``damping``, ``stiffness``: (n, r, r), one frozen system per row.
    """
    size = mass.shape[-1]
    state = np.zeros((mass.shape[0], 2 * size, 2 * size))
    state[:, :size, size:] = np.eye(size)
    state[:, size:, :size] = -np.linalg.solve(mass, stiffness)
    state[:, size:, size:] = -np.linalg.solve(mass, damping)
    return float(np.min(-np.linalg.eigvals(state).real))


def warm_up_s(tables, speed_max, reset_gap_s, tolerance=WARM_UP_TOLERANCE):
    """
    Return the warm-up [s] after which a follower's start has faded below ``tolerance``.

    :func:`warm_up_for_rate` of :func:`slowest_decay_rate` at rest and at ``speed_max``
    [rad/s].
    """
    return warm_up_for_rate(slowest_decay_rate(tables, (0.0, speed_max)), reset_gap_s,
                            tolerance)


def warm_up_for_rate(rate, reset_gap_s, tolerance=WARM_UP_TOLERANCE):
    """
    Return ``ln(1 / tolerance)`` over the decay ``rate`` [1/s]: a start's error faded by then.

    At least twice ``reset_gap_s``, so that a span with no sample in its warm-up starts after
    a gap the sequential follower restarts at too. Infinite for a model that does not decay.
    """
    if not rate > 0.0:
        return math.inf
    return max(math.log(1.0 / tolerance) / rate, 2.0 * reset_gap_s)


def follow_span(tables, reset_gap_s, warm_up, span, follows_samples):
    """
    Follow one span's accepted samples after its warm-up; its outputs and what it counted.

    Parameters
    ----------
    tables : NonlinearTables
        The reduced nonlinear model.
    reset_gap_s : float
        The follower's reset gap.
    warm_up : tuple of ndarray or None
        (stamps [ns], angles, speeds) of the accepted samples of the warm-up before the span
        (None: the span starts the recording).
    span : tuple of ndarray
        (stamps [ns], angles, speeds) of the span's accepted samples.
    follows_samples : bool
        Accepted samples came before the warm-up: a span whose warm-up has none starts again
        after a gap (its first sample is a restart, as in one sequential follower).

    Returns
    -------
    outputs : ndarray, shape (K, channels)
    follower : NonlinearFollower
        Its ``counts`` and ``slope_max`` over the span's samples alone; ``validity`` and
        ``last`` after the span's last sample.

    """
    follower = NonlinearFollower(tables, reset_gap_s)
    warmed = warm_up is not None and len(warm_up[0]) > 0
    if warmed:
        follower.follow(*warm_up)
    follower.counts = dict.fromkeys(follower.counts, 0)     # the span's own
    follower.slope_max = 0.0
    outputs = follower.follow(*span)
    if not warmed and follows_samples and len(span[0]):
        # No sample for a warm-up (longer than the reset gap): one follower restarts here.
        follower.counts['restarts'] += 1
    return outputs, follower


__all__ = ['WARM_UP_TOLERANCE', 'slowest_decay_rate', 'least_decay_rate', 'warm_up_s',
           'warm_up_for_rate', 'follow_span']
