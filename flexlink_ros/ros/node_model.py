"""
The model flexlink_node loads, without rclpy: read the mechanism, load or build its model.

Also what the node derives from the model at start-up (the markers' exaggeration).
"""

import dataclasses

from . import parameters
from ..core.estimation.marker_scale import default_exaggeration, MARKER_SHARE
from ..core.mechanism_file import read_mechanism_file, read_mechanism_source
from ..core.options import PLANNED_TOLERANCE
from ..core.reduction.mechanism_model import model_for_mechanism


def load_node_model(values, warn, progress=None, source=None):
    """
    Load the mechanism and its reduced model (cached, else built).

    A model that cannot be built raises its FlexlinkError.

    Parameters
    ----------
    values : dict
        Parameter name -> value.
    warn : callable
        Called with a warning sentence.
    progress : callable or None
        ``progress(done, total, what)`` while the model is built (not on a cache hit).
    source : (path, bytes), optional
        The mechanism file as read once by the caller (:func:`read_mechanism_source`, whose
        bytes the recording also names); default: ``values['mechanism']`` read here.

    Returns
    -------
    model : core.reduction.model.ReducedModel
    options : core.options.ModelOptions
        The options used.
    notes : list of str
        Warnings given (empty if none).

    """
    path, raw = source or read_mechanism_source(values['mechanism'])
    mechanism, file_beta = read_mechanism_file(path, raw=raw)
    zeta = values['damping_ratio']      # -1: the file's
    if zeta >= 0.0 and zeta != mechanism.damping_ratio:
        mechanism = dataclasses.replace(mechanism, damping_ratio=zeta)
    options = parameters.model_options(values, file_beta, mechanism.crank_speed)
    notes = []
    if values['model.modes'] == 0 and values['model.tolerance'] < PLANNED_TOLERANCE:
        notes.append(f'the default model was planned for {PLANNED_TOLERANCE:g} relative '
                     f'error; for {values["model.tolerance"]:g} run `flexlink plan --tolerance '
                     f'{values["model.tolerance"]:g}` and set model.modes')
        warn(notes[-1])
    cache_dir = values['model.cache_dir'] or None
    model = model_for_mechanism(mechanism, options, cache_dir=cache_dir, progress=progress)
    soft = model.info.get('soft') or {}
    if options.soft_modes == -1 and not soft.get('used', True) \
            and model.dynamic_second_order is None:
        # model.soft_modes -1 found no usable spectral gap: say so where the node logs
        notes.append(f'stepping all {model.size} coordinates: {soft.get("reason")}')
        warn(notes[-1])
    return model, options, notes


def marker_exaggeration(estimator, log):
    """
    Return the markers' exaggeration when ``markers.exaggeration`` is 0, and log the rule.

    Parameters
    ----------
    estimator : StreamingEstimator
        The node's estimator (:func:`core.estimation.marker_scale.default_exaggeration`).
    log : callable
        Called with the sentence the node logs.

    """
    factor, peak, length = default_exaggeration(estimator)
    log(f'markers: deflections drawn x{factor:g} when markers.exaggeration is 0 (the expected '
        f"peak, {peak * 1e6:.3g} um, as at least {MARKER_SHARE:.0%} of the coupler's "
        f'{length:g} m)')
    return factor
