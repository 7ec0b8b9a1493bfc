"""
The estimator's model configurations and their accuracy against the full-order reference.

:func:`model_configurations` lists the default model and its neighbours (fewer and more
modes, no static directions, coarser and finer grid), :func:`soft_configurations` the other
sizes of the default's soft basis; :func:`configuration_row` measures one configuration's
error per speed; :func:`estimator_report_data` adds the 391 rpm estimate and its reference
for the report's charts. The timing of the same configurations is a benchmark of the team's
(``python benchmarks/estimator_bench.py``).
"""

import dataclasses
import math

import numpy as np

from .synthetic import last_revolution, PAPER_RPM, run_estimate, synthetic_signal
from ..core.estimation.segment_replay import replay
from ..core.numerics import relative_rms, RPM
from ..core.reduction import mechanism_model
from ..core.reduction import reference as reduction_reference
from ..core.reduction.soft_basis import gap_ratios, MIN_GAP_RATIO
from ..core.reduction.soft_tables import node_values


def configuration_error(mechanism, model, options, rpm, rate_hz=1000.0, jitter=0.0,
                        seconds=None, seed=0):
    """
    Streaming error of a model against the full-order reference at one speed.

    The estimator replays (batched, the same numbers as streaming) a synthetic signal of
    ``seconds`` (default: two revolutions after a warm start) and the last revolution is
    compared with the reference response at the same crank angles.

    Returns
    -------
    dict
        error_lever_tip, error_coupler_mid (relative RMS), reference (its source).

    """
    period = 2.0 * math.pi / (rpm * RPM)
    seconds = seconds or 2.0 * period
    stamps, angles, speeds = synthetic_signal(rpm, seconds, rate_hz, jitter, seed)
    out = replay(model, stamps, angles, speeds)
    mask = last_revolution(stamps, rpm)
    ref = reduction_reference.reference_response(mechanism, options, rpm * RPM, angles[mask])
    return {'error_lever_tip': relative_rms(out['lever_tip'][mask], ref['lever_tip']),
            'error_coupler_mid': relative_rms(out['coupler_mid'][mask], ref['coupler_mid']),
            'reference': ref.get('source')}


def model_configurations(base):
    """
    List the configurations compared side by side: the default first.

    Parameters
    ----------
    base : ModelOptions
        The default configuration.

    Returns
    -------
    list of (label, ModelOptions)

    """
    smaller = dataclasses.replace(base, modes=max(1, base.modes - 4))
    larger = dataclasses.replace(base, modes=base.modes + 4)
    return [('default', base),
            (f'{smaller.modes} modes + {smaller.static} static', smaller),
            (f'{larger.modes} modes + {larger.static} static', larger),
            ('no static', dataclasses.replace(base, static=0)),
            ('grid 64', dataclasses.replace(base, grid_size=64)),
            ('grid 256', dataclasses.replace(base, grid_size=256))]


def usable_soft_sizes(model, accel_limit=5000.0):
    """
    Return the soft basis sizes p at which ``model`` has a usable spectral gap, small first.

    The gap check of the soft tables (:func:`.soft_basis.gap_ratios` over the crank angle,
    the speed range and +-``accel_limit``, at least :data:`.soft_basis.MIN_GAP_RATIO` in
    frequency).
    """
    ratios = gap_ratios(node_values(model, 'M')['1'], node_values(model, 'K'),
                        float(model.speed_max), float(accel_limit))
    return [int(p) for p in np.flatnonzero(ratios >= MIN_GAP_RATIO ** 2) + 1]


def soft_configurations(options, model):
    """
    List the soft basis sizes of the default beside its own: (label, options, model).

    Every other usable gap (:func:`usable_soft_sizes`) and soft off (the r-coordinate step),
    made from the default's model (same tables, no rebuild).
    """
    bare = dataclasses.replace(model, soft=None)
    rows = [(f'soft basis p = {p}', dataclasses.replace(options, soft_modes=p),
             mechanism_model.with_soft_basis(bare, p))
            for p in usable_soft_sizes(model) if p != model.step_size]
    if model.soft is not None:
        rows.append((f'soft off (r = {model.size})', dataclasses.replace(options, soft_modes=0),
                     mechanism_model.with_soft_basis(bare, 0)))
    return rows


def configuration_row(mechanism, label, options, model, speeds_rpm=PAPER_RPM, rate_hz=1000.0):
    """One configuration's row: sizes and errors per speed (the max over them)."""
    errors = {}
    for rpm in speeds_rpm:
        errors[f'{rpm:g}'] = configuration_error(mechanism, model, options, rpm, rate_hz)
    return {
        'label': label, 'default': label == 'default', 'size': model.size,
        'step_size': model.step_size,
        'grid_size': model.grid_size, 'bytes': int(model.nbytes),
        'error_coupler_mid': max(e['error_coupler_mid'] for e in errors.values()),
        'error_lever_tip': max(e['error_lever_tip'] for e in errors.values()),
        'errors': errors}


def configuration_rows(mechanism, base, progress=None):
    """
    Measure every configuration's sizes and errors (:func:`model_configurations`, soft sizes).

    Parameters
    ----------
    mechanism : Mechanism
        The mechanism.
    base : ModelOptions
        The default configuration.
    progress : callable or None
        ``progress(done, total, what)`` before each model built and each row's errors.

    Returns
    -------
    list of dict
        :func:`configuration_row` per configuration, the default first.

    """
    configurations = model_configurations(base)
    total = 2 * len(configurations)
    models = []
    for built, (label, options) in enumerate(configurations):
        if progress is not None:
            progress(built, total, f'building {label}')
        models.append((label, options,
                       mechanism_model.model_for_mechanism(mechanism, options, use_cache=False)))
        if label == 'default':
            models += soft_configurations(options, models[-1][2])
    rows, total = [], len(configurations) + len(models)
    for label, options, model in models:
        if progress is not None:
            progress(len(configurations) + len(rows), total, f'errors of {label}')
        rows.append(configuration_row(mechanism, label, options, model))
    return rows


def estimator_report_data(mechanism, options, progress=None):
    """
    Compute the report's estimator section: the configurations, the 391 rpm estimate.

    Parameters
    ----------
    mechanism : Mechanism
        The mechanism (Cho 1992).
    options : ModelOptions
        The default model.
    progress : callable or None
        ``progress(done, total, what)`` of the configurations (:func:`configuration_rows`).

    Returns
    -------
    dict
        'configurations' (:func:`configuration_rows`), 'crank_deg' (the estimate's last
        revolution), 'estimate' and 'reference' ({'lever_tip', 'coupler_mid'}: (m, 2)
        arrays), 'rpm'.

    """
    configurations = configuration_rows(mechanism, options, progress)
    model = mechanism_model.model_for_mechanism(mechanism, options)
    rpm = PAPER_RPM[-1]
    estimate = run_estimate(model, rpm)
    angles = np.radians(estimate['crank_deg'])
    reference = reduction_reference.reference_response(mechanism, options, rpm * RPM, angles)
    series = {key: np.column_stack([estimate[key]['dx_m'], estimate[key]['dy_m']])
              for key in ('lever_tip', 'coupler_mid')}
    return {'configurations': configurations, 'crank_deg': np.asarray(estimate['crank_deg']),
            'estimate': series, 'reference': reference, 'rpm': rpm}
