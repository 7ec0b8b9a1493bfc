"""
A crank speed ramp up and down through a band, in the Exudyn peer and the streaming estimate.

Does the response branch near the resonance (two periodic solutions over a speed range, a
jump between ramp-up and ramp-down)? A periodic continuation answers it for one model; a ramp
answers it for both the peer and the streaming estimate under the same crank signal, and says
whether the streaming estimate, which follows its own history, lands on the peer's branch.

The ramp (:class:`RampProfile`): hold ``low`` rpm for ``settle`` revolutions (the start
transient decays), ramp linearly to ``high`` over ``ramp_s``, hold ``high`` for ``hold``
revolutions, ramp back to ``low`` over ``ramp_s``, hold ``low`` for ``hold`` revolutions. The
crank angle is the exact integral of the piecewise linear speed, so the peer (whose crank pin
is prescribed as a function of time) and the estimator (sampled at ``rate_hz`` with optional
jitter) see the same crank.

Measures per crank revolution (:func:`per_revolution`): the mean speed, the peak-to-peak
length of the lever tip and coupler mid-point deflection vectors (hypot of the dX and dY
peak-to-peak), and for the estimate its largest validity indicator. :func:`branch_gap`
compares the ramp-up and ramp-down amplitudes at the same speed: a branching response shows
a gap far above the quasi-static lag of the ramp, and a jump (a large change from one
revolution to the next).
"""

import bisect
import dataclasses
import math
import time

from flexlink_ros.core.estimation.nonlinear_follow import nonlinear_validity
from flexlink_ros.core.estimation.nonlinear_stream import estimate_nonlinear
from flexlink_ros.studies.peer_model import build_peer, deflections, OUTPUT_KEYS, require_exudyn
from flexlink_ros.studies.peer_model import DEFAULT_SPECTRAL_RADIUS, resolve_mechanism
from flexlink_ros.studies.peer_model import solver_settings
from flexlink_ros.studies.peer_solver import solve_or_explain
import numpy as np

POINTS = ('lever_tip', 'coupler_mid')
# Largest number of peer steps (or estimator samples) a ramp may ask for: bounds the memory.
MAX_STEPS = 5_000_000


@dataclasses.dataclass(frozen=True)
class RampProfile:
    """Hold ``low``, ramp up to ``high``, hold, ramp down, hold (module notes)."""

    low_rpm: float = 360.0
    high_rpm: float = 440.0
    ramp_s: float = 90.0
    settle_revolutions: float = 30.0
    hold_revolutions: float = 10.0

    def knots(self):
        """Return the breakpoint times [s] and speeds [rad/s] of the piecewise linear speed."""
        low, high = self.low_rpm * math.pi / 30.0, self.high_rpm * math.pi / 30.0
        settle = self.settle_revolutions * 2.0 * math.pi / low
        hold_high = self.hold_revolutions * 2.0 * math.pi / high
        hold_low = self.hold_revolutions * 2.0 * math.pi / low
        steps = np.cumsum([0.0, settle, self.ramp_s, hold_high, self.ramp_s, hold_low])
        return steps, np.array([low, low, high, high, low, low])

    @property
    def duration_s(self):
        """Return the profile's length [s]."""
        return float(self.knots()[0][-1])

    def speed(self, t):
        """Return the crank speed [rad/s] at times ``t`` [s]."""
        times, speeds = self.knots()
        return np.interp(t, times, speeds)

    def angle(self, t):
        """Return the crank angle [rad] at times ``t`` [s] (the speed's integral from 0)."""
        times, speeds = self.knots()
        t = np.clip(np.asarray(t, dtype=float), 0.0, times[-1])
        segment = 0.5 * (speeds[1:] + speeds[:-1]) * np.diff(times)
        area = np.concatenate([[0.0], np.cumsum(segment)])
        k = np.clip(np.searchsorted(times, t, side='right') - 1, 0, len(times) - 2)
        dt = t - times[k]
        slope = (speeds[k + 1] - speeds[k]) / np.maximum(times[k + 1] - times[k], 1e-300)
        return area[k] + speeds[k] * dt + 0.5 * slope * dt * dt

    def angle_function(self):
        """Return a scalar theta(t) for the peer's user function (a few microseconds a call)."""
        times, speeds = (list(x) for x in self.knots())
        area = [float(a) for a in self.angle(np.array(times))]

        def angle_at(t):
            k = min(max(bisect.bisect_right(times, t) - 1, 0), len(times) - 2)
            dt = min(t, times[-1]) - times[k]
            slope = (speeds[k + 1] - speeds[k]) / (times[k + 1] - times[k])
            return area[k] + speeds[k] * dt + 0.5 * slope * dt * dt
        return angle_at


def peer_ramp(mechanism, profile, *, elements_per_link=8, bearings='springs', gravity=True,
              beta_s=1e-4, steps_per_revolution=720, stride=4):
    """
    Run the Exudyn peer through the ramp; every ``stride``-th step's deflections.

    The step is constant, ``steps_per_revolution`` per revolution at the highest speed.

    Returns
    -------
    dict
        'time' [s], 'crank_angle' [rad], 'speed' [rad/s], the four :data:`OUTPUT_KEYS` [m],
        'info' (settings, steps, wall time [s]).

    """
    exu, _ = require_exudyn()
    mech = resolve_mechanism(mechanism)
    h = 60.0 / (profile.high_rpm * steps_per_revolution)
    steps = int(math.ceil(profile.duration_s / h))
    if steps > MAX_STEPS:
        raise ValueError(f'the ramp needs {steps} peer steps, more than {MAX_STEPS}')
    wall = time.perf_counter()
    model = build_peer(mech, profile.low_rpm, elements_per_link=elements_per_link,
                       bearings=bearings, gravity=gravity, beta_s=beta_s,
                       mass_placement='split' if bearings == 'springs' else 'coupler-end',
                       crank_angle=profile.angle_function())
    settings = solver_settings(exu, steps * h, steps, DEFAULT_SPECTRAL_RADIUS, 0.5 * h)
    solve_or_explain(exu, model.mbs, settings, f'ramp {profile}', bearings)
    data = {name: np.asarray(model.mbs.GetSensorStoredData(sensor))
            for name, sensor in model.sensors.items()}
    t_all = data['lever_tip'][:, 0]
    wanted = np.arange(0, steps + 1, stride) * h
    index = np.minimum(np.searchsorted(t_all, wanted - 0.25 * h), len(t_all) - 1)
    theta = profile.angle(t_all[index])
    out = deflections(mech, theta, data['lever_tip'][index, 1:3],
                      data['coupler_mid'][index, 1:3])
    out.update({'time': t_all[index], 'crank_angle': theta, 'speed': profile.speed(t_all[index]),
                'info': {'profile': dataclasses.asdict(profile), 'steps': steps,
                         'time_step_s': h, 'elements_per_link': elements_per_link,
                         'bearings': bearings, 'gravity': bool(gravity), 'beta_s': beta_s,
                         'wall_s': time.perf_counter() - wall}})
    return out


def ramp_signal(profile, rate_hz=1000.0, jitter=0.0, seed=0):
    """Stamps [ns], angles [rad] and speeds [rad/s] of the ramp sampled with +-jitter."""
    count = int(profile.duration_s * rate_hz * (1.0 + jitter)) + 2
    if count > MAX_STEPS:
        raise ValueError(f'the ramp needs {count} samples, more than {MAX_STEPS}')
    rng = np.random.default_rng(seed)
    steps = (1.0 + jitter * rng.uniform(-1.0, 1.0, count)) / rate_hz
    t = np.concatenate([[0.0], np.cumsum(steps)])
    t = t[t <= profile.duration_s]
    return np.round(t * 1e9).astype(np.int64), profile.angle(t), profile.speed(t)


def stream_ramp(tables, profile, rate_hz=1000.0, jitter=0.0, seed=0):
    """
    Step the streaming estimate through the ramp.

    Returns
    -------
    dict
        As :func:`peer_ramp` ('time', 'crank_angle', 'speed', :data:`OUTPUT_KEYS`), plus
        'validity' (per sample, :func:`core.estimation.nonlinear_follow.nonlinear_validity`),
        'refused', 'beyond_von_karman', 'wall_s'.

    """
    wall = time.perf_counter()
    stamps, angles, speeds = ramp_signal(profile, rate_hz, jitter, seed)
    est = estimate_nonlinear(tables, stamps, angles, speeds)
    out = {key: est['outputs'][:, k] for k, key in enumerate(OUTPUT_KEYS)}
    out.update({'time': stamps * 1e-9, 'crank_angle': angles, 'speed': speeds,
                'validity': np.array([nonlinear_validity(s) for s in est['link_slope']]),
                'refused': est['refused'], 'beyond_von_karman': est['beyond_von_karman'],
                'wall_s': time.perf_counter() - wall})
    return out


def per_revolution(run):
    """
    Per whole crank revolution: mean speed [rpm], p2p per output point [m], phase of the ramp.

    Returns
    -------
    dict of ndarray
        'rpm', 'lever_tip', 'coupler_mid', 'time' (mid-revolution [s]) and 'validity' (largest
        per revolution, NaN for the peer).

    """
    turn = np.floor((run['crank_angle'] - run['crank_angle'][0]) / (2.0 * math.pi))
    edges = np.flatnonzero(np.diff(turn)) + 1
    rows = {key: [] for key in ('rpm', 'time', 'validity') + POINTS}
    for start, stop in zip(edges[:-1], edges[1:]):
        span = slice(start, stop)
        rows['rpm'].append(float(np.mean(run['speed'][span])) * 30.0 / math.pi)
        rows['time'].append(float(np.mean(run['time'][span])))
        for point in POINTS:
            rows[point].append(float(np.hypot(np.ptp(run[f'{point}_dx'][span]),
                                              np.ptp(run[f'{point}_dy'][span]))))
        rows['validity'].append(float(np.max(run['validity'][span])) if 'validity' in run
                                else math.nan)
    return {key: np.array(value) for key, value in rows.items()}


def ramp_halves(rows, profile):
    """Split per-revolution rows into the ramp-up and ramp-down revolutions (holds left out)."""
    times, _ = profile.knots()
    up = (rows['time'] > times[1]) & (rows['time'] < times[2])
    down = (rows['time'] > times[3]) & (rows['time'] < times[4])
    return ({key: value[up] for key, value in rows.items()},
            {key: value[down] for key, value in rows.items()})


def branch_gap(rows, profile, point='lever_tip', grid=None):
    """
    Ramp-up against ramp-down amplitude of one output point over speed.

    Returns
    -------
    dict
        'rpm' (grid), 'up', 'down' (p2p [m] interpolated on the grid), 'largest_gap'
        (max |up - down| relative to the larger amplitude there), 'at_rpm' (where),
        'largest_jump' (largest revolution-to-revolution p2p change, relative, either ramp).

    """
    up, down = ramp_halves(rows, profile)
    if grid is None:
        grid = np.linspace(profile.low_rpm, profile.high_rpm, 81)
    order = np.argsort(down['rpm'])
    a_up = np.interp(grid, up['rpm'], up[point])
    a_down = np.interp(grid, down['rpm'][order], down[point][order])
    gap = np.abs(a_up - a_down) / np.maximum(np.maximum(a_up, a_down), 1e-300)
    jumps = [np.max(np.abs(np.diff(half[point])) / half[point][1:]) if len(half[point]) > 1
             else 0.0 for half in (up, down)]
    k = int(np.argmax(gap))
    return {'rpm': grid, 'up': a_up, 'down': a_down, 'largest_gap': float(gap[k]),
            'at_rpm': float(grid[k]), 'largest_jump': float(max(jumps))}


def time_series_error(peer, estimate, point):
    """
    Relative RMS of the estimate's deflection vector against the peer's over the whole ramp.

    The estimate is interpolated onto the peer's sample times (after the settling hold).
    """
    t = peer['time']
    diff2 = 0.0
    ref2 = 0.0
    for axis in ('dx', 'dy'):
        key = f'{point}_{axis}'
        other = np.interp(t, estimate['time'], estimate[key])
        diff2 += np.sum((other - peer[key]) ** 2)
        ref2 += np.sum(peer[key] ** 2)
    return float(math.sqrt(diff2 / ref2))


__all__ = ['RampProfile', 'peer_ramp', 'ramp_signal', 'stream_ramp', 'per_revolution',
           'ramp_halves', 'branch_gap', 'time_series_error', 'POINTS', 'MAX_STEPS']
