"""
The model flexlink_node loads, without rclpy: read the mechanism, load or build its model.

Also what the node derives from the model at start-up: the markers' exaggeration, and whether
it runs the nonlinear model (``model.nonlinear``: :func:`choose_nonlinear`,
:func:`load_nonlinear_model`).
"""

import dataclasses
import time

from . import parameters
from ..core.estimation.marker_scale import default_exaggeration, machine_speed, MARKER_SHARE
from ..core.estimation.validity_scan import ranges_text, RPM, validity_over_speeds
from ..core.mechanism_file import read_mechanism_file, read_mechanism_source
from ..core.options import PLANNED_TOLERANCE
from ..core.reduction.mechanism_model import model_for_mechanism
from ..core.reduction.nonlinear_model import nonlinear_model_for


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
    mechanism, file_beta = node_mechanism(values, source)
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


def node_mechanism(values, source=None):
    """
    Return (mechanism, the file's stiffness damping) with the ``damping_ratio`` parameter.

    ``source``: (path, bytes) as read once by the caller; default ``values['mechanism']``.
    """
    path, raw = source or read_mechanism_source(values['mechanism'])
    mechanism, file_beta = read_mechanism_file(path, raw=raw)
    zeta = values['damping_ratio']      # -1: the file's
    if zeta >= 0.0 and zeta != mechanism.damping_ratio:
        mechanism = dataclasses.replace(mechanism, damping_ratio=zeta)
    return mechanism, file_beta


def choose_nonlinear(values, model):
    """
    Return (run the nonlinear model, why) for ``model.nonlinear``.

    ``auto`` scans the linear model's validity over its speed range
    (:func:`core.estimation.validity_scan.validity_over_speeds`; before the node releases
    the model's full table).
    """
    choice = values['model.nonlinear']
    if choice != 'auto':
        return choice == 'on', f'asked for (model.nonlinear {choice})'
    start = time.perf_counter()
    scan = validity_over_speeds(model)
    span = f'0-{model.speed_max * RPM:.0f} rpm'
    took = f'{time.perf_counter() - start:.1f} s scan'
    if scan['valid'] is None:
        return False, f'auto: the linear model has no validity indicator to decide by ({took})'
    reading = (f"validity indicator max {scan['largest']:.3g}, threshold "
               f"{scan['threshold']:g}; {took}")
    if scan['valid']:
        return False, f'auto: the linear model is valid over its speed range {span} ({reading})'
    return True, (f"auto: the linear model is not valid at {ranges_text(scan['not_valid_rpm'])}"
                  f' of its speed range {span} ({reading})')


def load_nonlinear_model(values, source, options):
    """
    Return (NonlinearTables, how it is damped) for the node's mechanism and model options.

    The same tables ``flexlink replay --nonlinear on`` loads for the recording's mechanism and
    options (cached beside the linear model's).
    """
    mechanism, _ = node_mechanism(values, source)
    return nonlinear_model_for(mechanism, options, values['model.cache_dir'] or None)


def marker_exaggeration(estimator, log, source=None):
    """
    Return the markers' exaggeration when ``markers.exaggeration`` is 0, and log the rule.

    Parameters
    ----------
    estimator : StreamingEstimator
        The node's estimator (:func:`core.estimation.marker_scale.default_exaggeration`).
    log : callable
        Called with the sentence the node logs.
    source : (str, bytes) or None
        The mechanism file as the node read it: the expected peak is its machine's, up to the
        file's ``crank_speed_rpm`` with the speed range's margin (None: the whole range).

    """
    mechanism = read_mechanism_file(source[0], raw=source[1])[0] if source else None
    top = machine_speed(mechanism, estimator.model.speed_max)
    factor, peak, length = default_exaggeration(estimator, mechanism)
    log(f'markers: deflections drawn x{factor:g} when markers.exaggeration is 0 (the expected '
        f'peak up to {top * RPM:.0f} rpm, {peak * 1e6:.3g} um, as at least {MARKER_SHARE:.0%} '
        f"of the coupler's {length:g} m)")
    return factor
