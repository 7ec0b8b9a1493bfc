"""
``flexlink bench``: the estimator's cost and accuracy, configuration by configuration.

Side by side in one run: streaming cost per sample (median, p99), offline samples per
second, full-order CPU per simulated second, and each configuration's error against the
full-order reference (:func:`run_bench`); the reduced nonlinear model's update against the
default's in alternating rounds (:func:`nonlinear_timing`); :func:`estimator_report_data`
adds the 391 rpm estimate and its reference for the report's charts.
"""

import dataclasses
import math
import time

import numpy as np

from .synthetic import last_revolution, PAPER_RPM, run_estimate, stream_nonlinear_timed, \
    stream_timed, synthetic_signal, timing_summary
from ..core.estimation.native import compiled_step_available
from ..core.estimation.nonlinear_stream import estimate_nonlinear
from ..core.estimation.offline import replay
from ..core.fe import linkage as assembly
from ..core.integrators import RadauIIA
from ..core.numerics import relative_rms, RPM
from ..core.reduction import mechanism_model
from ..core.reduction import reference as reduction_reference
from ..core.reduction.nonlinear_model import nonlinear_model_for
from ..core.reduction.soft_basis import gap_ratios, MIN_GAP_RATIO
from ..core.reduction.soft_tables import node_values

# Length of the signal the offline replay rate is measured on [s] (amortises the warm start).
OFFLINE_SECONDS = 20.0
# The estimator's targets (the soft basis's): median streaming update [us], offline samples/s.
UPDATE_TARGET_US = 10.0
OFFLINE_TARGET = 100_000.0
# The nonlinear model's: its update's median over the linear one's, offline samples/s.
NONLINEAR_RATIO_TARGET = 10.0
NONLINEAR_OFFLINE_TARGET = 10_000.0
# Length of the signal the nonlinear model's offline rate is measured on [s].
NONLINEAR_OFFLINE_SECONDS = 4.0


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


def full_order_cpu_per_second(mechanism, options, rpm, rate_hz=1000.0, steps=40):
    """
    CPU seconds per simulated second of a direct full-order integration at ``rate_hz``.

    Each step assembles the FE system at the two Radau stage angles (core/fe/linkage.py),
    builds the modal damping from all frozen modes and takes one order-3 Radau IIA step:
    what integrating the unreduced model sample by sample costs.
    """
    mech = mechanism_model.fe_mechanism(mechanism, options)
    linkage = assembly.FlexibleLinkage(mech, options)
    method = RadauIIA(2)
    speed, h = rpm * RPM, 1.0 / rate_hz
    q = np.zeros(linkage.size)
    v = np.zeros(linkage.size)
    start = time.process_time()
    for n in range(steps):
        system = linkage.assemble(speed * h * (n + method.c))
        mass, damping, stiffness, load = system.evaluate(speed)
        frozen = system.frozen_stiffness(speed)
        damping = damping + np.array([
            mechanism_model.modal_damping_matrix(m, k, mech.damping_ratio)
            for m, k in zip(mass, frozen)])
        q, v, _ = method.step(q, v, h, mass, damping, stiffness, load)
    return (time.process_time() - start) / steps * rate_hz


def reference_cpu_per_second(mechanism, options, rpm, rate_hz):
    """Full-order CPU per simulated second (None if the FE model is not available)."""
    try:
        return full_order_cpu_per_second(mechanism, options, rpm, rate_hz)
    except (ImportError, AttributeError, TypeError):
        return None


def bench_configurations(base):
    """
    List the configurations compared by ``bench``: the default first.

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


def interleaved_timing(entries, signal, long_signal, rounds=3, each_round=None):
    """
    Time the streaming and offline cost of (model, step) entries in interleaved rounds.

    Every round times every entry once, so a slow spell of a shared machine hits all of them
    alike; each entry keeps its best round (lowest median: the slower rounds measure the
    neighbours). Streaming over ``signal``, offline replay over ``long_signal`` (stamps,
    angles, speeds).

    Parameters
    ----------
    entries : dict
        key -> (model, compiled).
    signal, long_signal : tuple of ndarray
        (stamps, angles, speeds) of the streamed and the replayed signal.
    rounds : int
        Rounds of timing.
    each_round : callable or None
        ``each_round(k)`` before round k (0-based).

    Returns
    -------
    dict
        key -> us_per_sample, us_per_sample_p99, offline_samples_per_s.

    """
    best = {key: {'us_per_sample': math.inf, 'offline_samples_per_s': 0.0} for key in entries}
    for k in range(rounds):
        if each_round is not None:
            each_round(k)
        for key, (model, compiled) in entries.items():
            median, p99 = timing_summary(stream_timed(model, *signal, compiled=compiled)[1])
            start = time.perf_counter()
            replay(model, *long_signal, compiled=compiled)
            offline = long_signal[0].size / (time.perf_counter() - start)
            row = best[key]
            if median < row['us_per_sample']:
                row.update(us_per_sample=median, us_per_sample_p99=p99)
            row['offline_samples_per_s'] = max(row['offline_samples_per_s'], offline)
    return best


def nonlinear_timing(mechanism, options, model, signal, rounds=3):
    """
    Time the reduced nonlinear model's update against the linear model's, alternating.

    Each round times the linear streaming update (``model``) and the nonlinear model's
    streaming update (:func:`.synthetic.stream_nonlinear_timed`, the node's call) over
    ``signal``, and the nonlinear model offline (:func:`estimate_nonlinear`, many samples per
    compiled call) over its first :data:`NONLINEAR_OFFLINE_SECONDS`; each keeps its best
    round.

    Returns
    -------
    dict
        'size', 'damping', 'us_per_sample', 'us_per_sample_p99', 'offline_samples_per_s',
        'linear_us_per_sample' (the same rounds), 'ratio' (nonlinear / linear median),
        'newton_per_sample', 'refused'.

    """
    tables, damping = nonlinear_model_for(mechanism, options, use_cache=False)
    stamps = signal[0]
    offline = stamps <= stamps[0] + int(NONLINEAR_OFFLINE_SECONDS * 1e9)
    best = {'us_per_sample': math.inf, 'linear_us_per_sample': math.inf,
            'offline_samples_per_s': 0.0}
    for _ in range(rounds):
        linear, _ = timing_summary(stream_timed(model, *signal)[1])
        out = estimate_nonlinear(tables, *signal)
        median, p99 = timing_summary(stream_nonlinear_timed(tables, *signal)[1][1:])
        start = time.perf_counter()
        estimate_nonlinear(tables, *(array[offline] for array in signal))
        rate = int(offline.sum()) / (time.perf_counter() - start)
        best['linear_us_per_sample'] = min(best['linear_us_per_sample'], linear)
        if median < best['us_per_sample']:
            best.update(us_per_sample=median, us_per_sample_p99=p99, refused=out['refused'],
                        newton_per_sample=out['newton_iterations'] / max(1, stamps.size - 1))
        best['offline_samples_per_s'] = max(best['offline_samples_per_s'], rate)
    return {**best, 'size': tables.size, 'damping': damping,
            'ratio': best['us_per_sample'] / best['linear_us_per_sample']}


def _configuration_row(mechanism, label, options, model, timing, speeds_rpm, rate_hz):
    """One configuration's row: sizes, timings and errors per speed (the max over them)."""
    errors = {}
    for rpm in speeds_rpm:
        errors[f'{rpm:g}'] = configuration_error(mechanism, model, options, rpm, rate_hz)
    return {
        'label': label, 'default': label == 'default', 'size': model.size,
        'step_size': model.step_size,
        'grid_size': model.grid_size, 'bytes': int(model.nbytes),
        'us_per_sample': timing['us_per_sample'],
        'us_per_sample_p99': timing['us_per_sample_p99'],
        'offline_samples_per_s': timing['offline_samples_per_s'],
        'error_coupler_mid': max(e['error_coupler_mid'] for e in errors.values()),
        'error_lever_tip': max(e['error_lever_tip'] for e in errors.values()),
        'errors': errors}


def bench_targets(result):
    """
    Judge the estimator's targets from the default configuration's figures.

    Parameters
    ----------
    result : dict
        :func:`run_bench`'s result ('configurations', 'cpu_ratio').

    Returns
    -------
    list of dict
        name, value, unit, target, met.

    """
    default = result['configurations'][0]
    return [
        {'name': 'update median', 'value': default['us_per_sample'], 'unit': 'us',
         'target': f'<= {UPDATE_TARGET_US:g}',
         'met': default['us_per_sample'] <= UPDATE_TARGET_US},
        {'name': 'offline', 'value': default['offline_samples_per_s'], 'unit': 'samples/s',
         'target': f'>= {OFFLINE_TARGET:g}',
         'met': default['offline_samples_per_s'] >= OFFLINE_TARGET},
        {'name': 'CPU vs full order at 1 kHz', 'value': result['cpu_ratio'], 'unit': 'x less',
         'target': '>= 100', 'met': bool(result['cpu_ratio'] and result['cpu_ratio'] >= 100.0)},
    ] + _nonlinear_targets(result.get('nonlinear'))


def _nonlinear_targets(nonlinear):
    """Judge the nonlinear model's targets (none without its timing)."""
    if not nonlinear:
        return []
    return [
        {'name': 'nonlinear update vs linear', 'value': nonlinear['ratio'], 'unit': 'x',
         'target': f'<= {NONLINEAR_RATIO_TARGET:g}',
         'met': nonlinear['ratio'] <= NONLINEAR_RATIO_TARGET},
        {'name': 'nonlinear offline', 'value': nonlinear['offline_samples_per_s'],
         'unit': 'samples/s', 'target': f'>= {NONLINEAR_OFFLINE_TARGET:g}',
         'met': nonlinear['offline_samples_per_s'] >= NONLINEAR_OFFLINE_TARGET}]


class _Steps:
    """Counts a job's steps for a ``progress(done, total, what)`` callable (or none)."""

    def __init__(self, progress, total):
        self.progress, self.total, self.done = progress, total, 0

    def __call__(self, what):
        """Report the step starting now."""
        if self.progress is not None:
            self.progress(self.done, self.total, what)
        self.done += 1


def run_bench(mechanism, base, rate_hz=1000.0, seconds=2.0, speeds_rpm=PAPER_RPM,
              configurations=None, progress=None, nonlinear=True):
    """
    Side-by-side costs and errors of the configurations (see module docstring).

    Parameters
    ----------
    mechanism : Mechanism
        The mechanism.
    base : ModelOptions
        The default configuration (:func:`bench_configurations` varies it).
    rate_hz : float
        Sample rate of the synthetic signals [Hz].
    seconds : float
        Length of the streamed signal [s].
    speeds_rpm : sequence of float
        Speeds of the error checks [rpm].
    configurations : list of (label, ModelOptions), optional
        The configurations (default :func:`bench_configurations`, and after the default the
        other sizes of its soft basis and soft off, :func:`soft_configurations`).
    progress : callable or None
        ``progress(done, total, what)`` before each step (a model built, a timing round, a
        configuration's errors, the full-order CPU) and once at the end.
    nonlinear : bool
        Also time the reduced nonlinear model of the default's options against the default
        (:func:`nonlinear_timing`).

    Returns
    -------
    dict
        'configurations': per configuration us/sample (median, p99), offline samples/s,
        errors per speed, model bytes; 'reference_cpu_s_per_s'; 'cpu_ratio'; 'nonlinear'
        (:func:`nonlinear_timing`, or False); 'targets'.

    """
    signal = synthetic_signal(max(speeds_rpm), seconds, rate_hz)
    long_signal = synthetic_signal(max(speeds_rpm), OFFLINE_SECONDS, rate_hz)
    models = []
    soft_rows = configurations is None      # the default's soft basis sizes too
    configurations = configurations or bench_configurations(base)
    rounds = 3
    step = _Steps(progress, 2 * len(configurations) + rounds + 1 + bool(nonlinear))
    for label, options in configurations:
        step(f'building {label}')
        models.append((label, options,
                       mechanism_model.model_for_mechanism(mechanism, options, use_cache=False)))
        if soft_rows and label == 'default':
            models += soft_configurations(options, models[-1][2])
    step.total += len(models) - len(configurations)
    entries = {label: (model, compiled_step_available()) for label, _, model in models}
    # The default's numpy step too (the compiled step's reference and fallback).
    numpy_key = ('numpy step',)
    entries[numpy_key] = (models[0][2], False)
    timings = interleaved_timing(entries, signal, long_signal, rounds,
                                 lambda k: step(f'timing round {k + 1} of {rounds}'))
    numpy_step = timings.pop(numpy_key)
    if nonlinear:
        step('the nonlinear model against the default')
        nonlinear = nonlinear_timing(mechanism, configurations[0][1], models[0][2], signal,
                                     rounds)
    rows, reference_cpu = [], None
    for label, options, model in models:
        step(f'errors of {label}')
        rows.append(_configuration_row(mechanism, label, options, model, timings[label],
                                       speeds_rpm, rate_hz))
        if reference_cpu is None:
            step('full-order CPU')
            reference_cpu = reference_cpu_per_second(mechanism, options, max(speeds_rpm),
                                                     rate_hz)
    estimator_cpu = rows[0]['us_per_sample'] * 1e-6 * rate_hz  # CPU s per simulated s
    result = {'rate_hz': rate_hz, 'configurations': rows,
              'reference_cpu_s_per_s': reference_cpu,
              'estimator_cpu_s_per_s': estimator_cpu,
              'cpu_ratio': (reference_cpu / estimator_cpu) if reference_cpu else None,
              'compiled_step': compiled_step_available(),
              'numpy_step': numpy_step, 'nonlinear': nonlinear}
    result['targets'] = bench_targets(result)
    step('done')
    return result


def estimator_report_data(mechanism, options, progress=None):
    """
    Compute the report's estimator section: the bench, the 391 rpm estimate and reference.

    Parameters
    ----------
    mechanism : Mechanism
        The mechanism (Cho 1992).
    options : ModelOptions
        The default model.
    progress : callable or None
        ``progress(done, total, what)`` of the bench (:func:`run_bench`).

    Returns
    -------
    dict
        'bench' (:func:`run_bench`), 'crank_deg' (the estimate's last revolution),
        'estimate' and 'reference' ({'lever_tip', 'coupler_mid'}: (m, 2) arrays), 'rpm'.

    """
    bench = run_bench(mechanism, options, progress=progress)
    model = mechanism_model.model_for_mechanism(mechanism, options)
    rpm = PAPER_RPM[-1]
    estimate = run_estimate(model, rpm)
    angles = np.radians(estimate['crank_deg'])
    reference = reduction_reference.reference_response(mechanism, options, rpm * RPM, angles)
    series = {key: np.column_stack([estimate[key]['dx_m'], estimate[key]['dy_m']])
              for key in ('lever_tip', 'coupler_mid')}
    return {'bench': bench, 'crank_deg': np.asarray(estimate['crank_deg']),
            'estimate': series, 'reference': reference, 'rpm': rpm}
