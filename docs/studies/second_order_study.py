"""
Linear KED and linear + second order against the nonlinear Exudyn peer.

``python docs/studies/second_order_study.py [--rpm 269 391] [--gravity both]
[--elements 8] [--json]`` prints, per speed and gravity setting (rigid crank, rigid bearings),
the peer's peak-to-peak of the four outputs, the package's linear full-order response and the
same plus the second-order motion of :mod:`core.fe.second_order_full` (p2p error and relative
RMS against the peer), and the streaming estimate of order 2 (the reduced model with its
second-order tables, default basis, streamed by core/estimation as the node does).
``--cost`` prints the multiply-adds per sample of the streaming form for the reduced models,
and ``--bench`` times it compiled (needs a C compiler).
"""

import argparse
import dataclasses
import json
import math
import pathlib
import sys

from flexlink_ros.core.estimation.segment_replay import replay
from flexlink_ros.core.fe.linkage import FlexibleLinkage
from flexlink_ros.core.fe.second_order_full import corrected_response
from flexlink_ros.core.fe.second_order_geometry import FORMS
from flexlink_ros.core.fe.simulate import periodic_response
from flexlink_ros.core.options import DEFAULT_SIZES, ModelOptions
from flexlink_ros.core.reduction.mechanism_model import fe_mechanism, model_for_mechanism
from flexlink_ros.studies.peer_exudyn import compare, peak_to_peak, peer_response
from flexlink_ros.studies.peer_linear import linear_model
from flexlink_ros.studies.peer_model import DEFAULT_ELEMENTS, OUTPUT_KEYS, resolve_mechanism
import numpy as np

# The compiled kernels' timers live with the benchmarks, beside this folder.
sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[2] / 'benchmarks'))
import second_order_bench  # noqa: E402
from second_order_forms import factored_forms, step_cost  # noqa: E402, I100

TARGETS = {'lever_tip': 0.10, 'coupler_mid': 0.03}
# The streaming estimate's targets against the peer (p2p relative error).
STREAM_TARGETS = {'lever_tip': 0.12, 'coupler_mid': 0.04}
# Samples per revolution fed to the streaming estimate (the peer's output grid).
STREAM_SAMPLES = 720


def _as_response(angles, values):
    out = {'crank_angle': angles}
    out.update(zip(OUTPUT_KEYS, np.asarray(values).T))
    return out


def run_case(mechanism, rpm, gravity, elements, points=720, zeta=None, revolutions=None):
    """
    Peer, linear and linear + second order at one speed (rigid crank, rigid bearings).

    Returns
    -------
    dict
        'rpm', 'gravity', 'elements', 'peer_p2p' (per output, m), 'linear' and 'second_order'
        (per output: :func:`peer_exudyn.compare` entries), 'periodicity' of the peer,
        'max_sums' (largest S per :data:`core.fe.second_order_geometry.FORMS`, m), 'info'.

    """
    response = peer_response(mechanism, rpm, elements_per_link=elements, gravity=gravity,
                             revolutions=revolutions)
    linkage = linear_model(mechanism, elements_per_link=elements, gravity=gravity)
    linear = periodic_response(linkage, rpm * math.pi / 30.0, method='full', points=points,
                               zeta=zeta)
    corrected = corrected_response(linkage, linear)
    p2p = peak_to_peak(response)
    streamed = reduced_response(mechanism, rpm, gravity, elements, points)
    return {'rpm': float(rpm), 'gravity': bool(gravity), 'elements': elements,
            'peer_p2p': {k: p2p[k] for k in OUTPUT_KEYS},
            'periodicity': p2p['periodicity'],
            'linear': compare(response, _as_response(linear.crank_angle, linear.outputs)),
            'second_order': compare(response, _as_response(linear.crank_angle,
                                                           corrected['total'])),
            'reduced': compare(response, _as_response(*streamed[:2])),
            'reduced_size': streamed[2],
            'max_sums': dict(zip(FORMS, np.abs(corrected['detail']['sums']).max(axis=0))),
            'info': {'peer_cpu_s': response['info']['cpu_s'],
                     'linear_wall_s': linear.info['wall_s'], 'zeta': linear.info['zeta']}}


def reduced_response(mechanism, rpm, gravity, elements, points=720, sizes=None, grid=128):
    """
    Run the streaming estimate of order 2 at constant speed: its last of two revolutions.

    The reduced model of order 2 (core/reduction, with its second-order tables) streamed by
    the estimator (core/estimation, offline replay: the node's numbers) on 720 samples per
    revolution from crank angle 0, warm-started at the measured speed.

    Parameters
    ----------
    mechanism : Mechanism or str
        A Mechanism, or a mechanism file path or bare name.
    rpm, gravity, elements :
        As :func:`run_case` (rigid crank, rigid bearings).
    points : int
        Output points per revolution (a divisor of the 720 samples).
    sizes : tuple of int or None
        (modes, static) of the basis; None for the default (4, 2).
    grid : int
        Crank-angle grid of the tables.

    Returns
    -------
    angles : ndarray, shape (points,)
    outputs : ndarray, shape (points, 4)
        Linear (with the residual correction) + second order [m].
    size : int
        r.

    """
    mech = resolve_mechanism(mechanism)
    if not gravity:
        mech = dataclasses.replace(mech, gravity=(0.0, 0.0))
    modes, static = sizes or (None, None)
    options = ModelOptions.linear(modes=modes, static=static, grid_size=grid,
                                  elements_per_link=elements, bearings='rigid', order=2,
                                  speed_max=max(ModelOptions.speed_max,
                                                1.05 * rpm * math.pi / 30.0))
    model = model_for_mechanism(mech, options)
    speed = rpm * math.pi / 30.0
    angles = 2.0 * math.pi * np.arange(2 * STREAM_SAMPLES) / STREAM_SAMPLES
    stamps = np.round(angles / speed * 1e9).astype(np.int64)
    out = replay(model, stamps, angles, np.full(angles.size, speed))
    last = slice(STREAM_SAMPLES, 2 * STREAM_SAMPLES, STREAM_SAMPLES // points)
    outputs = np.hstack([out['lever_tip'], out['coupler_mid']])[last]
    return np.mod(angles[last], 2.0 * math.pi), outputs, model.size


def meets_targets(record, name='second_order'):
    """
    Tell whether a response meets the p2p targets, per output.

    ``name`` 'second_order' (the full order + second order: :data:`TARGETS`) or 'reduced' (the
    streaming estimate of order 2: :data:`STREAM_TARGETS`).
    """
    targets = TARGETS if name == 'second_order' else STREAM_TARGETS
    return {key: abs(record[name][key]['p2p_error'])
            <= targets[key.rsplit('_', 1)[0]] for key in OUTPUT_KEYS}


def format_record(record):
    """Format the text table of one case."""
    lines = [f"{record['rpm']:g} rpm, gravity {'on' if record['gravity'] else 'off'}, "
             f"{record['elements']} elements per link, rigid crank and bearings "
             f"(modal zeta {record['info']['zeta']:g} in the linear model)",
             '  ' + ' ' * 24 + ''.join(f'{k:>16s}' for k in OUTPUT_KEYS),
             '  peer p2p [um]           ' + ''.join(f"{record['peer_p2p'][k] * 1e6:16.2f}"
                                                    for k in OUTPUT_KEYS)]
    ok, streamed = meets_targets(record), meets_targets(record, 'reduced')
    for label, name in (('linear', 'linear'), ('linear + 2nd', 'second_order'),
                        (f"streamed r={record['reduced_size']} o2", 'reduced')):
        table = record[name]
        lines.append(f'  {label + " p2p [um]":24s}' + ''.join(
            f"{table[k]['other_p2p'] * 1e6:16.2f}" for k in OUTPUT_KEYS))
        lines.append(f'  {label + " p2p err":24s}' + ''.join(
            f"{100 * table[k]['p2p_error']:15.1f}%" for k in OUTPUT_KEYS))
        lines.append(f'  {label + " rel RMS":24s}' + ''.join(
            f"{100 * table[k]['rms_error']:15.1f}%" for k in OUTPUT_KEYS))
    lines.append('  target (10 % tip, 3 % mid) ' + ' '.join(
        f"{k}: {'met' if ok[k] else 'MISSED'}" for k in OUTPUT_KEYS))
    lines.append('  streamed (12 %, 4 %)       ' + ' '.join(
        f"{k}: {'met' if streamed[k] else 'MISSED'}" for k in OUTPUT_KEYS))
    return '\n'.join(lines)


def reduced_costs(mechanism):
    """
    Count multiply-adds per sample of the reduced models.

    By :func:`second_order_forms.step_cost`, for their default sizes
    (core.options.DEFAULT_SIZES) with the mechanism's elements per link.
    """
    out = []
    for (bearings, rigid_crank), (modes, static) in DEFAULT_SIZES.items():
        options = ModelOptions.linear(bearings=bearings, rigid_crank=rigid_crank, grid_size=8)
        linkage = FlexibleLinkage(fe_mechanism(mechanism, options),
                                  options)
        size = modes + static
        basis = np.eye(linkage.size)[:, :size] if size <= linkage.size else None
        if basis is None:
            continue
        factored = factored_forms(linkage, basis)
        cost = step_cost(factored, size)
        out.append({'bearings': bearings, 'rigid_crank': rigid_crank, 'r': size,
                    'elements': mechanism.elements_per_link, 'dofs': linkage.size, **cost})
    return out


def main(argv=None):
    """Print the peer / linear / linear + second-order table (see the module notes)."""
    parser = argparse.ArgumentParser(prog='python docs/studies/second_order_study.py',
                                     description=__doc__.strip().splitlines()[0])
    parser.add_argument('--mechanism', default='cho1992')
    parser.add_argument('--rpm', type=float, nargs='+', default=[269.0, 391.0])
    parser.add_argument('--gravity', choices=('off', 'on', 'both'), default='both')
    parser.add_argument('--elements', type=int, default=DEFAULT_ELEMENTS)
    parser.add_argument('--zeta', type=float, default=None,
                        help='modal damping ratio of the linear model (default: mechanism)')
    parser.add_argument('--revolutions', type=int, default=None,
                        help='peer revolutions (default: until the transient has decayed)')
    parser.add_argument('--cost', action='store_true', help='print the streaming cost only')
    parser.add_argument('--bench', action='store_true',
                        help='time the factored step compiled (needs cc)')
    parser.add_argument('--json', action='store_true')
    args = parser.parse_args(argv)
    mech = resolve_mechanism(args.mechanism)
    if args.cost or args.bench:
        costs = reduced_costs(mech)
        if args.bench:
            for entry in costs:
                entry['compiled_ns'] = second_order_bench.time_factored(
                    mech, entry['bearings'], entry['rigid_crank'], entry['r'])
        print(json.dumps(costs, indent=1, default=float))
        return 0
    gravities = {'off': [False], 'on': [True], 'both': [False, True]}[args.gravity]
    records = [run_case(mech, rpm, g, args.elements, zeta=args.zeta,
                        revolutions=args.revolutions)
               for rpm in args.rpm for g in gravities]
    if args.json:
        print(json.dumps(records, indent=1, default=float))
        return 0
    for record in records:
        print(format_record(record))
    return 0


__all__ = ['TARGETS', 'STREAM_TARGETS', 'run_case', 'reduced_response', 'meets_targets',
           'format_record', 'reduced_costs', 'main']


if __name__ == '__main__':
    raise SystemExit(main())
