"""
The streaming estimator with ``second_order='dynamic'`` against the Exudyn peer.

``python docs/studies/dynamic_second_order_peer.py [--rpm 269 391] [--elements 8]
[--no-gravity] [--cache DIR] [--cost] [--json]`` feeds :class:`StreamingEstimator` (the path of
the node, ``flexlink estimate`` and ``replay``) a constant-speed crank stream with measured
speeds, 720 samples per revolution (the peer's grid), rigid crank and rigid bearings, once
with the quasi-static second order (default sizes) and once with the dynamic pass (its
default sizes, :data:`core.options.DYNAMIC_SIZES`), and prints the last revolution's p2p
error against the peer per output; the targets are 12 % (lever tip) and 4 % (coupler
mid-point). ``--cost`` times both estimators per sample (CPU time, alternating rounds, medians).
"""

import argparse
import dataclasses
import json
import math
import time

from flexlink_ros.core.estimation.streaming import StreamingEstimator
from flexlink_ros.core.mechanism_file import load_mechanism
from flexlink_ros.core.options import ModelOptions, SECOND_ORDER_PASSES
from flexlink_ros.core.reduction.mechanism_model import model_for_mechanism
from flexlink_ros.studies.peer_exudyn import compare, revolution_slice
from flexlink_ros.studies.peer_model import OUTPUT_KEYS
from flexlink_ros.studies.validation import peer_run, Settings
import numpy as np

SAMPLES = 720
REVOLUTIONS = 8
# The targets for the streaming estimate: lever tip, coupler mid-point p2p.
TARGETS = (0.12, 0.12, 0.04, 0.04)


def case_options(rpm, elements, second_order):
    """Options of the case: rigid crank, rigid bearings, order 2, the pass's default sizes."""
    return ModelOptions.linear(elements_per_link=elements, bearings='rigid', order=2,
                               second_order=second_order,
                               speed_max=max(ModelOptions.speed_max, 1.05 * rpm * math.pi / 30.0))


def streamed_revolution(model, rpm, samples=SAMPLES, revolutions=REVOLUTIONS, start=0.0):
    """
    Stream an estimator of ``model`` at constant speed; its last revolution's outputs.

    Samples at crank angles ``start + 2 pi k / samples`` with the measured speed (the
    estimator warm-starts on the periodic orbit; the dynamic pass's state starts at rest and
    settles over the revolutions).

    Returns
    -------
    angles : ndarray, shape (samples,)
        The last revolution's crank angles, from ``start`` [rad].
    outputs : ndarray, shape (samples, 4)
        Lever tip and coupler mid-point deflections there [m].

    """
    speed = rpm * math.pi / 30.0
    estimator = StreamingEstimator(model)
    period_ns = 60e9 / rpm
    count = samples * revolutions
    outputs = np.empty((samples, 4))
    for k in range(count + 1):
        sample = estimator.update(round(k * period_ns / samples),
                                  start + 2.0 * math.pi * k / samples, speed)
        if k >= count - samples + 1:
            outputs[(k - 1) % samples] = sample.lever_tip + sample.coupler_mid
    order = np.roll(np.arange(samples), 1)      # the last sample is the revolution's start
    return start + 2.0 * math.pi * np.arange(samples) / samples, outputs[order]


def against_peer(mechanism, rpm, elements=8, gravity=True, cache=None, revolutions=REVOLUTIONS):
    """
    P2p errors of the streamed estimates against the peer, per second-order pass.

    Returns
    -------
    dict
        'rpm', 'elements', 'gravity', 'peer_p2p' [m] and per pass ('quasi-static', 'dynamic')
        'r' (basis size) and 'p2p_error' (OUTPUT_KEYS order), and 'meets_targets'.

    """
    if not gravity:
        mechanism = dataclasses.replace(mechanism, gravity=(0.0, 0.0))
    peer = peer_run(mechanism, rpm, Settings(elements_per_link=elements, gravity=gravity,
                                             cache=cache))
    start = float(peer['crank_angle'][revolution_slice(peer).start])
    out = {'rpm': rpm, 'elements': elements, 'gravity': bool(gravity)}
    for kind in SECOND_ORDER_PASSES:
        model = model_for_mechanism(mechanism, case_options(rpm, elements, kind))
        angles, values = streamed_revolution(model, rpm, revolutions=revolutions,
                                             start=start % (2.0 * math.pi))
        response = {'crank_angle': angles, **dict(zip(OUTPUT_KEYS, values.T))}
        table = compare(peer, response)
        errors = [table[key]['p2p_error'] for key in OUTPUT_KEYS]
        out['peer_p2p'] = [table[key]['peer_p2p'] for key in OUTPUT_KEYS]
        out[kind] = {'r': model.size, 'p2p_error': errors,
                     'meets_targets': all(abs(e) <= t for e, t in zip(errors, TARGETS))}
    return out


def cost(mechanism, rpm, elements=8, rounds=9, samples=600):
    """
    CPU time per sample [ns] of the streaming estimator's update, per pass (medians).

    Alternating rounds of ``samples`` 1 kHz samples at constant speed after a warm start;
    returns {'quasi-static': ns, 'dynamic': ns}.
    """
    speed = rpm * math.pi / 30.0
    estimators = {}
    for kind in SECOND_ORDER_PASSES:
        estimator = StreamingEstimator(model_for_mechanism(
            mechanism, case_options(rpm, elements, kind)))
        estimator.update(0, 0.0, speed)
        estimators[kind] = estimator
    times = {kind: [] for kind in estimators}
    stamp = 0
    for _ in range(rounds):
        first = stamp
        for kind, estimator in estimators.items():
            before = time.process_time_ns()
            for k in range(1, samples + 1):
                estimator.update((first + k) * 1_000_000, speed * (first + k) * 1e-3, speed)
            times[kind].append((time.process_time_ns() - before) / samples)
        stamp = first + samples
    return {kind: float(np.median(values)) for kind, values in times.items()}


def format_result(result):
    """Format :func:`main`'s result as text (p2p errors in %, costs in us)."""
    lines = []
    for case in result['cases']:
        lines.append(f"{case['rpm']:.0f} rpm, gravity {'on' if case['gravity'] else 'off'}, "
                     f"{case['elements']} elements per link; p2p error against the peer "
                     f"({', '.join(OUTPUT_KEYS)}), %:")
        for kind in SECOND_ORDER_PASSES:
            entry = case[kind]
            errors = ' '.join(f'{100 * e:+6.2f}' for e in entry['p2p_error'])
            lines.append(f"  {kind:12s} r={entry['r']:2d} {errors}"
                         f"{'  targets met' if entry['meets_targets'] else '  targets MISSED'}")
    for rpm, entry in result.get('cost', {}).items():
        lines.append(f"{rpm} rpm, CPU per sample: quasi-static {entry['quasi-static'] / 1e3:.1f} "
                     f"us, dynamic {entry['dynamic'] / 1e3:.1f} us")
    return '\n'.join(lines)


def main(argv=None):
    """Print :func:`against_peer` per speed (and :func:`cost` with ``--cost``)."""
    parser = argparse.ArgumentParser(prog='python docs/studies/dynamic_second_order_peer.py',
                                     description=__doc__.strip().splitlines()[0])
    parser.add_argument('--mechanism', default='cho1992')
    parser.add_argument('--rpm', type=float, nargs='+', default=[269.0, 391.0])
    parser.add_argument('--elements', type=int, default=8)
    parser.add_argument('--no-gravity', action='store_true')
    parser.add_argument('--cache', default=None, help='directory of cached peer runs')
    parser.add_argument('--cost', action='store_true')
    parser.add_argument('--json', action='store_true')
    args = parser.parse_args(argv)
    mechanism = load_mechanism(args.mechanism)
    result = {'cases': [against_peer(mechanism, rpm, args.elements, not args.no_gravity,
                                     args.cache) for rpm in args.rpm]}
    if args.cost:
        result['cost'] = {f'{rpm:g}': cost(mechanism, rpm, args.elements) for rpm in args.rpm}
    print(json.dumps(result, indent=1) if args.json else format_result(result))
    return 0


__all__ = ['case_options', 'streamed_revolution', 'against_peer', 'cost', 'format_result',
           'main']


if __name__ == '__main__':
    raise SystemExit(main())
