"""
Time the estimator's model configurations side by side, with their errors, and draw the chart.

In one run: streaming cost per sample (median, p99), offline samples per second, full-order CPU
per simulated second, and each configuration's error against the full-order reference (the
configurations and their errors: :mod:`studies.configurations`); every configuration is timed
in interleaved rounds, best of three; the reduced nonlinear model's update against the
default's in alternating rounds (:func:`nonlinear_timing`). It prints a table and writes a
chart of error against cost. ``python benchmarks/estimator_bench.py`` runs it for the node's
default model with the estimator's model flags (``--modes``, ``--grid-size``, ...).
"""

import argparse
import json
import math
import pathlib
import time

from flexlink_ros.cli.model_args import add_estimator_arguments, model_options
from flexlink_ros.cli.progress import Progress
from flexlink_ros.core.estimation.native import compiled_step_available
from flexlink_ros.core.estimation.nonlinear_stream import estimate_nonlinear
from flexlink_ros.core.estimation.segment_replay import replay
from flexlink_ros.core.fe import linkage as assembly
from flexlink_ros.core.integrators import RadauIIA
from flexlink_ros.core.mechanism_file import load_mechanism
from flexlink_ros.core.numerics import RPM
from flexlink_ros.core.reduction import mechanism_model
from flexlink_ros.core.reduction.nonlinear_model import nonlinear_model_for
from flexlink_ros.studies.configurations import configuration_row, model_configurations, \
    soft_configurations
from flexlink_ros.studies.synthetic import PAPER_RPM, stream_nonlinear_timed, stream_timed, \
    synthetic_signal, timing_summary
import numpy as np

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
CHANNELS = (('coupler_mid', 'coupler mid-point'), ('lever_tip', 'lever tip'))
# Markers of the configurations after the default's star (colours: matplotlib's tab10).
MARKERS = ('o', 's', '^', 'v', 'D', 'P', 'X', '<', '>', 'h')


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
    streaming update (:func:`studies.synthetic.stream_nonlinear_timed`, the node's call) over
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
        The default configuration (:func:`studies.configurations.model_configurations`
        varies it).
    rate_hz : float
        Sample rate of the synthetic signals [Hz].
    seconds : float
        Length of the streamed signal [s].
    speeds_rpm : sequence of float
        Speeds of the error checks [rpm].
    configurations : list of (label, ModelOptions), optional
        The configurations (default :func:`studies.configurations.model_configurations`,
        and after the default the other sizes of its soft basis and soft off,
        :func:`studies.configurations.soft_configurations`).
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
    configurations = configurations or model_configurations(base)
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
        row = configuration_row(mechanism, label, options, model, speeds_rpm, rate_hz)
        rows.append({**row, **timings[label]})
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


def error_vs_cost_figure(configurations, tolerance=None):
    """
    Draw error against cost per sample, one marker per configuration, named in the legend.

    The configurations sit close together (a few us apart, errors within a decade), so they
    are named in one legend under both panels rather than beside their markers, where the
    labels overlapped each other and the axes' edge.

    Parameters
    ----------
    configurations : list of dict
        Each with 'label' (str), 'us_per_sample' (float), 'error_coupler_mid' and
        'error_lever_tip' (relative RMS, float) and optionally 'default' (bool).
    tolerance : float or None
        Relative error target, drawn as a horizontal line.

    Returns
    -------
    matplotlib.figure.Figure

    """
    from matplotlib.figure import Figure   # only when drawing

    figure = Figure(figsize=(10.0, 4.8), layout='constrained')
    axes = figure.subplots(1, 2, sharex=True)
    others = iter(zip(MARKERS * 2, ('tab:blue', 'tab:orange', 'tab:green', 'tab:purple',
                                    'tab:brown', 'tab:pink', 'tab:gray', 'tab:olive',
                                    'tab:cyan', 'k') * 2))
    styles = [('*', 'tab:red', 140) if c.get('default') else (*next(others), 40)
              for c in configurations]
    for ax, (key, title) in zip(axes, CHANNELS):
        for config, (marker, colour, size) in zip(configurations, styles):
            ax.scatter(config['us_per_sample'], max(config[f'error_{key}'], 1e-6), s=size,
                       marker=marker, color=colour, zorder=3, label=config['label'])
        if tolerance is not None:
            ax.axhline(tolerance, color='grey', linestyle='--', linewidth=1.0,
                       label=f'tolerance {tolerance:g}')
        errors = [max(c[f'error_{key}'], 1e-6) for c in configurations]
        low, high = min(errors + [tolerance or errors[0]]), max(errors + [tolerance or 0.0])
        ax.set_ylim(low / 3.0, high * 3.0)
        ax.set_yscale('log')
        ax.set_title(f'{title}: relative RMS error')
        ax.set_xlabel('streaming update, median [us/sample]')
        ax.grid(True, which='both', alpha=0.3)
        ax.margins(x=0.15)
    axes[0].set_ylabel('error vs full-order reference')
    handles, labels = axes[0].get_legend_handles_labels()
    figure.legend(handles, labels, loc='outside lower center', fontsize=8,
                  ncols=min(len(labels), 4))
    return figure


def plot_error_vs_cost(configurations, path, tolerance=None):
    """
    Write :func:`error_vs_cost_figure` to a PNG file.

    Parameters
    ----------
    configurations : list of dict
        As :func:`error_vs_cost_figure`.
    path : str or Path
        PNG file to write.
    tolerance : float or None
        Relative error target, drawn as a horizontal line.

    Returns
    -------
    pathlib.Path

    """
    path = pathlib.Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    error_vs_cost_figure(configurations, tolerance).savefig(path, dpi=120)
    return path


def bench_lines(result):
    """Write the text of ``bench``: a row per configuration, numpy step, CPU ratio, targets."""
    lines = [f'{"configuration":<22} {"r":>3} {"p":>3} {"grid":>5} {"us p50":>7} '
             f'{"us p99":>7} {"offline/s":>10} {"coupler":>9} {"lever":>9} {"MB":>6}']
    for row in result['configurations']:
        lines.append(f'{row["label"]:<22} {row["size"]:>3} {row.get("step_size", "-"):>3} '
                     f'{row["grid_size"]:>5} '
                     f'{row["us_per_sample"]:>7.1f} {row["us_per_sample_p99"]:>7.1f} '
                     f'{row["offline_samples_per_s"]:>10.0f} '
                     f'{row["error_coupler_mid"]:>9.2e} {row["error_lever_tip"]:>9.2e} '
                     f'{row["bytes"] / 1e6:>6.2f}')
    numpy_step = result['numpy_step']
    lines.append(f'{"default, numpy step":<22} {"":>3} {"":>3} {"":>5} '
                 f'{numpy_step["us_per_sample"]:>7.1f} {numpy_step["us_per_sample_p99"]:>7.1f} '
                 f'{numpy_step["offline_samples_per_s"]:>10.0f}   (the same numbers; '
                 + ('every row timed in interleaved rounds, best of 3)'
                    if result['compiled_step'] else 'the compiled step is NOT built)'))
    nonlinear = result.get('nonlinear')
    if nonlinear:
        lines.append(f'{"nonlinear (reduced)":<22} {nonlinear["size"]:>3} {"":>3} {"":>5} '
                     f'{nonlinear["us_per_sample"]:>7.1f} {nonlinear["us_per_sample_p99"]:>7.1f} '
                     f'{nonlinear["offline_samples_per_s"]:>10.0f}   ({nonlinear["ratio"]:.1f}x '
                     f'the default linear update in the same rounds, '
                     f'{nonlinear["newton_per_sample"]:.2f} Newton iterations per sample; '
                     'its accuracy against the Exudyn peer: docs/nonlinear.md)')
    if result['cpu_ratio']:
        lines.append(f'full-order reference: {result["reference_cpu_s_per_s"]:.3g} CPU s per '
                     f'simulated s; estimator {result["estimator_cpu_s_per_s"]:.3g} '
                     f'({result["cpu_ratio"]:.0f}x less)')
    for target in result['targets']:
        value = target['value']
        lines.append(f'target {target["name"]}: {"n/a" if value is None else f"{value:.4g}"} '
                     f'{target["unit"]} (target {target["target"]}) '
                     f'{"met" if target["met"] else "NOT met"}')
    if result.get('chart'):
        lines.append(f'chart: {result["chart"]}')
    return lines


def main(argv=None):
    """Run :func:`run_bench` with the estimator's model flags; print the table, draw the chart."""
    parser = argparse.ArgumentParser(prog='python benchmarks/estimator_bench.py',
                                     description=__doc__.strip().splitlines()[0])
    add_estimator_arguments(parser)
    parser.add_argument('--out', default='out', help='directory of the chart (default out/)')
    parser.add_argument('--no-chart', action='store_true', help='skip the chart')
    parser.add_argument('--seconds', type=float, default=2.0,
                        help='length of the streamed signal [s]')
    parser.add_argument('--speeds', default=None,
                        help='speeds of the error checks, comma list [rpm] (default: the paper)')
    parser.add_argument('--only-default', action='store_true',
                        help='the default configuration alone (a quick run)')
    parser.add_argument('--no-nonlinear', action='store_true',
                        help="leave out the reduced nonlinear model's row")
    args = parser.parse_args(argv)
    mechanism = load_mechanism(args.mechanism)
    base = model_options(args)
    speeds = tuple(float(s) for s in args.speeds.split(',')) if args.speeds else PAPER_RPM
    with Progress('bench', unit='step') as progress:
        result = run_bench(mechanism, base, args.rate_hz, args.seconds, speeds,
                           [('default', base)] if args.only_default else None, progress,
                           nonlinear=not args.no_nonlinear)
    if not args.no_chart:
        chart = pathlib.Path(args.out) / 'estimator_error_vs_cost.png'
        result['chart'] = str(plot_error_vs_cost(result['configurations'], chart))
    print(json.dumps(result, indent=1, default=float) if args.json
          else '\n'.join(bench_lines(result)))


if __name__ == '__main__':
    main()
