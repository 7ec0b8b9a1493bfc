"""
The linear estimate of a recording in two parts at once: where to cut, and the warm-up.

The estimator's state (the modal coordinates and the crank filter's fit) forgets where it
started: both are damped. A second estimate started a warm-up before a row (as after a gap, at
the first sample of the warm-up) reaches, by that row, the state of the estimate that ran from
the recording's start, to ``tolerance`` of the deflection range. :func:`linear_warm_up_s` takes
the warm-up from the model's least damped frozen mode over the crank-angle grid at rest and at
the model's top speed (:func:`.follow_spans.least_decay_rate`, the rule of the nonlinear spans)
and from the crank filter's time constant, whichever fades slower. :func:`split_row` cuts the
rows so that the two parts (the second with its warm-up) cost about the same.
"""

import math

import numpy as np

from .crank_filter import DEFAULT_FIT_TIME_CONSTANT_S
from .follow_spans import least_decay_rate, warm_up_for_rate, WARM_UP_TOLERANCE
from .tables import system_blocks


def linear_decay_rate(model, tables, speeds):
    """
    Return the smallest decay rate [1/s] of the linear model's frozen modes, over the grid.

    ``M q'' + C q' + K q = 0`` (:func:`.tables.system_blocks`) at every grid angle and each
    crank speed of ``speeds`` [rad/s], at zero acceleration.
    """
    theta = 2.0 * math.pi * np.arange(model.grid_size) / model.grid_size
    return min(least_decay_rate(*system_blocks(model, tables, theta, speed, 0.0)[:3])
               for speed in speeds)


def linear_warm_up_s(model, tables, reset_gap_s, tolerance=WARM_UP_TOLERANCE,
                     fit_time_constant_s=DEFAULT_FIT_TIME_CONSTANT_S, decay_rate=None):
    """
    Return the warm-up [s] after which a second estimate's start has faded below ``tolerance``.

    The slower of the model's least damped mode (``decay_rate`` where known, else
    :func:`linear_decay_rate` at rest and at ``model.speed_max``) and the crank filter's
    forgetting (``1 / fit_time_constant_s``); :func:`.follow_spans.warm_up_for_rate` of it (at
    least twice ``reset_gap_s``).
    """
    if decay_rate is None:
        decay_rate = linear_decay_rate(model, tables, (0.0, model.speed_max))
    return warm_up_for_rate(min(decay_rate, 1.0 / fit_time_constant_s), reset_gap_s, tolerance)


def split_row(rows, warm_up_rows, first_share=0.5):
    """
    Return the first row of the second part, or None when the recording is too short.

    ``rows``: the recording's rows; ``warm_up_rows``: rows the second part estimates before
    its own. The second part (its warm-up included) takes ``1 - first_share`` of the work.
    None when the second part's own rows would not exceed its warm-up (a split would not pay).
    """
    total = rows + warm_up_rows
    first = int(math.ceil(first_share * total))
    if rows - first <= warm_up_rows or first <= 0:
        return None
    return first


__all__ = ['linear_decay_rate', 'linear_warm_up_s', 'split_row']
