"""
``flexlink validate``: the full-order model against the nonlinear Exudyn peer.

    flexlink validate --peer exudyn --rpm R [R ...] [--sweep START:STOP:STEP]
                      [--bearings rigid|flexible] [--gravity | --no-gravity]
                      [--elements-per-link N] [--zeta Z | --stiffness-damping BETA_S]
                      [--revolutions N] [--cache DIR] [--nonlinear]
                      [--chart PATH] [--json]

Prints, per speed, the peer's peak-to-peak and, for the linear KED, linear + quasi-static
second order and linear + the dynamic second-order pass, p2p, p2p error and relative RMS per
output; with ``--sweep`` one line per speed with the validity indicator and where its flag
turns. With ``--nonlinear``: the linear and the geometrically nonlinear full order damped as
the peer (:mod:`studies.nonlinear_validation`), with the orbit's Floquet multipliers, Newton
iterations and cost per step. The peer is the optional extra ``pip install '.[peer]'``
(exudyn). The computation is :mod:`studies.validation`, the chart :mod:`report.validation`.
"""

import argparse

from .main import emit
from .progress import Progress
from ..report.validation import plot_validation
from ..studies import nonlinear_validation, validation


def register(subparsers):
    """Add the `validate` subcommand."""
    parser = subparsers.add_parser(
        'validate', help='compare the FE model (linear, + 2nd order, + dynamic pass) with '
        'the nonlinear Exudyn peer')
    parser.add_argument('--peer', default='exudyn', choices=validation.PEERS,
                        help='the nonlinear peer (default: %(default)s; '
                        "`pip install '.[peer]'`)")
    parser.add_argument('--mechanism', default='cho1992',
                        help='mechanism YAML file or bare name (default: %(default)s)')
    parser.add_argument('--rpm', type=float, nargs='+', default=[], metavar='R',
                        help='crank speeds [rpm]')
    parser.add_argument('--sweep', default=None, metavar='START:STOP:STEP',
                        help='a speed sweep [rpm], STOP included (with the validity flag)')
    parser.add_argument('--bearings', choices=tuple(validation.BEARINGS), default='rigid',
                        help='rigid pins, or the bearing springs of the mechanism file '
                        '(default: %(default)s)')
    parser.add_argument('--gravity', action=argparse.BooleanOptionalAction, default=True,
                        help="apply the mechanism's gravity in both models (default: on)")
    parser.add_argument('--elements-per-link', type=int, default=validation.DEFAULT_ELEMENTS,
                        metavar='N', help='elements per flexible link in both models '
                        '(default: %(default)s)')
    parser.add_argument('--zeta', type=float, default=None,
                        help='modal damping ratio of the package (default: the mechanism '
                        "file; 0.012 matches the peer's beta = 1e-4 s at the first modes)")
    parser.add_argument('--stiffness-damping', type=float, default=None, metavar='BETA_S',
                        help='damp the package and the peer with beta [s] on the strain rates '
                        'and bearing deflection rates (default: the package with modal zeta, '
                        'the peer with beta 1e-4 s)')
    parser.add_argument('--revolutions', type=int, default=None, metavar='N',
                        help='peer revolutions (default: until its start transient decays)')
    parser.add_argument('--cache', default=None, metavar='DIR',
                        help='keep peer runs in DIR and reuse them')
    parser.add_argument('--nonlinear', action='store_true',
                        help='compare the linear and the geometrically nonlinear full order, '
                        'damped as the peer (beta; modal zeta 0 unless --zeta)')
    parser.add_argument('--chart', default=None, metavar='PATH', help='write a PNG chart')
    parser.add_argument('--json', action='store_true', help='print one JSON object')
    parser.set_defaults(func=validate_command)


def validate_command(args):
    """Run `flexlink validate`; returns the exit code."""
    validation.require_peer(args.peer)
    speeds = list(args.rpm)
    if args.sweep:
        speeds += validation.sweep_speeds(args.sweep)
    if not speeds:
        raise ValueError('give crank speeds with --rpm R [R ...] or --sweep START:STOP:STEP')
    settings = validation.Settings(
        elements_per_link=args.elements_per_link, bearings=args.bearings,
        gravity=args.gravity, zeta=args.zeta, revolutions=args.revolutions,
        stiffness_damping=args.stiffness_damping, cache=args.cache)
    speeds = sorted(set(speeds))
    if args.nonlinear:
        return _nonlinear(args, speeds, settings)
    records = []
    with Progress('validate', total=len(speeds), unit='speed') as progress:
        for rpm in speeds:
            progress(len(records), what=f'{rpm:g} rpm: peer, linear, dynamic pass')
            records.append(validation.validate_speed(args.mechanism, rpm, settings))
        progress(len(records), what='done')
    sweep = bool(args.sweep)
    if args.chart:
        plot_validation(records, args.chart, sweep=sweep or None)
    result = {'peer': args.peer, 'records': [validation.without_series(r) for r in records],
              'flag_turns': validation.flag_turns(records), 'chart': args.chart}
    if sweep:
        text = validation.format_sweep(records)
    else:
        text = '\n\n'.join(validation.format_speed(r) for r in records)
    if args.chart:
        text += f'\nchart: {args.chart}'
    return emit(result, text, args.json)


def _nonlinear(args, speeds, settings):
    """Run ``validate --nonlinear`` over the speeds; returns the exit code."""
    if args.chart:
        raise ValueError('--chart draws the linear models: leave it out with --nonlinear')
    records = []
    with Progress('validate', total=len(speeds), unit='speed') as progress:
        for rpm in speeds:
            progress(len(records), what=f'{rpm:g} rpm: peer, linear, nonlinear')
            records.append(nonlinear_validation.validate_nonlinear(args.mechanism, rpm,
                                                                   settings))
        progress(len(records), what='done')
    result = {'peer': args.peer, 'model': 'nonlinear',
              'records': [nonlinear_validation.without_series(r) for r in records]}
    text = '\n\n'.join(nonlinear_validation.format_nonlinear(r) for r in records)
    return emit(result, text, args.json)
