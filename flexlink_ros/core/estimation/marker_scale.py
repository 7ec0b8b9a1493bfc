"""
How much the markers exaggerate the deflections: enough to see the expected peak.

Rule: the deflections are drawn ``k`` times their size, ``k`` the smallest round factor
(1, 2, 5 times a power of ten, from 1 to 10^6) that draws the expected peak deflection as at
least :data:`MARKER_SHARE` (5 %) of the coupler's length. The expected peak is the model's
quasi-static one: the largest deflection component of K q = f over the crank-angle grid at
constant speeds up to the machine's speed (:func:`machine_speed`: the mechanism file's
``crank_speed_rpm`` with the speed range's margin, else the top of the model's speed range;
:meth:`StreamingEstimator.quasi_static_peak`); a dynamic response near resonance can be a few
times larger. The range's top alone would not do: a 60 rpm machine's model serves at least
620 rpm, where it bends a hundred times as much. Cho 1992's default model gets x2, a steel
linkage bending 30 um at 600 rpm x500.
"""

import math

import numpy as np

from .streaming import StreamingEstimator
from ..options import SPEED_MARGIN
from ..reduction.mechanism_model import cached_model_values

MARKER_SHARE = 0.05   # the expected peak deflection drawn as this share of the coupler length
PEAKS_CACHE_NAME = 'quasi-static-peaks'
MAX_EXAGGERATION = 1e6   # the node's parameter range
ROUND_STEPS = (1.0, 2.0, 5.0)


def round_exaggeration(peak_m, length_m, share=MARKER_SHARE):
    """
    Return the smallest round factor drawing ``peak_m`` as at least ``share`` of ``length_m``.

    Parameters
    ----------
    peak_m : float
        The deflection to show [m] (0 or not finite: the largest factor).
    length_m : float
        The reference length [m].
    share : float
        Drawn size of the peak relative to ``length_m``.

    Returns
    -------
    float
        1, 2, 5, 10, 20, ... up to :data:`MAX_EXAGGERATION`.

    """
    if not (math.isfinite(peak_m) and peak_m > 0.0):
        return MAX_EXAGGERATION
    wanted = share * length_m / peak_m
    if wanted <= 1.0:
        return 1.0
    decade = 10.0 ** math.floor(math.log10(wanted))
    for step in ROUND_STEPS + (10.0,):
        if step * decade >= wanted * (1.0 - 1e-12):
            return min(step * decade, MAX_EXAGGERATION)
    return MAX_EXAGGERATION


def machine_speed(mechanism, speed_max):
    """
    Return the top speed [rad/s] of the expected peak: the machine's, within the model's range.

    Parameters
    ----------
    mechanism : Mechanism or None
        The linkage; its ``crank_speed`` (the file's ``crank_speed_rpm``) times
        :data:`core.options.SPEED_MARGIN`, if it states one.
    speed_max : float
        The top of the model's speed range [rad/s] (the answer without a machine speed).

    """
    crank_speed = getattr(mechanism, 'crank_speed', None)
    if crank_speed:
        return min(float(speed_max), SPEED_MARGIN * abs(float(crank_speed)))
    return float(speed_max)


def model_exaggeration(model, step_tables=None, mechanism=None):
    """Return :func:`default_exaggeration` of a reduced model (its step tables, if given)."""
    estimator = StreamingEstimator(model, step_tables=step_tables)
    return default_exaggeration(estimator, mechanism)[0]


def default_exaggeration(estimator, mechanism=None):
    """
    Return the markers' default exaggeration of a model, with what it was derived from.

    Parameters
    ----------
    estimator : StreamingEstimator
        An estimator of the model (its step tables give the quasi-static peak).
    mechanism : Mechanism or None
        The linkage: the expected peak is taken up to its :func:`machine_speed`.

    Returns
    -------
    exaggeration : float
    peak_m : float
        The expected peak deflection [m].
    length_m : float
        The coupler's length [m].

    """
    model = estimator.model
    positions, _ = model.shapes(0.0, np.zeros(model.size))
    coupler = positions[1]
    length = float(np.hypot(*(coupler[-1] - coupler[0])))
    peak = float(estimator.quasi_static_peak(machine_speed(mechanism, model.speed_max)))
    return round_exaggeration(peak, length), peak, length


def load_quasi_static_peaks(model, step_tables, mechanism, options, cache_dir, use_cache):
    """
    Give the step tables the quasi-static peaks at the model's top speed and the machine's.

    They set the deflection bound and the markers' exaggeration; computing them solves K q = f
    over the grid at many speeds (about 0.05 s for the default model), so they are kept in a
    file beside the model's cache (:func:`.reduction.mechanism_model.cached_model_values`) and
    taken from it when its speeds are these.
    """
    speeds = np.array(sorted({float(model.speed_max), machine_speed(mechanism, model.speed_max)}))

    def build():
        return {'speeds': speeds,
                'peaks': np.array([step_tables.quasi_static_peak(model, top) for top in speeds])}
    values = cached_model_values(mechanism, options, cache_dir, use_cache, PEAKS_CACHE_NAME, build)
    if np.array_equal(values['speeds'], speeds):
        step_tables.know_quasi_static_peaks(values['speeds'], values['peaks'])
