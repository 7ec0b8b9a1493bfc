"""
The dynamic second-order pass per basis size: accuracy and cost of its step.

``python docs/studies/dynamic_second_order_study.py [--rpm 391] [--elements 8]
[--sizes 4,2 8,4] [--peer] [--cost] [--no-gravity] [--json]`` streams the numpy step of the
pass (core/estimation/second_order_dynamic_step.py) at constant speed (rigid crank, rigid
bearings, gravity unless ``--no-gravity``) per basis size and prints its coupler and lever
p2p against the full-order pass (core/fe/second_order_dynamic.py) and, with ``--peer``,
against the Exudyn peer, next to the quasi-static estimate of the same model. ``--cost``
times, in alternating rounds, the numpy step with and without the pass and the compiled
order-2 step of each basis, and the pass's own work compiled
(``benchmarks/dynamic_second_order_bench.py``).
"""

import argparse
import dataclasses
import json
import math
import pathlib
import sys
import time

from flexlink_ros.core.estimation import native
from flexlink_ros.core.estimation.second_order_dynamic_kernel import DynamicPassKernel
from flexlink_ros.core.estimation.second_order_dynamic_step import (DynamicSecondOrderStep,
                                                                    steady_revolution)
from flexlink_ros.core.estimation.step import NumpyStep
from flexlink_ros.core.estimation.streaming import StreamingEstimator
from flexlink_ros.core.estimation.tables import step_tables
from flexlink_ros.core.fe.linkage import FlexibleLinkage
from flexlink_ros.core.fe.second_order_dynamic import dynamic_pass
from flexlink_ros.core.fe.second_order_full import corrected_response
from flexlink_ros.core.fe.simulate import periodic_response
from flexlink_ros.core.mechanism_file import load_mechanism
from flexlink_ros.core.options import ModelOptions
from flexlink_ros.core.reduction.mechanism_model import fe_mechanism, model_for_mechanism
from flexlink_ros.core.reduction.second_order_dynamic_tables import load_for_model
from flexlink_ros.studies.peer_exudyn import compare, peer_response
from flexlink_ros.studies.peer_model import OUTPUT_KEYS
import numpy as np

# The compiled kernels' timers live with the benchmarks, beside this folder.
sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[2] / 'benchmarks'))
from dynamic_second_order_bench import time_pass  # noqa: E402, I100

SAMPLES = 720


def case_options(rpm, elements, sizes, order=2):
    """Model options of a case: rigid crank, rigid bearings, basis ``sizes`` (modes, static)."""
    return ModelOptions.linear(modes=sizes[0], static=sizes[1], elements_per_link=elements,
                               bearings='rigid', order=order,
                               speed_max=max(ModelOptions.speed_max, 1.05 * rpm * math.pi / 30.0),
                               soft_modes=0)


def _p2p_errors(outputs, reference):
    return (np.ptp(outputs, axis=0) / np.ptp(reference, axis=0) - 1.0).tolist()


def accuracy(mechanism, rpm, elements, sizes_list, revolutions=10, peer=False, gravity=True):
    """
    Compare the streamed pass and the quasi-static estimate with the full-order pass (and peer).

    Returns
    -------
    dict
        'full_order': p2p [m] of the full-order pass, and its quasi-static and linear p2p
        errors; per basis 'r', 'dynamic' and 'quasi_static' p2p errors against the full-order
        pass; with ``peer`` the 'peer' p2p errors of every response (OUTPUT_KEYS order).
        ``gravity`` False: the mechanism's gravity set to zero (in the peer too).

    """
    if not gravity:
        mechanism = dataclasses.replace(mechanism, gravity=(0.0, 0.0))
    speed = rpm * math.pi / 30.0
    options = case_options(rpm, elements, sizes_list[0])
    linkage = FlexibleLinkage(fe_mechanism(mechanism, options), options)
    linear = periodic_response(linkage, speed, method='full', points=SAMPLES)
    full = dynamic_pass(linkage, linear)
    quasi_static = corrected_response(linkage, linear)['total']
    responses = {'full linear': linear.outputs, 'full quasi-static': quasi_static,
                 'full dynamic': full['total']}
    out = {'rpm': rpm, 'elements': elements, 'gravity': bool(gravity),
           'full_order': {'p2p': np.ptp(full['total'], axis=0).tolist(),
                          'quasi_static': _p2p_errors(quasi_static, full['total']),
                          'linear': _p2p_errors(linear.outputs, full['total'])},
           'bases': []}
    for sizes in sizes_list:
        options = case_options(rpm, elements, sizes)
        model = model_for_mechanism(mechanism, options)
        kernel = DynamicPassKernel(load_for_model(mechanism, options, model).arrays)
        step = {}
        for keep in (True, False):
            # a zero load: the plain quasi-static estimate
            used = kernel if keep else _ZeroLoad(model.size)
            step[keep] = steady_revolution(model, used, speed, SAMPLES, revolutions)[1]
        responses[f'r={model.size} dynamic'] = step[True]
        responses[f'r={model.size} quasi-static'] = step[False]
        out['bases'].append({'sizes': list(sizes), 'r': model.size,
                             'dynamic': _p2p_errors(step[True], full['total']),
                             'quasi_static': _p2p_errors(step[False], full['total'])})
    if peer:
        reference = peer_response(mechanism, rpm, elements_per_link=elements, gravity=gravity)
        out['peer'] = {name: [compare(reference, _as_response(linear.crank_angle, values))[key]
                              ['p2p_error'] for key in OUTPUT_KEYS]
                       for name, values in responses.items()}
    return out


class _ZeroLoad:
    """Loads of zero (the step then is the plain step: q2 stays zero)."""

    def __init__(self, size):
        self.zero = np.zeros((3, size))

    def __call__(self, stored, slots, states, angles):
        return self.zero


def _as_response(angles, values):
    out = {'crank_angle': angles}
    out.update(zip(OUTPUT_KEYS, np.asarray(values).T))
    return out


def _rows(speed, samples):
    angles = np.mod(speed * 1e-3 * (np.arange(samples) + 1.0), 2.0 * math.pi)
    return np.column_stack([np.full(samples, 1e-3), np.ones(samples), angles,
                            np.full(samples, speed), np.zeros(samples),
                            np.full(samples, speed * 1e-3)])


def _cpu_per_row(step, rows):
    records = np.empty((rows.shape[0], native.RECORD_SIZE))
    before = time.process_time_ns()
    step.advance(rows, np.empty(0), records)
    return (time.process_time_ns() - before) / rows.shape[0]


def cost(mechanism, rpm, elements, sizes_list, rounds=5, samples=400, kernel_samples=20000):
    """
    Per-sample CPU time [ns], medians over alternating rounds, per basis.

    'numpy' / 'numpy_dynamic' / 'dynamic': the numpy step without the pass, with it (its
    loads in numpy), and with its loads compiled (the estimator's dynamic step; 1 kHz rows at
    constant speed); 'compiled': the package's compiled order-2 step (the batched rows of the
    replay) of the same model; with ``kernel_samples`` (0: left out, it needs a C compiler)
    'kernel' and 'kernel_tabulated': the pass's own work compiled, with and without the
    static solves (``time_pass`` of ``benchmarks/dynamic_second_order_bench.py``). Returns a
    list of dicts with 'r' and these times.
    """
    speed = rpm * math.pi / 30.0
    rows = _rows(speed, samples)
    out = []
    for sizes in sizes_list:
        options = case_options(rpm, elements, sizes)
        model = model_for_mechanism(mechanism, options)
        shared = step_tables(model)
        estimator = StreamingEstimator(model, step_tables=shared)
        estimator.update(0, 0.0, speed)
        load = load_for_model(mechanism, options, model)
        steps = {'numpy': NumpyStep(model, shared),
                 'numpy_dynamic': DynamicSecondOrderStep(
                     model, shared, DynamicPassKernel(load.arrays, compiled=False)),
                 'dynamic': DynamicSecondOrderStep(model, shared, DynamicPassKernel(load.arrays))}
        for step in steps.values():
            step.start(np.zeros(model.size), np.zeros(model.size), (0.0, speed, 0.0),
                       np.empty(native.RECORD_SIZE))
        times = {name: [] for name in (*steps, 'compiled')}
        for _ in range(rounds):
            for name, step in steps.items():
                times[name].append(_cpu_per_row(step, rows))
            records = np.empty((samples, estimator.last_record.size))
            before = time.process_time_ns()
            estimator.step_rows(_rows(speed, samples), np.empty(0), records)
            times['compiled'].append((time.process_time_ns() - before) / samples)
        entry = {'sizes': list(sizes), 'r': model.size,
                 **{name: float(np.median(v)) for name, v in times.items()}}
        if kernel_samples:
            entry['kernel'] = time_pass(load, kernel_samples, solves=True)[0]
            entry['kernel_tabulated'] = time_pass(load, kernel_samples, solves=False)[0]
        out.append(entry)
    return out


def main(argv=None):
    """Print :func:`accuracy` (and :func:`cost` with ``--cost``)."""
    parser = argparse.ArgumentParser(prog='python docs/studies/dynamic_second_order_study.py',
                                     description=__doc__.strip().splitlines()[0])
    parser.add_argument('--mechanism', default='cho1992')
    parser.add_argument('--rpm', type=float, default=391.0)
    parser.add_argument('--elements', type=int, default=8)
    parser.add_argument('--sizes', nargs='+', default=['4,2', '8,4'])
    parser.add_argument('--peer', action='store_true')
    parser.add_argument('--cost', action='store_true')
    parser.add_argument('--no-gravity', action='store_true')
    parser.add_argument('--json', action='store_true')
    args = parser.parse_args(argv)
    mechanism = load_mechanism(args.mechanism)
    sizes = [tuple(int(v) for v in s.split(',')) for s in args.sizes]
    result = {'accuracy': accuracy(mechanism, args.rpm, args.elements, sizes, peer=args.peer,
                                   gravity=not args.no_gravity)}
    if args.cost:
        result['cost'] = cost(mechanism, args.rpm, args.elements, sizes)
    if args.json:
        print(json.dumps(result, indent=1))
    else:
        print(format_result(result))
    return 0


def format_result(result):
    """Format :func:`main`'s result as text (p2p errors in %, costs in us)."""
    acc = result['accuracy']
    lines = [f"{acc['rpm']:.0f} rpm, {acc['elements']} elements per link, gravity "
             f"{'on' if acc.get('gravity', True) else 'off'}; p2p error "
             f"against the full-order dynamic pass ({', '.join(OUTPUT_KEYS)}), %:"]

    def pct(values):
        return ' '.join(f'{100 * v:+6.2f}' for v in values)

    lines.append(f"  full order quasi-static      {pct(acc['full_order']['quasi_static'])}")
    for entry in acc['bases']:
        for name in ('quasi_static', 'dynamic'):
            lines.append(f"  r={entry['r']:2d} streamed {name:13s} {pct(entry[name])}")
    for name, values in acc.get('peer', {}).items():
        lines.append(f'  against the peer: {name:22s} {pct(values)}')
    for entry in result.get('cost', []):
        lines.append(f"  r={entry['r']:2d} per sample: numpy {entry['numpy'] / 1e3:7.1f} us, "
                     f"numpy + pass {entry['numpy_dynamic'] / 1e3:7.1f} us, "
                     f"numpy + compiled pass {entry['dynamic'] / 1e3:7.1f} us, compiled order 2 "
                     f"{entry['compiled'] / 1e3:6.2f} us")
        if 'kernel' in entry:
            lines.append(f"       the pass compiled {entry['kernel'] / 1e3:5.2f} us "
                         f"({entry['kernel_tabulated'] / 1e3:5.2f} us without the static solves)")
    return '\n'.join(lines)


__all__ = ['case_options', 'accuracy', 'cost', 'main', 'format_result']


if __name__ == '__main__':
    raise SystemExit(main())
