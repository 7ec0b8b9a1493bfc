"""
Coil-spring design against contact loss (Kang, Lee & Yoon 1990, Sec. 2.2 and 3).

Problem (Eqs. 4, 12-19). Choose the stiffness K and the free angle theta0 of a coil spring
between coupler and lever, T = K (theta_ij - theta0) (Eq. 1), to minimise the sum over the
clearance joints A, B, O4 (the paper's joints 1, 2, 3) of max |gamma_dot / R| over the
revolution, subject to

* 0 <= K <= 20 N m/rad and 0 <= theta0 <= 360 deg (Eqs. 12-15, bounds stated in Sec. 3);
* max TQ <= r TQ0_max (Eq. 16) and min TQ >= r TQ0_min (Eq. 17), r = 1.7, with TQ0 the
  input torque of the mechanism without spring. Eq. 17 is printed "Max(TQ) - r2 TQ0_min <=
  0", which no design can meet (TQ0_min < 0 < Max TQ); it is read as the lower limit it
  names (the torque minimum may fall at most to 1.7 times the original minimum);
* max R_j <= c R0_j (Eq. 19), c = 1.5, j = A, B, O4, R0_j the original maximum.

The paper's own design (K = 20, theta0 = 279.14 deg) stops on the limits: its torque maximum
is 1.70005 TQ0_max (0.003 % over, a stop on the boundary) with K at its bound, and its O4
force maximum is 0.8 % below its limit.

Method. The reactions are affine in the spring torque T_s (the Newton-Euler equations are
linear in the loads), so with F0 (no spring) and G (unit spring torque) tabulated once on a
scan grid, ``F = F0 + T_s G`` and ``dF/dt = dF0/dt + K w_ij G + T_s dG/dt`` cost a few array
operations per design. Each evaluation takes the scan maximum and a parabolic refinement of
it; the multimodal search is scipy's differential evolution (fixed seed) with the limits as
constraints, polished by COBYLA; the final design and the paper's design are then evaluated
with the fully refined true maxima of :mod:`core.criteria`.
"""

import dataclasses
import math

import numpy as np
import scipy.optimize

from .criteria import criterion_ratio, NEAR_ZERO_ABS, NEAR_ZERO_FRACTION, revolution_extremes
from .dynamics import solve_dynamics, spring_angle
from .kinematics import solve_kinematics
from .mechanism import Spring
from ..names import JOINT_NAMES

# Clearance joints of the objective (Kang 1990: joints 1, 2, 3).
DESIGN_JOINTS = ('A', 'B', 'O4')
# c_j of Eq. 19: allowed growth of each joint's maximum force.
FORCE_FACTOR = 1.5
# r_1 = r_2 of Eqs. 16-17: allowed growth of the input-torque extremes.
TORQUE_FACTOR = 1.7
# Upper bound of K [N m/rad] and bounds of theta0 [deg] (Sec. 3).
STIFFNESS_MAX = 20.0
THETA0_BOUNDS_DEG = (0.0, 360.0)
# The paper's optimum (Table 2).
PAPER_DESIGN = (20.0, 279.14)
# A limit counts as active within this fraction of its bound ...
ACTIVE_MARGIN = 5e-3
# ... and as met within this fraction (the search sees parabola-refined scan maxima).
FEASIBILITY_TOL = 1e-6
# Scan size used inside the search (0.25 degree) before parabolic refinement.
DESIGN_SCAN_POINTS = 1440


@dataclasses.dataclass(frozen=True)
class DesignEvaluation:
    """
    One spring design evaluated with true (refined) maxima.

    Attributes
    ----------
    stiffness : float
        K [N m/rad].
    theta0 : float
        [rad].
    objective : float
        Sum of the true max |gamma_dot / R| over DESIGN_JOINTS [rad/(s N)].
    max_ratio : dict of str to float
        Per joint (all four joints).
    constraints : dict of str to dict
        Per limit: 'value', 'limit' and 'margin' (>= 0 feasible, as a fraction of the limit).
    feasible : bool
    active : list of str
        Limits within 0.5 % of their bound, including the K and theta0 bounds.

    """

    stiffness: float
    theta0: float
    objective: float
    max_ratio: dict
    constraints: dict
    feasible: bool
    active: list

    def as_dict(self):
        """JSON-ready summary (theta0 in degrees)."""
        return {'k_nm_per_rad': self.stiffness, 'theta0_deg': math.degrees(self.theta0),
                'objective': self.objective, 'max_ratio': dict(self.max_ratio),
                'constraints': self.constraints, 'feasible': self.feasible,
                'active': list(self.active)}


class SpringProblem:
    """
    Kang's spring-design problem for one mechanism at constant crank speed.

    Parameters
    ----------
    mechanism : Mechanism
        The original mechanism (its own spring, if any, is ignored).
    crank_speed : float or None
        [rad/s]; default ``mechanism.crank_speed``.
    scan_points : int
        Scan size of the fast evaluation used in the search.

    """

    def __init__(self, mechanism, crank_speed=None, scan_points=DESIGN_SCAN_POINTS):
        speed = mechanism.crank_speed if crank_speed is None else crank_speed
        if speed is None or not math.isfinite(speed) or speed == 0.0:
            raise ValueError(f'`crank_speed` must be finite and non-zero, got {speed!r}')
        if scan_points < 36:
            raise ValueError(f'`scan_points` must be >= 36, got {scan_points!r}')
        self.mechanism = dataclasses.replace(mechanism, spring=None)
        self.crank_speed = float(speed)
        self.theta = 2.0 * np.pi * np.arange(scan_points) / scan_points
        self.step = self.theta[1]
        self._tables = self.tables(self.theta)
        self._joints = [JOINT_NAMES.index(j) for j in DESIGN_JOINTS]
        base = self._tables
        force = np.abs(base['force'])
        self.reference = {'force': {j: float(force[JOINT_NAMES.index(j)].max())
                                    for j in DESIGN_JOINTS},
                          'torque_max': float(base['torque'].max()),
                          'torque_min': float(base['torque'].min())}
        rms = np.sqrt(np.mean(force ** 2, axis=1))
        self._floor = np.maximum(NEAR_ZERO_FRACTION * rms, NEAR_ZERO_ABS)[:, None]

    def tables(self, theta):
        """Reactions without spring and per unit spring torque at crank angles theta."""
        state = solve_kinematics(self.mechanism, theta, self.crank_speed, 0.0)
        base = solve_dynamics(self.mechanism, state)
        unit = solve_dynamics(dataclasses.replace(
            self.mechanism, spring=Spring(stiffness=1.0, theta0=0.0)), state)
        # Unit *constant* torque: remove the stretch term of the spring's rate and value.
        stretch = spring_angle(state)
        rate_ij = state.omega[1] - state.omega[2]
        unit_force = (unit.force - base.force) / stretch
        unit_torque = (unit.input_torque - base.input_torque) / stretch
        unit_rate = (unit.force_rate - base.force_rate - rate_ij * unit_force) / stretch
        unit_torque_rate = (unit.input_torque_rate - base.input_torque_rate
                            - rate_ij * unit_torque) / stretch
        return {'force': base.force, 'force_rate': base.force_rate, 'torque': base.input_torque,
                'unit_force': unit_force, 'unit_rate': unit_rate, 'unit_torque': unit_torque,
                'unit_torque_rate': unit_torque_rate, 'stretch': stretch, 'rate_ij': rate_ij}

    @staticmethod
    def _combine(tables, stiffness, theta0):
        torque = stiffness * (tables['stretch'] - theta0)
        torque_rate = stiffness * tables['rate_ij']
        force = tables['force'] + torque * tables['unit_force']
        force_rate = (tables['force_rate'] + torque_rate * tables['unit_force']
                      + torque * tables['unit_rate'])
        return force, force_rate, tables['torque'] + torque * tables['unit_torque']

    def fast(self, design):
        """
        Objective and constraint values of a design on the scan with parabolic refinement.

        Parameters
        ----------
        design : sequence of float
            (K [N m/rad], theta0 [deg]).

        Returns
        -------
        objective : float
        constraints : ndarray, shape (5,)
            g <= 0 feasible, as fractions of the limits: forces at A, B, O4, torque max and
            torque min.

        """
        stiffness, theta0 = float(design[0]), math.radians(float(design[1]))
        force, force_rate, torque = self._combine(self._tables, stiffness, theta0)
        ratio = criterion_ratio(force, force_rate, self._floor)
        objective = sum(_parabolic_max(ratio[j]) for j in self._joints)
        magnitude = np.abs(force)
        limits = self.reference
        g = [-_limit(_parabolic_max(magnitude[JOINT_NAMES.index(j)]),
                     FORCE_FACTOR * limits['force'][j])['margin'] for j in DESIGN_JOINTS]
        g.append(-_limit(_parabolic_max(torque), TORQUE_FACTOR * limits['torque_max'])['margin'])
        g.append(-_limit(-_parabolic_max(-torque), TORQUE_FACTOR * limits['torque_min'],
                         upper=False)['margin'])
        return objective, np.array(g)

    def evaluate(self, stiffness, theta0, scan_points=3600, bounds=None):
        """
        Evaluate a design with refined true maxima of the criterion, forces and torque.

        Parameters
        ----------
        stiffness : float
            K [N m/rad].
        theta0 : float
            [rad].
        scan_points : int
            Scan size before refinement.
        bounds : dict or None
            'stiffness' and 'theta0_deg' ranges for the active-bound report; default the
            paper's.

        Returns
        -------
        DesignEvaluation

        """
        def evaluate(theta):
            force, force_rate, _ = self._combine(self.tables(np.atleast_1d(theta)),
                                                 stiffness, theta0)
            return force, force_rate
        found = revolution_extremes(evaluate, scan_points=scan_points)
        constraints = self._refined_constraints(stiffness, theta0, scan_points)
        bounds = bounds or {'stiffness': (0.0, STIFFNESS_MAX), 'theta0_deg': THETA0_BOUNDS_DEG}
        return DesignEvaluation(
            stiffness=float(stiffness), theta0=float(theta0),
            objective=float(sum(found[j].max_ratio for j in DESIGN_JOINTS)),
            max_ratio={j: c.max_ratio for j, c in found.items()}, constraints=constraints,
            feasible=all(c['margin'] >= -FEASIBILITY_TOL for c in constraints.values()),
            active=_active_bounds(constraints, stiffness, theta0, bounds))

    def _refined_constraints(self, stiffness, theta0, scan_points):
        """Force and torque limits of a design with the maxima refined (Brent)."""
        theta = 2.0 * np.pi * np.arange(scan_points) / scan_points
        force, _, torque = self._combine(self.tables(theta), stiffness, theta0)
        torque_of = lambda t: self._combine(self.tables(np.atleast_1d(t)),  # noqa: E731
                                            stiffness, theta0)[2][0]
        constraints = {}
        for j in DESIGN_JOINTS:
            index = JOINT_NAMES.index(j)

            def magnitude_of(t, index=index):
                f = self._combine(self.tables(np.atleast_1d(t)), stiffness, theta0)[0]
                return abs(f[index][0])
            peak = _refined_max(magnitude_of, theta, np.abs(force[index]))
            constraints[f'force_{j}'] = _limit(peak, FORCE_FACTOR * self.reference['force'][j])
        constraints['torque_max'] = _limit(_refined_max(torque_of, theta, torque),
                                           TORQUE_FACTOR * self.reference['torque_max'])
        low = -_refined_max(lambda t: -torque_of(t), theta, -torque)
        constraints['torque_min'] = _limit(low, TORQUE_FACTOR * self.reference['torque_min'],
                                           upper=False)
        return constraints


def _active_bounds(constraints, stiffness, theta0, bounds):
    """Names of the constraints and search bounds a design sits on."""
    active = [name for name, c in constraints.items() if c['margin'] < ACTIVE_MARGIN]
    k_low, k_high = bounds['stiffness']
    if stiffness >= k_high - ACTIVE_MARGIN * k_high:
        active.append('k_max')
    if stiffness <= k_low + ACTIVE_MARGIN * k_high:
        active.append('k_min')
    degrees = math.degrees(theta0)
    t_low, t_high = bounds['theta0_deg']
    if degrees <= t_low + 0.5:
        active.append('theta0_min')
    if degrees >= t_high - 0.5:
        active.append('theta0_max')
    return active


def _parabolic_max(values):
    """
    Maximum of periodic samples refined by a parabola (exact for a quadratic peak).

    The parabola goes through the top sample and its neighbours.
    """
    k = int(np.argmax(values))
    left, mid, right = values[k - 1], values[k], values[(k + 1) % values.size]
    curvature = left - 2.0 * mid + right
    if curvature >= 0.0:
        return float(mid)
    return float(mid - 0.125 * (right - left) ** 2 / curvature)


def _refined_max(function, theta, values):
    """Bounded-Brent refinement of the largest sample of a smooth periodic function."""
    k = int(np.argmax(values))
    step = theta[1] - theta[0]
    found = scipy.optimize.minimize_scalar(lambda t: -float(function(t)),
                                           bounds=(theta[k] - step, theta[k] + step),
                                           method='bounded', options={'xatol': 1e-10})
    return max(float(-found.fun), float(values[k]))


def _limit(value, limit, upper=True):
    margin = (limit - value if upper else value - limit) / abs(limit)
    return {'value': float(value), 'limit': float(limit), 'margin': float(margin)}


def design_spring(mechanism, crank_speed=None, seed=0, maxiter=60, popsize=15,
                  scan_points=DESIGN_SCAN_POINTS, theta0_bounds_deg=THETA0_BOUNDS_DEG,
                  stiffness_max=STIFFNESS_MAX):
    """
    Re-solve Kang's spring design with a global search.

    Parameters
    ----------
    mechanism : Mechanism
        The original mechanism.
    crank_speed : float or None
        [rad/s]; default ``mechanism.crank_speed``.
    seed : int
        Seed of differential evolution (the result is reproducible).
    maxiter, popsize : int
        Differential-evolution budget.
    scan_points : int
        Scan size of the fast evaluation in the search.
    theta0_bounds_deg : tuple of float
        Search range of theta0 [deg]; the paper's is (0, 360). A wider range models a spring
        pre-wound by more than a turn.
    stiffness_max : float
        Upper bound of K [N m/rad] (the paper's 20).

    Returns
    -------
    dict
        'design' and 'paper': DesignEvaluation; 'search': facts about the search
        (evaluations, fast objective, message); 'reference': the original extremes.

    """
    low, high = _checked_bounds(theta0_bounds_deg, stiffness_max)
    problem = SpringProblem(mechanism, crank_speed, scan_points)
    fast = _CachedObjective(problem)
    found = _global_search(fast, [(0.0, stiffness_max), (low, high)], seed, maxiter, popsize)
    start = found.x
    polished = _polish(fast, start, stiffness_max, (low, high))
    best = polished.x if (polished.fun <= found.fun
                          and np.all(fast(polished.x)[1] <= 1e-9)) else start
    best = np.clip(best, [0.0, low], [stiffness_max, high])
    bounds = {'stiffness': (0.0, stiffness_max), 'theta0_deg': (low, high)}
    design = problem.evaluate(float(best[0]), math.radians(float(best[1])), bounds=bounds)
    paper = problem.evaluate(PAPER_DESIGN[0], math.radians(PAPER_DESIGN[1]))
    return {'design': design, 'paper': paper, 'reference': problem.reference,
            'search': {'evaluations': fast.calls, 'fast_objective': float(fast(best)[0]),
                       'global_stage': {'k': float(start[0]), 'theta0_deg': float(start[1]),
                                        'objective': float(found.fun),
                                        'message': str(found.message)},
                       'polish_message': str(polished.message)}}


def _checked_bounds(theta0_bounds_deg, stiffness_max):
    """Return the theta0 search range (low, high) [deg] after checking both bounds."""
    low, high = (float(b) for b in theta0_bounds_deg)
    if not (math.isfinite(low) and math.isfinite(high) and low < high):
        raise ValueError(f'`theta0_bounds_deg` must be finite and increasing, got '
                         f'{theta0_bounds_deg!r}')
    if not (math.isfinite(stiffness_max) and stiffness_max > 0.0):
        raise ValueError(f'`stiffness_max` must be positive, got {stiffness_max!r}')
    return low, high


class _CachedObjective:
    """``SpringProblem.fast`` of the last design asked for, and a count of evaluations."""

    def __init__(self, problem):
        self.problem = problem
        self.calls = 0
        self.cache = {}

    def __call__(self, x):
        key = (float(x[0]), float(x[1]))
        if key not in self.cache:
            self.calls += 1
            self.cache.clear()
            self.cache[key] = self.problem.fast(x)
        return self.cache[key]


def _global_search(fast, bounds, seed, maxiter, popsize):
    """Differential evolution over (K, theta0) with the constraints of ``fast``."""
    constraint = scipy.optimize.NonlinearConstraint(lambda x: fast(x)[1], -np.inf, 0.0)
    return scipy.optimize.differential_evolution(
        lambda x: fast(x)[0], bounds, constraints=(constraint,), seed=seed, maxiter=maxiter,
        popsize=popsize, tol=1e-8, polish=False, init='sobol')


def _polish(fast, start, stiffness_max, theta0_range):
    """COBYLA from the global stage's design, inside the constraints and bounds."""
    low, high = theta0_range
    cons = [{'type': 'ineq', 'fun': lambda x, i=i: -fast(x)[1][i]} for i in range(5)]
    cons += [{'type': 'ineq', 'fun': lambda x: x[0]},
             {'type': 'ineq', 'fun': lambda x: stiffness_max - x[0]},
             {'type': 'ineq', 'fun': lambda x: x[1] - low},
             {'type': 'ineq', 'fun': lambda x: high - x[1]}]
    return scipy.optimize.minimize(lambda x: fast(x)[0], start, method='COBYLA',
                                   constraints=cons,
                                   options={'rhobeg': 0.5, 'tol': 1e-7, 'maxiter': 400})


__all__ = ['SpringProblem', 'DesignEvaluation', 'design_spring', 'DESIGN_JOINTS',
           'FORCE_FACTOR', 'TORQUE_FACTOR', 'STIFFNESS_MAX', 'PAPER_DESIGN']
