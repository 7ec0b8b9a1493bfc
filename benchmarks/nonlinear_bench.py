"""
The reduced nonlinear update against the linear update, in alternating whole processes.

    .venv/bin/python benchmarks/nonlinear_bench.py [--rpm 391] [--seconds 3] [--pairs 3]
                                                   [--basis M ...]

Each round runs two processes in alternating order: one times the linear streaming update
(the compiled step, ``StreamingEstimator.update``) per sample, the other the reduced nonlinear
model's streaming update (``NonlinearFollower.sample``, the node's call: one compiled step
plus its outputs) per sample, on the same synthetic 1 kHz signal (rigid crank, bearing
springs, 8 elements per link, beta 1e-4 s). Both models come from the cache (built once
before the rounds). Prints each run's median and p99 per sample and the offline samples per
second (the linear stream; the nonlinear ``estimate_nonlinear``, many samples per compiled
call), then the medians over the rounds and the ratio. ``--basis`` times the nonlinear update
with each basis size given (0: the size the snapshots' singular values give, the default),
every size in every round, the order reversed every other round.
"""

import argparse
import json
import pathlib
import statistics
import subprocess
import sys
import tempfile
import time

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from flexlink_ros.core.estimation.nonlinear_stream import estimate_nonlinear  # noqa: E402
from flexlink_ros.core.mechanism_file import load_mechanism  # noqa: E402
from flexlink_ros.core.options import ModelOptions  # noqa: E402
from flexlink_ros.core.reduction.mechanism_model import model_for_mechanism  # noqa: E402
from flexlink_ros.core.reduction.nonlinear_model import nonlinear_model_for  # noqa: E402
from flexlink_ros.studies.synthetic import stream_nonlinear_timed, stream_timed  # noqa: E402
from flexlink_ros.studies.synthetic import synthetic_signal  # noqa: E402
from flexlink_ros.studies.synthetic import timing_summary  # noqa: E402
import numpy as np  # noqa: E402

OPTIONS = ModelOptions(rigid_crank=True, bearings='flexible', elements_per_link=8,
                       stiffness_damping=1e-4)


def measure(kind, rpm, seconds, cache, basis=0):
    """Time one model's update per sample (``basis``: the nonlinear basis size); a dict."""
    mech = load_mechanism('cho1992')
    stamps, angles, speeds = synthetic_signal(rpm, seconds, 1000.0)
    started = time.perf_counter()
    if kind == 'linear':
        model = model_for_mechanism(mech, OPTIONS, cache_dir=cache)
        started = time.perf_counter()
        _, update_ns = stream_timed(model, stamps, angles, speeds)
        wall = time.perf_counter() - started
    else:
        tables, _ = nonlinear_model_for(mech, OPTIONS, cache_dir=cache,
                                        basis_size=basis or None)
        _, update_ns = stream_nonlinear_timed(tables, stamps, angles, speeds)
        update_ns = update_ns[1:]
        started = time.perf_counter()
        estimate_nonlinear(tables, stamps, angles, speeds)
        wall = time.perf_counter() - started
    median, p99 = timing_summary(np.asarray(update_ns))
    return {'kind': kind if kind == 'linear' else f'nonlinear m={tables.size}',
            'median_us': median, 'p99_us': p99, 'samples_per_s': len(stamps) / wall}


def run_one(kind, basis, args, cache):
    """One whole process timing one model; its :func:`measure` dict."""
    out = subprocess.run([sys.executable, __file__, '--one', kind, '--rpm', str(args.rpm),
                          '--seconds', str(args.seconds), '--cache-dir', cache,
                          '--basis', str(basis)], capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main():
    """Time the linear and the nonlinear update(s) in alternating processes; print medians."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--rpm', type=float, default=391.0)
    parser.add_argument('--seconds', type=float, default=3.0)
    parser.add_argument('--pairs', type=int, default=3)
    parser.add_argument('--cache-dir', default=None)
    parser.add_argument('--basis', type=int, nargs='+', default=[0],
                        help='nonlinear basis sizes (0: the singular values decide)')
    parser.add_argument('--one', choices=('linear', 'nonlinear'), help=argparse.SUPPRESS)
    args = parser.parse_args()
    cache = args.cache_dir or tempfile.mkdtemp(prefix='nonlinear-bench-')
    if args.one:
        print(json.dumps(measure(args.one, args.rpm, args.seconds, cache, args.basis[0])))
        return
    kinds = [('linear', 0)] + [('nonlinear', size) for size in args.basis]
    for kind, size in kinds:                  # build and cache every model first
        measure(kind, args.rpm, 0.05, cache, size)
    runs = {}
    for pair in range(args.pairs):
        for kind, size in (kinds if pair % 2 == 0 else kinds[::-1]):
            result = run_one(kind, size, args, cache)
            runs.setdefault(result['kind'], []).append(result)
            print(f"round {pair + 1} {result['kind']:15s}: median {result['median_us']:9.1f} us, "
                  f"p99 {result['p99_us']:9.1f} us, {result['samples_per_s']:9.0f} samples/s")
    medians = {kind: statistics.median(r['median_us'] for r in values)
               for kind, values in runs.items()}
    for kind, values in runs.items():
        print(f'{kind:15s}: median of medians {medians[kind]:9.1f} us, median p99 '
              f"{statistics.median(r['p99_us'] for r in values):9.1f} us, median "
              f"{statistics.median(r['samples_per_s'] for r in values):9.0f} samples/s")
    for kind in medians:
        if kind != 'linear':
            print(f"{kind} / linear update median: {medians[kind] / medians['linear']:.1f}x")


if __name__ == '__main__':
    main()
