"""
Time the streaming update around the step: the compiled update against the Python path.

Each round runs ``samples`` in-process updates (StreamingEstimator.update, the node's call) of
a jittered signal at ``rpm`` on two estimators of one model: one with the compiled update
(core/estimation/compiled_update.py: the whole update of an ordinary sample in one C call),
one whose every sample takes the Python path around the same compiled step; which of the two
goes first alternates from round to round. A third estimator times the batched step of as
many rows (step_rows, the replay's call; median over chunks of CHUNK rows, which keep the
GIL as a single sample does). The update minus the batched step is what the estimator adds
around the step. Both estimators' samples are checked to agree before anything is reported.
``python -m flexlink_ros.studies.update_bench`` prints it for the node's default model.
"""

import argparse
import json
import math
import time

import numpy as np

from .bench import node_model_options
from .synthetic import synthetic_signal
from ..core.estimation.compiled_update import compiled_samples, use_python_path
from ..core.estimation.streaming import StreamingEstimator
from ..core.mechanism_file import load_mechanism
from ..core.reduction.pipeline import model_for_mechanism

# Rows per batched call of the step (below the compiled step's GIL release, as one sample).
CHUNK = 50
# Updates left out of each round's figures (the first after a switch of estimator).
SETTLE = 50


def _update_round(estimator, signal):
    """Durations [us] of the updates of ``signal`` (stamps, angles, speeds lists); the last."""
    clock = time.perf_counter_ns
    update = estimator.update
    times = []
    for stamp, angle, speed in zip(*signal):
        before = clock()
        sample = update(stamp, angle, speed)
        times.append(clock() - before)
    return np.array(times[SETTLE:]) * 1e-3, sample


def _rows_round(estimator, speed, rows, angle):
    """
    Time the batched step over chunks of CHUNK rows at constant speed from crank ``angle``.

    Returns the median [us] per row and the crank angle reached.
    """
    per_row = []
    for _ in range(max(1, rows // CHUNK)):
        angles = np.mod(angle + speed * 1e-3 * np.arange(1, CHUNK + 1), 2.0 * math.pi)
        table = np.column_stack([np.full(CHUNK, 1e-3), np.ones(CHUNK), angles,
                                 np.full(CHUNK, speed), np.zeros(CHUNK),
                                 np.full(CHUNK, speed * 1e-3)])
        records = np.empty((CHUNK, estimator.last_record.size))
        before = time.perf_counter_ns()
        estimator.step_rows(table, np.empty(0), records)
        per_row.append((time.perf_counter_ns() - before) * 1e-3 / CHUNK)
        angle = float(angles[-1])
    return float(np.median(per_row)), angle


def _check_agree(compiled, python):
    """Raise unless both paths' last samples have the same flags and state (to 1e-9)."""
    same = compiled.flags == python.flags and np.allclose(
        compiled.modal + compiled.lever_tip, python.modal + python.lever_tip, rtol=1e-9,
        atol=0.0)
    if not same:
        raise RuntimeError('the compiled update and the Python path disagree')


def update_overhead(model, rpm=391.0, rounds=9, samples=3000, jitter=0.3):
    """
    Time the update with the compiled path and with the Python path, and the batched step.

    Parameters
    ----------
    model : ReducedModel
        The model (the node's default: :func:`.bench.node_model_options`).
    rpm : float
        Crank speed of the signal [rpm] (1 kHz, ``jitter`` of each interval).
    rounds, samples : int
        Rounds, and updates per estimator and round.
    jitter : float
        Relative jitter of the sample intervals.

    Returns
    -------
    dict
        'compiled' and 'python': median and p99 [us] (medians over the rounds); 'step_us'
        (batched step per row); 'around_step_us' of each path (its median minus the step);
        'saved_us' (median of the rounds' differences); 'taken' (samples the compiled path
        estimated) and 'samples'.

    """
    signal = synthetic_signal(rpm, rounds * samples / 1000.0 + 1.0, 1000.0, jitter, seed=0)
    signal = [values.tolist() for values in signal]
    fast, python, rows = (StreamingEstimator(model) for _ in range(3))
    use_python_path(python)
    speed = rpm * math.pi / 30.0
    rows.update(0, 0.0, speed)
    timed = {'compiled': [], 'python': []}
    steps, angle = [], 0.0
    for k in range(rounds):
        part = [values[k * samples:(k + 1) * samples] for values in signal]
        order = (('compiled', fast), ('python', python))
        results = {}
        for name, estimator in (order if k % 2 == 0 else order[::-1]):
            times, results[name] = _update_round(estimator, part)
            timed[name].append((float(np.median(times)), float(np.percentile(times, 99))))
        _check_agree(results['compiled'], results['python'])
        step, angle = _rows_round(rows, speed, samples, angle)
        steps.append(step)
    step = float(np.median(steps))
    out = {'step_us': step, 'taken': compiled_samples(fast), 'samples': fast.samples,
           'around_step_us': {}}
    for name, values in timed.items():
        median = float(np.median([m for m, _ in values]))
        out[name] = {'median_us': median, 'p99_us': float(np.median([p for _, p in values]))}
        out['around_step_us'][name] = median - step
    pairs = zip(timed['compiled'], timed['python'])
    out['saved_us'] = float(np.median([python[0] - compiled[0] for compiled, python in pairs]))
    return out


def main(argv=None):
    """Print :func:`update_overhead` for the node's default model (JSON with --json)."""
    parser = argparse.ArgumentParser(prog='python -m flexlink_ros.studies.update_bench',
                                     description=__doc__.strip().splitlines()[0])
    parser.add_argument('--mechanism', default='cho1992')
    parser.add_argument('--rpm', type=float, default=391.0)
    parser.add_argument('--rounds', type=int, default=9)
    parser.add_argument('--samples', type=int, default=3000)
    parser.add_argument('--json', action='store_true')
    args = parser.parse_args(argv)
    model = model_for_mechanism(load_mechanism(args.mechanism), node_model_options())
    result = update_overhead(model, args.rpm, args.rounds, args.samples)
    if args.json:
        print(json.dumps(result, indent=1))
        return
    print(f'node default model (r = {model.size}), {args.rpm:g} rpm, 1 kHz +-30 % jitter, '
          f'{args.rounds} alternating rounds of {args.samples} updates:')
    for name in ('compiled', 'python'):
        entry = result[name]
        print(f'  update, {name + " path":15s} median {entry["median_us"]:6.2f} us, '
              f'p99 {entry["p99_us"]:6.2f} us, around the step '
              f'{result["around_step_us"][name]:5.2f} us')
    print(f'  batched step {result["step_us"]:.2f} us per row; the compiled path saves '
          f'{result["saved_us"]:.2f} us per update and took {result["taken"]} of '
          f'{result["samples"]} samples')


if __name__ == '__main__':
    main()
