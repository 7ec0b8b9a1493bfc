"""
Periodic steady state of the geometrically nonlinear full order at constant crank speed.

The model is the linear KED full order of :mod:`core.fe.simulate` (same DOFs, inertia,
convective terms, loads, bearings, outputs) with every element's elastic and Kelvin-Voigt
force taken from the element-averaged von Karman strain (:mod:`core.fe.nonlinear_strain`)
and the rigid-body geometric stiffness K_G dropped (the axial coordinates now carry the
axial force it linearises). Inertia stays linear and exact because the link frames follow
the prescribed rigid-body motion; the outputs ``d = R H u^L`` stay exact for the same
reason. Damping: ``beta`` on the nonlinear strain rate and the bending rate of every element
(link-frame rates) and ``beta k`` on the bearing springs, as the Exudyn peer damps; modal zeta
(from the frozen modes of the linear model, as :mod:`core.fe.simulate`) on top if asked.

Time marching: s-stage Radau IIA with full Newton per step (:mod:`core.fe.nonlinear_step`).
Periodic orbit by shooting: one revolution from z_0 = (U, U') gives z_T and the monodromy
P = dz_T/dz_0 (the product of the linearised steps); Newton on ``z_T(z_0) - z_0 = 0``
updates ``z_0 += (I - P)^-1 (z_T - z_0)``, falling back to plain marching (z_0 = z_T) when a
Newton update does not reduce the mismatch, until the revolution-to-revolution change is
below ``tolerance`` relative to the orbit's size. The start is the linear periodic
response (:func:`core.fe.simulate.periodic_response`, same damping) unless given. The
Floquet multipliers are the eigenvalues of P on the converged orbit: all inside the unit
circle for a stable orbit; one near 1 marks a fold (a jump between two periodic solutions).
"""

import dataclasses
import time

import numpy as np

from .modes import modal_damping
from .nonlinear_step import ElementLaw, newton_step, StageSystem, STRAINS
from .nonlinear_strain import element_gather, model_elements
from .simulate import (DEFAULT_POINTS, DEFAULT_STAGES, DEFAULT_STEPS, frozen_eigen,
                       periodic_response, PeriodicResponse)
from ..integrators import RadauIIA
from ...errors import ConvergenceError

# Shooting stops when the revolution's change is this small against the orbit's size.
PERIODIC_TOLERANCE = 1e-8
MAX_REVOLUTIONS = 60
# Steps whose stage systems are built together, at most (and at most CHUNK_BYTES of them).
CHUNK_STEPS = 48
CHUNK_BYTES = 64 * 2 ** 20
# A revolution's stage systems are kept for the next revolutions when they fit in this many
# bytes (about 220 MB for 8 elements per link, rigid crank, bearing springs: n = 54).
STAGE_CACHE_BYTES = 256 * 2 ** 20


@dataclasses.dataclass(frozen=True)
class Run:
    """Settings of a nonlinear run at constant crank speed (see :func:`nonlinear_response`)."""

    law: ElementLaw
    integrator: RadauIIA
    speed: float
    h: float
    steps: int
    stride: int
    start_angle: float
    zeta: float


def stage_systems(model, run, angles):
    """
    Return the :class:`StageSystem` data at crank angles (N,): arrays with a leading axis N.

    Linear part: M, ``w C1 + beta K_b`` (+ modal zeta), ``K_b + K_c`` (+ K_G with the linear
    strain), R; element gathers ``T_e`` and ``w_L D1_e``.
    """
    system = model.assemble(angles)
    bearing = np.asarray(model.bearing_stiffness)
    law, speed = run.law, run.speed
    damping = speed * system.gyroscopic + law.beta * bearing
    if run.zeta:
        values, shapes = frozen_eigen(system, speed)
        damping = damping + modal_damping(system.mass, values, shapes, run.zeta)
    stiffness = bearing + system.coupling_at(speed)
    if not law.nonlinear:
        stiffness = stiffness + system.geometric_at(speed)
    link_angle, g1, _, _ = model.kinematic_coefficients(angles)
    t0 = {link: model.gather(link, link_angle[link], 0) for link in model.links}
    t1 = {link: speed * g1[link][:, None, None] * model.gather(link, link_angle[link], 1)
          for link in model.links}
    return StageSystem(mass=system.mass, damping=damping, stiffness=stiffness,
                       load=system.load_at(speed), gather=element_gather(law.elements, t0),
                       rate_gather=element_gather(law.elements, t1))


def _chunk_stages(model, run, chunk):
    """Stage systems of a chunk of steps, a list of :class:`StageSystem` (one per step)."""
    c = run.integrator.c
    angles = run.start_angle + run.speed * run.h * (chunk[:, None] + c[None, :])
    data = stage_systems(model, run, angles.ravel())
    fields = [getattr(data, f.name) for f in dataclasses.fields(StageSystem)]
    shaped = [x.reshape((len(chunk), len(c)) + x.shape[1:]) for x in fields]
    return [StageSystem(*(x[i] for x in shaped)) for i in range(len(chunk))]


def stage_bytes(model, run, steps):
    """Memory [bytes] of ``steps`` steps' :class:`StageSystem` data."""
    s, n, count = run.integrator.c.shape[0], model.size, len(run.law.elements)
    return 8 * steps * s * (3 * n * n + n + 2 * count * 6 * n)


def march(model, run, q, v, steps, sensitivity=False, stride=None, cache=None):
    """
    March ``steps`` steps of the nonlinear model from (q, v) at ``run.start_angle``.

    ``cache``: a list; empty, it is filled with every step's :class:`StageSystem`; holding
    ``steps`` of them, they are used instead of assembling again (same run, same steps).

    Returns
    -------
    dict
        'q', 'v' (end state), 'saved' (list of (q, v) at every ``stride``-th step from the
        start, start included), 'iterations' (Newton iterations per step, (steps,)),
        'monodromy' (d z_end / d z_start, (2 n, 2 n), with ``sensitivity``).

    """
    n = q.shape[0]
    stride = run.stride if stride is None else stride
    product = np.eye(2 * n) if sensitivity else None
    guess, saved, iterations = None, [], np.zeros(steps, dtype=int)
    cached = cache is not None and len(cache) == steps
    size = max(1, min(CHUNK_STEPS, CHUNK_BYTES // stage_bytes(model, run, 1)))
    for begin in range(0, steps, size):
        chunk = np.arange(begin, min(begin + size, steps))
        stages = cache[begin:chunk[-1] + 1] if cached else _chunk_stages(model, run, chunk)
        if cache is not None and not cached:
            cache.extend(stages)
        for k, stage in zip(chunk, stages):
            if k % stride == 0:
                saved.append((q, v))
            q, v, acc, iterations[k], step_map = newton_step(
                run.integrator, run.h, q, v, stage, run.law, guess, sensitivity)
            guess = np.broadcast_to(acc[-1], acc.shape)
            if sensitivity:
                product = step_map @ product
    return {'q': q, 'v': v, 'saved': saved, 'iterations': iterations, 'monodromy': product}


def _mismatch(start, end, n):
    """Revolution-to-revolution change of U and of U', each relative to its size."""
    diff = end - start
    size_q = max(np.abs(end[:n]).max(), 1e-300)
    size_v = max(np.abs(end[n:]).max(), 1e-300)
    return max(np.abs(diff[:n]).max() / size_q, np.abs(diff[n:]).max() / size_v)


def periodic_orbit(model, run, start, tolerance=PERIODIC_TOLERANCE,
                   max_revolutions=MAX_REVOLUTIONS):
    """
    Shoot for the periodic orbit from the state ``start`` = (U, U'), (2 n,).

    Returns
    -------
    revolution : dict
        :func:`march` of the converged revolution (from the periodic start).
    history : dict
        'revolutions' marched, 'newton_updates' (shooting updates taken), 'mismatch' per
        revolution, 'iterations' (Newton iterations per step over every revolution).

    """
    n = start.shape[0] // 2
    z0 = np.array(start, dtype=float)
    history = {'revolutions': 0, 'newton_updates': 0, 'mismatch': [], 'iterations': []}
    # constant speed: every revolution meets the same stage systems
    cache = [] if stage_bytes(model, run, run.steps) <= STAGE_CACHE_BYTES else None

    def revolution(state):
        out = march(model, run, state[:n], state[n:], run.steps, sensitivity=True, cache=cache)
        history['revolutions'] += 1
        history['iterations'].append(out['iterations'])
        end = np.concatenate([out['q'], out['v']])
        history['mismatch'].append(_mismatch(state, end, n))
        return out, end, history['mismatch'][-1]

    current, end, error = revolution(z0)
    while error > tolerance:
        if history['revolutions'] >= max_revolutions:
            raise ConvergenceError('the periodic orbit (shooting)', history['revolutions'],
                                   error)
        step = np.linalg.solve(np.eye(2 * n) - current['monodromy'], end - z0)
        trial = z0 + step
        out, trial_end, trial_error = revolution(trial)
        if trial_error < error:
            history['newton_updates'] += 1
            z0, current, end, error = trial, out, trial_end, trial_error
        else:   # a Newton update that did not help: march on from where it was
            z0 = end
            current, end, error = revolution(z0)
    history['iterations'] = np.concatenate(history['iterations'])
    return current, history


def _check(model, speed, steps, points):
    if not np.isfinite(speed) or speed == 0.0:
        raise ValueError(f'`speed` must be a non-zero crank speed [rad/s], got {speed!r}')
    if points < 1 or steps < 1 or steps % points:
        raise ValueError(f'`steps` ({steps}) must be a positive multiple of `points` ({points})')


def make_run(model, speed, steps, points, stages, zeta, beta, nonlinear, start_angle,
             strain=STRAINS[0]):
    """Return the :class:`Run` of :func:`nonlinear_response` (defaults from the model)."""
    beta = getattr(model.options, 'stiffness_damping', 0.0) if beta is None else beta
    if not (np.isfinite(beta) and beta >= 0.0):
        raise ValueError(f'`beta` must be >= 0 [s], got {beta!r}')
    law = ElementLaw(elements=model_elements(model), beta=float(beta), nonlinear=nonlinear,
                     strain=strain)
    return Run(law=law, integrator=RadauIIA(stages), speed=float(speed),
               h=2.0 * np.pi / abs(speed) / steps, steps=steps, stride=steps // points,
               start_angle=float(start_angle),
               zeta=model.mechanism.damping_ratio if zeta is None else float(zeta))


def nonlinear_response(model, speed, steps=DEFAULT_STEPS, points=DEFAULT_POINTS,
                       stages=DEFAULT_STAGES, zeta=None, beta=None, nonlinear=True,
                       start_angle=0.0, start=None, tolerance=PERIODIC_TOLERANCE,
                       max_revolutions=MAX_REVOLUTIONS, strain=STRAINS[0]):
    """
    Periodic steady state of the nonlinear full order over one revolution.

    Parameters
    ----------
    model : FlexibleLinkage
        The FE model (:class:`core.fe.linkage.FlexibleLinkage`): any crank model, rigid or
        flexible bearings, gravity on or off.
    speed : float
        Crank speed w [rad/s] (non-zero).
    steps, points, stages : int
        Time steps and output points per revolution, Radau IIA stages.
    zeta : float or None
        Modal damping ratio; None for ``mechanism.damping_ratio`` (0 for beta alone).
    beta : float or None
        Kelvin-Voigt damping [s]; None for ``model.options.stiffness_damping``.
    nonlinear : bool
        False: the linear strain and K_G (the linear full order, for checks).
    start_angle : float
        Crank angle of the first output [rad].
    start : ndarray, shape (2 n,) or None
        Initial guess (U, U') at ``start_angle``; None for the linear periodic state.
    tolerance : float
        Relative revolution-to-revolution change accepted as periodic.
    max_revolutions : int
        Revolutions marched at most (ConvergenceError beyond).
    strain : str
        The nonlinear element strain, one of :data:`core.fe.nonlinear_step.STRAINS`:
        'corotational' (exact in an element's rigid turn) or 'von-karman'.

    Returns
    -------
    PeriodicResponse
        As :func:`core.fe.simulate.periodic_response`; ``info`` adds 'nonlinear', the Newton
        iterations per step ('newton_mean', 'newton_max': the periodic revolution), the
        shooting history ('revolutions', 'shooting_updates', 'periodicity') and
        'step_cost_s' and 'step_cpu_s' (wall and CPU time per step marched, the monodromy's
        products included).

    """
    _check(model, speed, steps, points)
    started = time.perf_counter()
    run = make_run(model, speed, steps, points, stages, zeta, beta, nonlinear, start_angle,
                   strain)
    if start is None:
        linear = periodic_response(model, speed, steps=steps, points=points, stages=stages,
                                   zeta=run.zeta, start_angle=start_angle, beta=run.law.beta)
        start = np.concatenate([linear.displacement[0], linear.velocity[0]])
    marching, cpu = time.perf_counter(), time.process_time()
    orbit, history = periodic_orbit(model, run, np.asarray(start, dtype=float), tolerance,
                                    max_revolutions)
    wall, cpu = time.perf_counter(), time.process_time() - cpu
    disp = np.array([q for q, _ in orbit['saved']])
    vel = np.array([v for _, v in orbit['saved']])
    angles = start_angle + speed * run.h * run.stride * np.arange(points)
    outputs = np.einsum('kon,kn->ko', model.output_operator(angles), disp)
    multipliers = np.linalg.eigvals(orbit['monodromy'])
    multipliers = multipliers[np.argsort(-np.abs(multipliers))]
    info = {'method': 'nonlinear' if nonlinear else 'full', 'nonlinear': bool(nonlinear),
            'strain': run.law.strain if nonlinear else 'linear',
            'steps': steps, 'points': points, 'stages': stages, 'zeta': run.zeta,
            'stiffness_damping_s': run.law.beta, 'speed_rad_s': float(speed),
            'dofs': model.size, 'spectral_radius': float(np.abs(multipliers[0])),
            'newton_mean': float(orbit['iterations'].mean()),
            'newton_max': int(orbit['iterations'].max()),
            'revolutions': history['revolutions'],
            'shooting_updates': history['newton_updates'],
            'periodicity': float(history['mismatch'][-1]),
            'step_cost_s': (wall - marching) / (history['revolutions'] * steps),
            'step_cpu_s': cpu / (history['revolutions'] * steps),
            'wall_s': wall - started}
    return PeriodicResponse(crank_angle=angles, displacement=disp, velocity=vel,
                            outputs=outputs, floquet_multipliers=multipliers, info=info)


__all__ = ['PERIODIC_TOLERANCE', 'MAX_REVOLUTIONS', 'STAGE_CACHE_BYTES', 'Run',
           'stage_systems', 'stage_bytes', 'march',
           'periodic_orbit', 'make_run', 'nonlinear_response']
