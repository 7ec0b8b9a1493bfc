"""
Earles-Wu joint-contact criterion of the zero-clearance rigid mechanism (Kang, Lee & Yoon 1990).

For each revolute joint, R = |F| is the magnitude of the reaction (:mod:`core.dynamics`),
gamma its direction in the ground frame and ::

    gamma_dot = (Fx dFy/dt - Fy dFx/dt) / R^2          (exact, from the analytic dF/dt)

Contact loss in a joint with clearance is likely where ``|gamma_dot / R|`` is large (Kang
1990, Eq. 2; Earles & Wu 1975). The paper's Table 2 values are samples on a 1-degree grid;
where a reaction dips to a few newtons the peak is about a degree wide, so a grid misses
it. :func:`evaluate_criteria` therefore scans a fine grid (:data:`SCAN_POINTS`), refines
every candidate peak with a bounded scalar optimiser (location to :data:`REFINE_XATOL`,
far below the 0.1 % the report needs), and also reports the maximum on a user grid that
starts with the crank along O2->O4.

Near-zero reactions. R is clamped below at ``R_floor = NEAR_ZERO_FRACTION * RMS(R)`` of that
joint over the revolution (and at least :data:`NEAR_ZERO_ABS`), so the ratio stays finite;
``near_zero_force`` flags a joint whose minimum R falls below the floor: its ratio is then
a lower bound (the direction of a force passing through zero turns arbitrarily fast).
"""

import dataclasses
import math

import numpy as np
import scipy   # scipy.optimize loads on first use: a replay from the cache never needs it

from .dynamics import solve_dynamics
from .kinematics import solve_kinematics
from ..names import JOINT_NAMES

# Uniform scan of the revolution before refinement (0.05 degree): peaks here are >= ~1 deg wide.
SCAN_POINTS = 7200
# Location tolerance of the refined peak [rad]; the value then converges far below 0.1 %.
REFINE_XATOL = 1e-10
# Refine every local scan maximum at least this fraction of the scan's largest ...
CANDIDATE_FRACTION = 0.2
# ... and at most this many per joint.
MAX_CANDIDATES = 8
# R below this fraction of the joint's RMS reaction is clamped (and flagged) ...
NEAR_ZERO_FRACTION = 1e-6
# ... and never below this absolute floor [N].
NEAR_ZERO_ABS = 1e-9


@dataclasses.dataclass(frozen=True)
class JointCriterion:
    """
    Earles-Wu criterion of one joint over a revolution.

    Attributes
    ----------
    joint : str
        'O2', 'A', 'B' or 'O4'.
    max_ratio : float
        True maximum of |gamma_dot / R| [rad/(s N)] (refined).
    at_crank_angle : float
        Crank angle of the true maximum [rad], in [0, 2 pi).
    max_ratio_on_grid : float
        Maximum over the user grid [rad/(s N)].
    at_grid_angle : float
        Grid angle of that maximum [rad].
    min_force, at_min_force_angle : float
        True minimum of R [N] (refined) and where [rad].
    max_force : float
        True maximum of R [N] (refined).
    rms_force : float
        RMS of R over the revolution [N].
    force_floor : float
        R below this was clamped [N].
    near_zero_force : bool
        min R fell below ``force_floor``: max_ratio is a finite lower bound.

    """

    joint: str
    max_ratio: float
    at_crank_angle: float
    max_ratio_on_grid: float
    at_grid_angle: float
    min_force: float
    at_min_force_angle: float
    max_force: float
    rms_force: float
    force_floor: float
    near_zero_force: bool

    @property
    def grid_shortfall_percent(self):
        """How far the grid maximum falls below the true maximum [%]."""
        if self.max_ratio == 0.0:
            return 0.0
        return 100.0 * (self.max_ratio - self.max_ratio_on_grid) / self.max_ratio

    def as_dict(self):
        """JSON-ready summary with units in the keys (angles in degrees)."""
        return {'max_ratio': self.max_ratio, 'at_crank_deg': math.degrees(self.at_crank_angle),
                'max_ratio_on_grid': self.max_ratio_on_grid,
                'at_grid_deg': math.degrees(self.at_grid_angle),
                'grid_shortfall_percent': self.grid_shortfall_percent,
                'min_force_n': self.min_force,
                'at_min_force_deg': math.degrees(self.at_min_force_angle),
                'max_force_n': self.max_force, 'rms_force_n': self.rms_force,
                'near_zero_force': self.near_zero_force}


def direction_rate(force, force_rate, floor=0.0):
    """
    Magnitude, direction and direction rate of reactions.

    Parameters
    ----------
    force, force_rate : ndarray, complex
        Reactions Fx + i Fy [N] and their time derivatives [N/s], any shape.
    floor : float or ndarray
        R is clamped below at this value [N] in the rate (broadcast against ``force``).

    Returns
    -------
    magnitude, direction, direction_rate : ndarray
        R [N], gamma in (-pi, pi] [rad] and gamma_dot [rad/s], shaped like ``force``.

    """
    magnitude = np.abs(force)
    cross = force.real * force_rate.imag - force.imag * force_rate.real
    safe = np.maximum(magnitude, floor)
    with np.errstate(divide='ignore', invalid='ignore'):
        rate = np.where(safe > 0.0, cross / np.where(safe > 0.0, safe, 1.0) ** 2, 0.0)
    return magnitude, np.angle(force), rate


def criterion_ratio(force, force_rate, floor=0.0):
    """
    |gamma_dot / R| = |Fx dFy/dt - Fy dFx/dt| / R^3 [rad/(s N)], R clamped at ``floor``.

    Parameters
    ----------
    force, force_rate : ndarray, complex
        Reactions and their time derivatives, any shape.
    floor : float or ndarray
        Lower clamp of R [N]; with floor 0 a zero reaction gives 0 (no rate) or inf.

    Returns
    -------
    ndarray
        Shaped like ``force``.

    """
    magnitude, _, rate = direction_rate(force, force_rate, floor)
    safe = np.maximum(magnitude, floor)
    with np.errstate(divide='ignore', invalid='ignore'):
        return np.where(safe > 0.0, np.abs(rate) / np.where(safe > 0.0, safe, 1.0),
                        np.where(rate == 0.0, 0.0, np.inf))


def reaction_evaluator(mechanism, crank_speed, crank_accel=0.0):
    """
    Make a function theta -> (force, force_rate), complex arrays (4, n), at a steady motion.

    Parameters
    ----------
    mechanism : Mechanism
        The linkage (with its optional spring).
    crank_speed, crank_accel : float
        Crank speed [rad/s] and acceleration [rad/s^2] (constant; the paper's case is a = 0).

    """
    def evaluate(theta):
        state = solve_kinematics(mechanism, np.atleast_1d(theta), crank_speed, crank_accel)
        result = solve_dynamics(mechanism, state)
        return result.force, result.force_rate
    return evaluate


def crank_grid(step_deg):
    """Crank angles [rad] from 0 (crank along O2->O4) in steps of ``step_deg``, below 360."""
    if not step_deg > 0.0 or not math.isfinite(step_deg) or step_deg > 360.0:
        raise ValueError(f'`grid_deg` must be in (0, 360], got {step_deg!r}')
    count = int(math.floor(360.0 / step_deg + 1e-9))
    return np.radians(step_deg * np.arange(count))


def _local_extrema(values, sign, fraction, limit):
    """Return the indices of periodic local maxima of sign*values worth refining, largest first."""
    v = sign * values
    peaks = np.flatnonzero((v >= np.roll(v, 1)) & (v >= np.roll(v, -1)))
    if peaks.size == 0:
        return np.array([int(np.argmax(v))])
    peaks = peaks[np.argsort(-v[peaks])]
    if sign > 0:
        top = v[peaks[0]]
        peaks = peaks[v[peaks] >= fraction * top]
    return peaks[:limit]


def _refine(function, theta, index, step, sign):
    """Maximum of sign*function on [theta_i - step, theta_i + step] (bounded Brent)."""
    centre = theta[index]
    found = scipy.optimize.minimize_scalar(
        lambda t: -sign * float(function(t)), bounds=(centre - step, centre + step),
        method='bounded', options={'xatol': REFINE_XATOL, 'maxiter': 500})
    return float(found.x), sign * -float(found.fun)


def revolution_extremes(evaluate, joints=JOINT_NAMES, grid=None, scan_points=SCAN_POINTS):
    """
    Find the true maxima of |gamma_dot / R| and minima of R over a revolution, per joint.

    Parameters
    ----------
    evaluate : callable
        theta (ndarray, shape (n,)) -> (force, force_rate), complex, shape (4, n), joints in
        ``JOINT_NAMES`` order.
    joints : sequence of str
        Joints to report.
    grid : ndarray or None
        User grid of crank angles [rad]; default the 1-degree grid from 0.
    scan_points : int
        Uniform scan size before refinement.

    Returns
    -------
    dict of str to JointCriterion

    """
    if scan_points < 36:
        raise ValueError(f'`scan_points` must be >= 36, got {scan_points!r}')
    grid = crank_grid(1.0) if grid is None else np.asarray(grid, dtype=float)
    scan = 2.0 * np.pi * np.arange(scan_points) / scan_points
    force, force_rate = evaluate(scan)
    grid_force, grid_rate = evaluate(grid)
    out = {}
    for joint in joints:
        j = JOINT_NAMES.index(joint)
        out[joint] = _joint_extremes(evaluate, joint, scan, (force[j], force_rate[j]),
                                     grid, (grid_force[j], grid_rate[j]))
    return out


def _largest_ratio(evaluate, j, scan, ratio, floor):
    """Scan the ratio's peaks and refine them: (crank angle, largest |gamma_dot / R|)."""
    def ratio_at(t):
        f, fr = evaluate(np.array([t]))
        return criterion_ratio(f[j], fr[j], floor)[0]

    best = (float(scan[np.argmax(ratio)]), float(ratio.max()))
    peaks = _local_extrema(ratio, 1.0, CANDIDATE_FRACTION, MAX_CANDIDATES)
    for index in peaks if best[1] > 0.0 else ():  # nothing to refine on a zero curve
        candidate = _refine(ratio_at, scan, index, scan[1], 1.0)
        if candidate[1] > best[1]:
            best = candidate
    return best


def _force_range(evaluate, j, scan, magnitude):
    """Scan and refine |R|: (crank angle, smallest |R|) and the largest |R|."""
    def force_at(t):
        return np.abs(evaluate(np.array([t]))[0][j])[0]

    step = scan[1]
    lowest = (float(scan[np.argmin(magnitude)]), float(magnitude.min()))
    dips = _local_extrema(magnitude, -1.0, 1.0, 3)
    for index in dips if lowest[1] > 0.0 else ():
        candidate = _refine(force_at, scan, index, step, -1.0)
        if candidate[1] < lowest[1]:
            lowest = candidate
    largest = float(magnitude.max())
    if largest > 0.0:
        largest = max(largest, _refine(force_at, scan, int(np.argmax(magnitude)), step,
                                       1.0)[1])
    return lowest, largest


def _joint_extremes(evaluate, joint, scan, scanned, grid, on_grid_values):
    """
    Collect one joint's criterion: refined extremes over the scan, the maximum on the grid.

    Parameters
    ----------
    evaluate : callable
        As :func:`revolution_extremes` takes it.
    joint : str
        The joint's name.
    scan : ndarray, shape (S,)
        Uniform scan of crank angles [rad] from 0.
    scanned : tuple of ndarray, shape (S,)
        The joint's force and force rate on the scan.
    grid : ndarray, shape (G,)
        User grid of crank angles [rad].
    on_grid_values : tuple of ndarray, shape (G,)
        The joint's force and force rate on the grid.

    Returns
    -------
    JointCriterion
        The joint's extremes.

    """
    j = JOINT_NAMES.index(joint)
    force, force_rate = scanned
    magnitude = np.abs(force)
    rms = float(np.sqrt(np.mean(magnitude ** 2)))
    floor = max(NEAR_ZERO_FRACTION * rms, NEAR_ZERO_ABS)
    ratio = criterion_ratio(force, force_rate, floor)
    best = _largest_ratio(evaluate, j, scan, ratio, floor)
    lowest, largest = _force_range(evaluate, j, scan, magnitude)
    on_grid = criterion_ratio(on_grid_values[0], on_grid_values[1], floor)
    k = int(np.argmax(on_grid)) if on_grid.size else 0
    return JointCriterion(
        joint=joint, max_ratio=best[1], at_crank_angle=float(np.mod(best[0], 2 * np.pi)),
        max_ratio_on_grid=float(on_grid[k]) if on_grid.size else float('nan'),
        at_grid_angle=float(grid[k]) if on_grid.size else float('nan'),
        min_force=lowest[1], at_min_force_angle=float(np.mod(lowest[0], 2 * np.pi)),
        max_force=largest, rms_force=rms, force_floor=floor,
        near_zero_force=bool(lowest[1] < floor))


def evaluate_criteria(mechanism, crank_speed=None, grid_deg=1.0, joints=JOINT_NAMES,
                      scan_points=SCAN_POINTS):
    """
    Earles-Wu criteria of every joint at constant crank speed (Kang 1990, Table 2).

    Parameters
    ----------
    mechanism : Mechanism
        Including its optional spring.
    crank_speed : float or None
        Crank speed [rad/s]; default ``mechanism.crank_speed``.
    grid_deg : float
        Step of the user grid [deg], starting with the crank along O2->O4.
    joints : sequence of str
        Joints to report.
    scan_points : int
        Uniform scan size before refinement.

    Returns
    -------
    dict of str to JointCriterion

    """
    speed = mechanism.crank_speed if crank_speed is None else crank_speed
    if speed is None:
        raise ValueError('`crank_speed` is needed (the mechanism file gives none)')
    if not math.isfinite(speed) or speed == 0.0:
        raise ValueError(f'`crank_speed` must be finite and non-zero, got {speed!r}')
    for joint in joints:
        if joint not in JOINT_NAMES:
            raise ValueError(f'`joints`: unknown joint {joint!r} (joints: {JOINT_NAMES})')
    return revolution_extremes(reaction_evaluator(mechanism, speed), joints,
                               crank_grid(grid_deg), scan_points)


def criterion_curves(mechanism, crank_angle, crank_speed=None):
    """
    R, gamma, gamma_dot and |gamma_dot / R| of every joint at given crank angles.

    Parameters
    ----------
    mechanism : Mechanism
        The linkage (with its optional spring).
    crank_angle : ndarray, shape (n,)
        [rad].
    crank_speed : float or None
        [rad/s]; default ``mechanism.crank_speed``.

    Returns
    -------
    dict
        'force', 'direction', 'direction_rate', 'ratio': ndarray, shape (4, n) [N, rad,
        rad/s, rad/(s N)]; R clamped as in :func:`revolution_extremes` for the ratio.

    """
    speed = mechanism.crank_speed if crank_speed is None else crank_speed
    force, force_rate = reaction_evaluator(mechanism, speed)(crank_angle)
    magnitude, direction, rate = direction_rate(force, force_rate)
    rms = np.sqrt(np.mean(magnitude ** 2, axis=1, keepdims=True))
    floor = np.maximum(NEAR_ZERO_FRACTION * rms, NEAR_ZERO_ABS)
    return {'force': magnitude, 'direction': direction, 'direction_rate': rate,
            'ratio': criterion_ratio(force, force_rate, floor)}


__all__ = ['JointCriterion', 'direction_rate', 'criterion_ratio', 'reaction_evaluator',
           'crank_grid', 'revolution_extremes', 'evaluate_criteria', 'criterion_curves',
           'SCAN_POINTS', 'NEAR_ZERO_FRACTION', 'NEAR_ZERO_ABS']
