"""
`flexlink estimate`, `flexlink plan`, `flexlink bench`: the streaming estimator offline.

- ``estimate`` runs :class:`StreamingEstimator` on a synthetic constant-speed crank signal
  (optionally jittered) and prints the last full revolution (:mod:`studies.synthetic`); its
  JSON has the validity indicator's ``nonlinearity`` (``indicator_max``, ``valid``,
  ``threshold``) over that revolution.
- ``plan`` picks the smallest model (physics: elements per link, rigid crank, geometric
  stiffness, bearings; size: modes, static directions, grid) meeting a tolerance against the
  full-order response of the richest model of the scene over a speed range, and shows the
  error and cost of the alternatives (:mod:`studies.plan`); ``--params-out FILE`` writes
  the choice as the node's parameters file (:mod:`.plan_params`).
- ``bench`` measures, side by side in one run: streaming cost per sample (median, p99),
  offline samples per second, full-order CPU per simulated second, and each configuration's
  error; it prints a table and writes a chart of error against cost (:mod:`studies.bench`).
"""

import argparse
import dataclasses
import pathlib

import numpy as np

from .estimate_nonlinear import add_nonlinear, CHOICES
from .flex import nonlinearity_line
from .main import emit
from .model_args import (add_chart_argument, add_estimator_arguments, crank_rpm,
                         criterion_thresholds, load_model, model_options)
from .plan_params import chosen_options, write_params_file
from .plan_table import plan_table
from .progress import Progress
from ..core.mechanism_file import load_mechanism
from ..core.numerics import RPM
from ..core.reduction.soft_basis import soft_basis_text
from ..report.cycle_chart import plot_cycle
from ..report.estimator import plot_error_vs_cost
from ..studies.bench import run_bench
from ..studies.plan import quick_plan, run_plan
from ..studies.synthetic import run_estimate


def _estimate(args):
    mechanism = load_mechanism(args.mechanism)
    args.rpm = crank_rpm(args.rpm, mechanism)
    options = model_options(args)
    options = dataclasses.replace(options, speed_max=max(options.speed_max,
                                                         1.05 * abs(args.rpm) * RPM))
    model = load_model(mechanism, options, args)
    result = run_estimate(model, args.rpm, args.seconds, args.rate_hz, args.jitter,
                          not args.no_warm_start, args.seed)
    result['order'] = model.order
    result['soft'] = model.info.get('soft')
    result['second_order'] = options.second_order if model.order == 2 else None
    lever = np.hypot(result['lever_tip']['dx_m'], result['lever_tip']['dy_m'])
    coupler = np.hypot(result['coupler_mid']['dx_m'], result['coupler_mid']['dy_m'])
    text = (f'{mechanism.name} at {args.rpm:g} rpm, {args.rate_hz:g} Hz '
            f'(jitter {args.jitter:g}), {result["samples"]} samples, order {model.order}'
            + (' (dynamic pass)' if options.second_order == 'dynamic' else '') + '; '
            'last revolution:\n'
            f'  lever tip |d| max   {1e3 * lever.max():.4f} mm\n'
            f'  coupler mid |d| max {1e3 * coupler.max():.4f} mm\n'
            f'  update {result["us_per_sample_median"]:.1f} us median, '
            f'{result["us_per_sample_p99"]:.1f} us p99 (r = {model.size}, '
            f'{soft_basis_text(model)}, '
            f'{model.grid_size} grid cells)\n  ' + nonlinearity_line(result['nonlinearity']))
    text += '\n' + '\n'.join(add_nonlinear(args, mechanism, options, result))
    if args.chart:
        result['chart'] = str(_estimate_chart(args, mechanism, model, result))
        text += f"\n  chart {result['chart']}"
    return emit(result, text, args.json)


def _estimate_chart(args, mechanism, model, result):
    """Draw the last revolution's deflections and criteria (``--chart``)."""
    def columns(point):
        return np.column_stack([result[point]['dx_m'], result[point]['dy_m']])
    criterion = np.asarray(result['criterion']) if model.force_moments.any() else None
    return plot_cycle(args.chart, np.radians(result['crank_deg']), columns('lever_tip'),
                      columns('coupler_mid'), criterion, thresholds=criterion_thresholds(),
                      title=f'{mechanism.name} at {args.rpm:g} rpm (last revolution, order '
                      f'{model.order}, flexlink estimate)')


def plan_fixed(args):
    """
    Collect the physical choices fixed on the command line, which every plan candidate keeps.

    ``--rigid-crank`` / ``--flexible-crank`` fix the crank model (neither: the plan tries
    both), ``--no-geometric-stiffness`` leaves it out (otherwise off and on are tried).
    """
    fixed = {}
    if args.rigid_crank is not None:
        fixed['rigid_crank'] = args.rigid_crank
    if args.no_geometric_stiffness:
        fixed['geometric_stiffness'] = False
    return fixed


def _plan(args):
    mechanism = load_mechanism(args.mechanism)
    args.rpm_max = crank_rpm(args.rpm_max, mechanism, '--rpm-max')
    # the scene (the reference) is the richest model whatever the user fixed
    scene_args = argparse.Namespace(**{**vars(args), 'rigid_crank': False,
                                       'no_geometric_stiffness': False})
    base, fixed = model_options(scene_args), plan_fixed(args)
    search = quick_plan(mechanism, base, args.rpm_max, fixed) if args.quick else {}
    with Progress('plan', unit='step') as progress:
        result = run_plan(mechanism, base, args.rpm_max, args.tolerance, args.rate_hz,
                          fixed=fixed, progress=progress, **search)
    text = plan_table(result)
    if args.params_out:
        if not result.get('choice'):
            emit(result, text, args.json)       # the table says why, the error line what
        options = chosen_options(result)
        model = load_model(mechanism, options, args)
        result['params'] = write_params_file(args.params_out, mechanism, options, model, args)
        text += (f'\nnode parameters: {args.params_out} (flexlink_node --ros-args '
                 f'--params-file {args.params_out})')
    return emit(result, text, args.json)


def _bench_lines(result):
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


def _bench(args):
    mechanism = load_mechanism(args.mechanism)
    with Progress('bench', unit='step') as progress:
        result = run_bench(mechanism, model_options(args), args.rate_hz, progress=progress)
    if not args.no_chart:
        chart = pathlib.Path(args.out) / 'estimator_error_vs_cost.png'
        result['chart'] = str(plot_error_vs_cost(result['configurations'], chart))
    return emit(result, '\n'.join(_bench_lines(result)), args.json)


def register(subparsers):
    """Add the estimate, plan and bench subcommands."""
    parser = subparsers.add_parser('estimate', help='streaming estimator on a synthetic '
                                   'constant-speed crank signal (last revolution)')
    add_estimator_arguments(parser)
    parser.add_argument('--rpm', type=float, default=None, help='crank speed [rpm] (default: '
                        "the mechanism file's crank_speed_rpm)")
    parser.add_argument('--seconds', type=float, default=3.0, help='signal length [s]')
    parser.add_argument('--jitter', type=float, default=0.0,
                        help='relative sample-time jitter, steps (1 +- jitter) / rate')
    parser.add_argument('--no-warm-start', action='store_true',
                        help='start from the static deflection, not the periodic state')
    parser.add_argument('--seed', type=int, default=0, help='jitter random seed')
    parser.add_argument('--nonlinear', choices=CHOICES, default='auto',
                        help='the reduced geometrically nonlinear model: auto (default: where '
                        "the linear estimate's validity indicator says it is not valid), on, "
                        "off; the deflections reported are the chosen model's")
    add_chart_argument(parser)
    parser.set_defaults(func=_estimate)

    parser = subparsers.add_parser('plan', help='smallest model (physics and size) meeting a '
                                   'tolerance against the full-order response of the scene '
                                   '(flexible crank, geometric stiffness, refined elements, '
                                   "--bearings); --elements-per-link sets the reference's "
                                   'elements; --rigid-crank/--flexible-crank and '
                                   '--no-geometric-stiffness fix those choices in every '
                                   'candidate (otherwise the plan tries both)')
    add_estimator_arguments(parser, second_order=False)
    parser.set_defaults(rigid_crank=None)   # None: the plan chooses the crank model
    parser.add_argument('--rpm-max', type=float, default=None, help='largest speed [rpm] '
                        "(default: the mechanism file's crank_speed_rpm)")
    parser.add_argument('--tolerance', type=float, default=0.01,
                        help='relative RMS error target (default 0.01)')
    parser.add_argument('--params-out', default=None, metavar='FILE',
                        help="write the choice as the node's parameters file (every model "
                        'choice, the speed range, criterion thresholds of this cycle)')
    parser.add_argument('--quick', action='store_true',
                        help="size the reduction only: the reference is the file's own "
                        'physics (its elements per link, flexible crank), one speed '
                        '(--rpm-max), one grid; minutes instead of a quarter of an hour')
    parser.set_defaults(func=_plan)

    parser = subparsers.add_parser('bench', help='estimator cost and accuracy side by side')
    add_estimator_arguments(parser)
    parser.add_argument('--out', default='out', help='directory of the chart (default out/)')
    parser.add_argument('--no-chart', action='store_true', help='skip the chart')
    parser.set_defaults(func=_bench)
