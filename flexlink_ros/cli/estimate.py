"""
`flexlink estimate`, `flexlink plan`: the streaming estimator offline.

- ``estimate`` runs :class:`StreamingEstimator` on a synthetic constant-speed crank signal
  (optionally jittered) and prints the last full revolution (:mod:`studies.synthetic`); its
  JSON has the validity indicator's ``nonlinearity`` (``indicator_max``, ``valid``,
  ``threshold``) over that revolution.
- ``plan`` picks the smallest model (physics: elements per link, rigid crank, geometric
  stiffness, bearings; size: modes, static directions, grid) meeting a tolerance against the
  full-order response of the richest model of the scene over a speed range, and shows the
  error and cost of the alternatives (:mod:`studies.plan`); ``--params-out FILE`` writes
  the choice as the node's parameters file (:mod:`.plan_params`).
"""

import argparse
import dataclasses

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
                      columns('coupler_mid'), criterion,
                      thresholds=criterion_thresholds(mechanism),
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


def register(subparsers):
    """Add the estimate and plan subcommands."""
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
