"""
Synthetic crank signals and the streaming estimator run and timed over them.

:func:`synthetic_signal` is a constant-speed crank sampled with jitter; :func:`run_estimate`
streams one through :class:`StreamingEstimator` (``flexlink estimate``) and keeps the last
full revolution. ``plan`` and ``bench`` (:mod:`studies.plan`, :mod:`studies.bench`) measure
models on the same signals.
"""

import math
import time

import numpy as np

from ..core.estimation.nonlinear_follow import NonlinearFollower
from ..core.estimation.streaming import StreamingEstimator
from ..core.numerics import RPM
from ..core.validity import is_valid

# Speeds of Cho 1992's deflection plots [rpm]: the accuracy checks use them.
PAPER_RPM = (269.0, 391.0)
# Samples whose update time is measured after a warm-up (median and p99 are reported).
TIMING_WARMUP = 50


def synthetic_signal(rpm, seconds, rate_hz, jitter=0.0, seed=0, start_angle=0.0):
    """
    Stamps, angles and speeds of a crank at constant speed sampled with jitter.

    Parameters
    ----------
    rpm : float
        Crank speed [rpm].
    seconds : float
        Duration [s].
    rate_hz : float
        Nominal sample rate [Hz].
    jitter : float
        Each step is (1 + jitter U(-1, 1)) / rate_hz.
    seed : int
        Random seed of the jitter.
    start_angle : float
        Crank angle at t = 0 [rad].

    Returns
    -------
    stamps_ns : ndarray of int, shape (m,)
    angles, speeds : ndarray, shape (m,)

    """
    if not 0.0 <= jitter < 1.0:
        raise ValueError(f'`jitter` must be in [0, 1), got {jitter}')
    if seconds <= 0.0 or rate_hz <= 0.0:
        raise ValueError('`seconds` and `rate_hz` must be positive')
    rng = np.random.default_rng(seed)
    count = int(seconds * rate_hz * (1.0 + jitter)) + 2
    steps = (1.0 + jitter * rng.uniform(-1.0, 1.0, count)) / rate_hz
    times = np.concatenate([[0.0], np.cumsum(steps)])
    times = times[times <= seconds]
    stamps = np.round(times * 1e9).astype(np.int64)
    speed = rpm * RPM
    return stamps, start_angle + speed * stamps * 1e-9, np.full(stamps.size, speed)


def last_revolution(stamps_ns, rpm):
    """Boolean mask of the samples in the last full revolution."""
    period_ns = 2.0 * math.pi / (abs(rpm) * RPM) * 1e9
    return stamps_ns > stamps_ns[-1] - period_ns


def stream_timed(model, stamps_ns, angles, speeds, warm_start=True, compiled=True):
    """
    Run the streaming estimator (its compiled step, or its numpy step) and time every update.

    Returns
    -------
    samples : list of Sample
    update_ns : ndarray of int
        perf_counter_ns duration of each update.

    """
    estimator = StreamingEstimator(model, warm_start=warm_start, compiled=compiled)
    samples, durations = [], []
    clock = time.perf_counter_ns
    for stamp, angle, speed in zip(stamps_ns.tolist(), angles.tolist(),
                                   None if speeds is None else speeds.tolist()):
        start = clock()
        samples.append(estimator.update(stamp, angle, speed))
        durations.append(clock() - start)
    return samples, np.array(durations)


def stream_nonlinear_timed(tables, stamps_ns, angles, speeds):
    """
    Step the reduced nonlinear model sample by sample as the node does; time every update.

    Each update is :meth:`NonlinearFollower.sample` (unwrapping, the compiled step of one
    sample, the outputs and the validity), the call the node and ``replay --nonlinear`` make.

    Returns
    -------
    outputs : ndarray, shape (K, channels)
    update_ns : ndarray of int
        perf_counter_ns duration of each update.

    """
    follower = NonlinearFollower(tables, reset_gap_s=math.inf)
    outputs, durations = [], []
    clock, sample = time.perf_counter_ns, follower.sample
    for stamp, angle, speed in zip(stamps_ns.tolist(), angles.tolist(), speeds.tolist()):
        start = clock()
        outputs.append(sample(stamp, angle, speed))
        durations.append(clock() - start)
    return np.array(outputs), np.array(durations)


def timing_summary(update_ns):
    """Median and 99th percentile [us] of update durations after the warm-up samples."""
    steady = update_ns[TIMING_WARMUP:] if update_ns.size > 2 * TIMING_WARMUP else update_ns
    return float(np.median(steady) / 1e3), float(np.percentile(steady, 99) / 1e3)


def run_estimate(model, rpm, seconds=3.0, rate_hz=1000.0, jitter=0.0, warm_start=True,
                 seed=0):
    """
    Estimate over the last full revolution of a synthetic constant-speed signal.

    Returns
    -------
    dict
        JSON-ready: crank_deg, lever_tip and coupler_mid {dx_m, dy_m}, criterion (per sample
        |dgamma/dt|/R of the four joints), error_indicator,
        nonlinearity (core.validity.is_valid of the samples' validity indicator),
        us_per_sample_median, us_per_sample_p99, samples, flags seen.

    """
    stamps, angles, speeds = synthetic_signal(rpm, seconds, rate_hz, jitter, seed)
    samples, update_ns = stream_timed(model, stamps, angles, speeds, warm_start)
    mask = last_revolution(stamps, rpm)
    chosen = [s for s, keep in zip(samples, mask) if keep]
    median, p99 = timing_summary(update_ns)
    return {
        'crank_deg': [math.degrees(s.crank_angle) for s in chosen],
        'lever_tip': {'dx_m': [s.lever_tip[0] for s in chosen],
                      'dy_m': [s.lever_tip[1] for s in chosen]},
        'coupler_mid': {'dx_m': [s.coupler_mid[0] for s in chosen],
                        'dy_m': [s.coupler_mid[1] for s in chosen]},
        'criterion': [list(s.criterion) for s in chosen],
        'error_indicator_max': max(s.error_indicator for s in chosen),
        'nonlinearity': is_valid([s.nonlinearity for s in chosen]),
        'us_per_sample_median': median,
        'us_per_sample_p99': p99,
        'samples': len(samples),
        'model': {'size': model.size, 'grid_size': model.grid_size,
                  'bytes': int(model.nbytes), 'options': model.info.get('options', {})},
    }
