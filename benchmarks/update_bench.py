"""
Time the streaming update around the step: the compiled update against the Python path.

Each round runs ``samples`` in-process updates (StreamingEstimator.update, the node's call) of
a jittered signal at ``rpm`` on two estimators of one model: one with the compiled update
(core/estimation/compiled_update.py: the whole update of an ordinary sample in one C call),
one whose every sample takes the Python path around the same compiled step; which of the two
goes first alternates from round to round. A third estimator times the batched step of as
many rows (step_rows, the replay's call: the rows the updates build, so the same step work;
median over chunks of CHUNK rows, which keep the GIL as a single sample does). The update
minus the batched step is what the estimator adds around the step. Both estimators' last
samples of each round are checked to agree before anything is reported.
``python benchmarks/update_bench.py`` prints it for the node's default model;
``--nonlinear`` times the reduced nonlinear update against the linear one instead
(:func:`nonlinear_rounds`).
"""

import argparse
import json
import time

from flexlink_ros.core.estimation.compiled_update import compiled_samples, use_python_path
from flexlink_ros.core.estimation.nonlinear_follow import NonlinearFollower
from flexlink_ros.core.estimation.step import MAX_SUBSTEP_NS
from flexlink_ros.core.estimation.streaming import StreamingEstimator
from flexlink_ros.core.mechanism_file import load_mechanism
from flexlink_ros.core.options import ModelOptions
from flexlink_ros.core.reduction.mechanism_model import model_for_mechanism
from flexlink_ros.core.reduction.nonlinear_model import nonlinear_model_for
from flexlink_ros.studies.synthetic import synthetic_signal
import numpy as np

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


def step_rows_of(estimator, stamps_ns, angles, speeds):
    """
    Return the step rows update() builds for the samples after the first of a clean signal.

    The estimator's kind of crank filter over the signal, clipped as the model sees it (the
    offline replay builds its rows the same way): the batched step then does the updates'
    own step work.
    """
    stamps_ns = np.asarray(stamps_ns, dtype=np.int64)
    motion = type(estimator.rate_filter)(estimator.rate_filter.time_constant_s).signal(
        (stamps_ns - stamps_ns[0]) * 1e-9, np.asarray(angles), np.asarray(speeds))[1:]
    dt_ns = np.diff(stamps_ns)
    speed_max = estimator.model.speed_max
    return np.column_stack([dt_ns * 1e-9, -(-dt_ns // MAX_SUBSTEP_NS), motion[:, 0],
                            np.clip(motion[:, 1], -speed_max, speed_max),
                            np.clip(motion[:, 2], -estimator.accel_limit, estimator.accel_limit),
                            motion[:, 3]])


def _rows_round(estimator, rows):
    """Median [us] per row of the batched step through ``rows`` in chunks of CHUNK rows."""
    per_row = []
    records = np.empty((CHUNK, estimator.last_record.size))
    for first in range(0, rows.shape[0] - CHUNK + 1, CHUNK):
        before = time.perf_counter_ns()
        estimator.step_rows(rows[first:first + CHUNK], np.empty(0), records)
        per_row.append((time.perf_counter_ns() - before) * 1e-3 / CHUNK)
    return float(np.median(per_row))


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
        The model (the node's default: :class:`core.options.ModelOptions`).
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
    fast, python, batched = (StreamingEstimator(model) for _ in range(3))
    use_python_path(python)
    first = (int(signal[0][0]), float(signal[1][0]), float(signal[2][0]))
    for estimator in (fast, python, batched):
        estimator.update(*first)
    rows = step_rows_of(batched, *signal)
    signal = [values[1:].tolist() for values in signal]
    timed = {'compiled': [], 'python': []}
    steps = []
    for k in range(rounds):
        part = [values[k * samples:(k + 1) * samples] for values in signal]
        order = (('compiled', fast), ('python', python))
        results = {}
        for name, estimator in (order if k % 2 == 0 else order[::-1]):
            times, results[name] = _update_round(estimator, part)
            timed[name].append((float(np.median(times)), float(np.percentile(times, 99))))
        _check_agree(results['compiled'], results['python'])
        steps.append(_rows_round(batched, rows[k * samples:(k + 1) * samples]))
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


NONLINEAR_OPTIONS = ModelOptions(rigid_crank=True, bearings='flexible', elements_per_link=8,
                                 stiffness_damping=1e-4)


def nonlinear_rounds(mechanism, rpm=391.0, rounds=9, samples=3000, jitter=0.3):
    """
    Time the reduced nonlinear streaming update against the linear update, interleaved.

    One process, one jittered 1 kHz signal: each round runs ``samples`` linear updates
    (``StreamingEstimator.update``) and as many nonlinear updates (``NonlinearFollower.sample``,
    the node's call: one compiled step and the outputs), which first alternating; both models
    of rigid crank, bearing springs, 8 elements per link, beta 1e-4 s.

    Returns
    -------
    dict
        'linear', 'nonlinear': median and p99 [us] (medians over the rounds); 'ratio' (the
        median of the rounds' median ratios); 'size' (the nonlinear model's m).

    """
    model = model_for_mechanism(mechanism, NONLINEAR_OPTIONS)
    tables, _ = nonlinear_model_for(mechanism, NONLINEAR_OPTIONS)
    signal = synthetic_signal(rpm, rounds * samples / 1000.0 + 1.0, 1000.0, jitter, seed=0)
    signal = [values.tolist() for values in signal]
    linear, follower = StreamingEstimator(model), NonlinearFollower(tables, reset_gap_s=1.0)
    timed = {'linear': [], 'nonlinear': []}
    for k in range(rounds):
        part = [values[k * samples:(k + 1) * samples] for values in signal]
        order = (('linear', linear.update), ('nonlinear', follower.sample))
        for name, update in (order if k % 2 == 0 else order[::-1]):
            times = _timed_calls(update, part)
            timed[name].append((float(np.median(times)), float(np.percentile(times, 99))))
    out = {name: {'median_us': float(np.median([m for m, _ in values])),
                  'p99_us': float(np.median([p for _, p in values]))}
           for name, values in timed.items()}
    out['ratio'] = float(np.median([n[0] / m[0] for m, n in zip(timed['linear'],
                                                                timed['nonlinear'])]))
    out['size'] = tables.size
    return out


def _timed_calls(update, signal):
    """Durations [us] of ``update(stamp, angle, speed)`` over ``signal``, after SETTLE."""
    clock = time.perf_counter_ns
    times = []
    for stamp, angle, speed in zip(*signal):
        before = clock()
        update(stamp, angle, speed)
        times.append(clock() - before)
    return np.array(times[SETTLE:]) * 1e-3


def _print_nonlinear(result, args):
    """Print :func:`nonlinear_rounds`' result."""
    print(f'reduced nonlinear update (m = {result["size"]}) against the linear update, '
          f'{args.rpm:g} rpm, 1 kHz +-30 % jitter, {args.rounds} interleaved rounds of '
          f'{args.samples} updates:')
    for name in ('linear', 'nonlinear'):
        print(f'  {name:9s} median {result[name]["median_us"]:7.2f} us, '
              f'p99 {result[name]["p99_us"]:7.2f} us')
    print(f'  nonlinear / linear median: {result["ratio"]:.1f}x')


def main(argv=None):
    """Print :func:`update_overhead` for the node's default model (JSON with --json)."""
    parser = argparse.ArgumentParser(prog='python benchmarks/update_bench.py',
                                     description=__doc__.strip().splitlines()[0])
    parser.add_argument('--mechanism', default='cho1992')
    parser.add_argument('--rpm', type=float, default=391.0)
    parser.add_argument('--rounds', type=int, default=9)
    parser.add_argument('--samples', type=int, default=3000)
    parser.add_argument('--json', action='store_true')
    parser.add_argument('--nonlinear', action='store_true',
                        help='time the reduced nonlinear update against the linear one')
    args = parser.parse_args(argv)
    if args.nonlinear:
        result = nonlinear_rounds(load_mechanism(args.mechanism), args.rpm, args.rounds,
                                  args.samples)
        print(json.dumps(result, indent=1)) if args.json else _print_nonlinear(result, args)
        return
    model = model_for_mechanism(load_mechanism(args.mechanism), ModelOptions())
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
