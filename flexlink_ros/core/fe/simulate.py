"""
Periodic steady-state elastic response of the flexible four-bar at constant crank speed.

Full order (the reference). Eq. 30 of Cho, Park & Lee (1992) in full, at crank speed w
(a = 0) ::

    M U'' + (C_c + C_d) U' + (K + K_G + K_c) U = R

with modal damping ``C_d = M Phi diag(2 zeta omega_i) Phi^T M`` from ALL frozen modes of
(K + K_G) vs M at the current angle (:mod:`core.fe.modes`), so every frozen mode has damping
ratio zeta. It is integrated by Radau IIA (:mod:`core.integrators`; L-stable, so the
unresolved axial modes follow quasi-statically) with the coefficient matrices assembled
exactly at every stage time. The one-revolution map is affine, ``z_T = P z_0 + g``
(z = (U, U')), so propagating the 2n unit states and the loaded zero state together gives
the monodromy matrix P and the periodic state ``z_0 = (I - P)^-1 g`` in one pass (shooting);
the Floquet multipliers (eigenvalues of P) are reported.

Mode superposition (the paper's method). On each time step the displacement is sought in
the span of the N lowest frozen modes Phi_k at the step's start, ``U = Phi_k q`` (Galerkin
projection of the full equation, including C_d, with the basis held constant over the step,
so no dPhi/dt terms arise); Phi_k are the frozen modes at the step's first Radau stage
(theta_k + h/3 for two stages, near the step's middle). At the step boundary theta_k the state
is carried to the new basis by the M(theta_k)-orthogonal projection
``q <- (B^T M B)^-1 B^T M Phi_{k-1} q`` (B = Phi_k; same for q'), which is an exact change of
coordinates when all modes are kept: then the modal response equals the full-order one. The
approximation is what the projection discards of the state: the part of the rotating frozen
subspace not resolved by N modes (the dPhi/dt terms), O(h^2) in the output. Measured at
391 rpm, 6 modes with static correction, against the full order (5760 steps): rigid crank
with flexible bearings 0.19 / 0.05 / 0.03 mm at 720 / 1440 / 2880 steps per revolution
(coupler mid-point peak-to-peak 14 mm), all links flexible with pins 0.17 / 0.06 / 0.03 mm
(7.6 mm). Rigid-body-like motions on the bearing springs are what rotate most in the mixed
moving/ground-frame coordinates. The static (residual-flexibility) correction adds, at
the output points, the quasi-static response of the discarded modes to the load the modal
part sees: ``U_r = (K_f^-1 - Phi Lambda^-1 Phi^T) (R - C_c U_m' - K_c U_m)`` with
K_f = K + K_G.

Stiffness-proportional damping. With ``beta`` > 0 the objective
Kelvin-Voigt damping of :mod:`core.fe.stiffness_damping` is added at every stage:
``C_beta U' + D_beta U`` with ``C_beta = beta K`` on the damping and ``D_beta = w Kb1`` on the
stiffness, on top of the modal zeta (set zeta = 0 for beta alone, the peer's convention).
"""

import dataclasses
import time

import numpy as np
import scipy.linalg

from .modes import modal_damping
from .stiffness_damping import stiffness_damping_terms
from ..integrators import RadauIIA

METHODS = ('full', 'modal')
# Time steps per revolution of the default run (order-3 Radau IIA, resolves ~40 Hz x 20).
DEFAULT_STEPS = 720
# Output points per revolution (the paper: 60 intervals, start and middle: every 3 degrees).
DEFAULT_POINTS = 120
DEFAULT_STAGES = 2
# Steps assembled per batch (bounds memory at n DOFs: CHUNK * stages * n^2 doubles per matrix).
CHUNK_STEPS = 48


@dataclasses.dataclass(frozen=True)
class PeriodicResponse:
    """
    One steady revolution of the elastic response.

    Attributes
    ----------
    crank_angle : ndarray, shape (P,)
        Output crank angles [rad] (unwrapped, from the start angle).
    displacement, velocity : ndarray, shape (P, n)
        U and U' (with the static correction in U when requested).
    outputs : ndarray, shape (P, 4)
        Ground-frame deflections [m] in :data:`names.OUTPUT_NAMES` order.
    floquet_multipliers : ndarray, shape (2 n,) or (2 N,)
        Eigenvalues of the one-revolution map, largest modulus first.
    info : dict
        Method, steps, stages, modes, wall time [s].

    """

    crank_angle: np.ndarray
    displacement: np.ndarray
    velocity: np.ndarray
    outputs: np.ndarray
    floquet_multipliers: np.ndarray
    info: dict

    @property
    def peak_to_peak(self):
        """Peak-to-peak of each output channel [m], shape (4,)."""
        return self.outputs.max(axis=0) - self.outputs.min(axis=0)


def frozen_eigen(system, speed, accel=0.0):
    """All frozen eigenpairs of (K + K_G) vs M: values (N, n), shapes (N, n, n)."""
    stiffness = system.frozen_stiffness(speed, accel)
    n = system.size
    values = np.empty((len(system), n))
    shapes = np.empty((len(system), n, n))
    for k in range(len(system)):
        values[k], shapes[k] = scipy.linalg.eigh(stiffness[k], system.mass[k])
    return values, shapes


def _stage_matrices(model, angles, speed, zeta, damped=None, beta=0.0):
    """
    M, C_c + C_d (+ C_beta), K + K_G + K_c (+ D_beta), R at angles, and the frozen eigenpairs.

    ``damped``: number of lowest frozen modes that carry modal damping (all if None);
    ``beta``: stiffness-proportional damping [s] (:mod:`core.fe.stiffness_damping`).
    """
    system = model.assemble(angles)
    mass, gyro, stiffness, load = system.evaluate(speed, 0.0)
    values, shapes = frozen_eigen(system, speed)
    damped = slice(None, damped)
    damping = gyro + modal_damping(mass, values[:, damped], shapes[:, :, damped], zeta)
    if beta:
        c_beta, d_beta = stiffness_damping_terms(model, angles, speed, beta)
        damping, stiffness = damping + c_beta, stiffness + d_beta
    return mass, damping, stiffness, load, values, shapes


def _check(model, speed, method, modes, steps, points):
    if method not in METHODS:
        raise ValueError(f'`method` must be one of {METHODS}, got {method!r}')
    if not np.isfinite(speed) or speed == 0.0:
        raise ValueError(f'`speed` must be a non-zero crank speed [rad/s], got {speed!r}')
    if points < 1 or steps < 1 or steps % points:
        raise ValueError(f'`steps` ({steps}) must be a positive multiple of `points` ({points})')
    if method == 'modal' and not (modes is not None and 1 <= modes <= model.size):
        raise ValueError(f'`modes` must be in 1..{model.size} for the modal method, got {modes!r}')


def periodic_response(model, speed, method='full', modes=None, static_correction=False,
                      steps=DEFAULT_STEPS, points=DEFAULT_POINTS, stages=DEFAULT_STAGES,
                      zeta=None, start_angle=0.0, matrices=None, beta=None):
    """
    Periodic steady state over one revolution at constant crank speed.

    Parameters
    ----------
    model : FlexibleLinkage
        The FE model (:class:`core.fe.linkage.FlexibleLinkage`).
    speed : float
        Crank speed w [rad/s] (non-zero, either sign).
    method : str
        'full' (Eq. 30 in full) or 'modal' (N lowest frozen modes, see the module notes).
    modes : int or None
        N for the modal method.
    static_correction : bool
        Add the residual-flexibility response of the discarded modes (modal method).
    steps : int
        Time steps per revolution (a multiple of ``points``).
    points : int
        Output points per revolution.
    stages : int
        Radau IIA stages (order 2 stages - 1).
    zeta : float or None
        Modal damping ratio; None for ``mechanism.damping_ratio``.
    start_angle : float
        Crank angle of the first output [rad].
    matrices : callable or None
        ``matrices(angles) -> (M, C, K, R)`` at an array of crank angles, in place of the
        model's own (modal damping ``zeta``) for the 'full' method: another damping model.
    beta : float or None
        Stiffness-proportional damping [s] added to the modal zeta (zeta = 0 for beta alone);
        None for ``model.options.stiffness_damping``.

    Returns
    -------
    PeriodicResponse

    """
    _check(model, speed, method, modes, steps, points)
    if matrices is not None and method != 'full':
        raise ValueError('`matrices` replaces the full-order matrices: method must be full')
    started = time.perf_counter()
    modal = method == 'modal'
    run = _Run(integrator=RadauIIA(stages), speed=speed, h=2.0 * np.pi / abs(speed) / steps,
               steps=steps, stride=steps // points, size=modes if modal else model.size,
               modal=modal, start_angle=start_angle,
               zeta=model.mechanism.damping_ratio if zeta is None else float(zeta),
               beta=_beta(model, beta))
    q, v, saved = _propagate(model, run, matrices)
    monodromy, disp, vel = _periodic_states(q, v, saved, modal)
    out_angles = start_angle + speed * run.h * run.stride * np.arange(points)
    corrected = modal and static_correction and run.size < model.size
    if corrected:
        disp = disp + _residual_flexibility(model, out_angles, speed, disp, vel, run.size,
                                            run.beta)
    outputs = np.einsum('kon,kn->ko', model.output_operator(out_angles), disp)
    multipliers = np.linalg.eigvals(monodromy)
    multipliers = multipliers[np.argsort(-np.abs(multipliers))]
    info = {'method': method, 'modes': run.size if modal else None,
            'static_correction': bool(corrected),
            'steps': steps, 'points': points, 'stages': stages,
            'zeta': run.zeta if matrices is None else None,
            'stiffness_damping_s': run.beta if matrices is None else None,
            'speed_rad_s': float(speed), 'dofs': model.size,
            'spectral_radius': float(np.abs(multipliers[0])),
            'wall_s': time.perf_counter() - started}
    return PeriodicResponse(crank_angle=out_angles, displacement=disp, velocity=vel,
                            outputs=outputs, floquet_multipliers=multipliers, info=info)


@dataclasses.dataclass(frozen=True)
class _Run:
    """Settings of one revolution's integration (see :func:`periodic_response`)."""

    integrator: RadauIIA
    speed: float
    h: float
    steps: int
    stride: int
    size: int
    modal: bool
    start_angle: float
    zeta: float
    beta: float = 0.0


def _beta(model, beta):
    """Return a run's stiffness-proportional damping [s]: ``beta``, else the model's option."""
    value = getattr(model.options, 'stiffness_damping', 0.0) if beta is None else beta
    value = float(value)
    if not (np.isfinite(value) and value >= 0.0):
        raise ValueError(f'`beta` must be >= 0 [s], got {beta!r}')
    return value


def _chunk_matrices(model, run, chunk, matrices):
    """Return M, C, K, R (and frozen eigenpairs) at a chunk's stages, (steps, stages, ...)."""
    angles = run.start_angle + run.speed * run.h * (chunk[:, None] + run.integrator.c[None, :])
    stages = run.integrator.c.shape[0]
    stage = (_stage_matrices(model, angles.ravel(), run.speed, run.zeta,
                             run.size if run.modal else None, run.beta)
             if matrices is None else matrices(angles.ravel()))
    return [x.reshape((len(chunk), stages) + x.shape[1:]) for x in stage]


def _change_basis(mass, new_basis, old_basis):
    """Map modal coordinates on ``old_basis`` to ``new_basis`` by M-orthogonal projection."""
    gram = new_basis.T @ mass @ new_basis
    return np.linalg.solve(gram, new_basis.T @ mass @ old_basis)


def _integrate_step(run, q, v, step_matrices, basis):
    """Advance the unit and loaded states (q, v) by one step of the integrator."""
    mass, damping, stiffness, load = step_matrices
    loads = np.zeros((load.shape[0], run.size, q.shape[1]))
    if run.modal:
        project = lambda x: basis.T @ x @ basis  # noqa: E731
        loads[..., -1] = load @ basis
        q, v, _ = run.integrator.step(q, v, run.h, project(mass), project(damping),
                                      project(stiffness), loads)
    else:
        loads[..., -1] = load
        q, v, _ = run.integrator.step(q, v, run.h, mass, damping, stiffness, loads)
    return q, v


def _propagate(model, run, matrices):
    """
    Carry the 2 N unit states and the loaded zero state over one revolution.

    Returns the final (q, v), each (N, 2 N + 1) (columns: unit displacements, unit velocities,
    loaded zero state), and (q, v, basis) at every output step (basis None for full order).
    """
    size = run.size
    q = np.zeros((size, 2 * size + 1))
    v = np.zeros((size, 2 * size + 1))
    q[:, :size] = np.eye(size)
    v[:, size:2 * size] = np.eye(size)
    basis = basis0 = mass_prev = None
    saved = []
    for begin in range(0, run.steps, CHUNK_STEPS):
        chunk = np.arange(begin, min(begin + CHUNK_STEPS, run.steps))
        mass, damping, stiffness, load, *eigen = _chunk_matrices(model, run, chunk, matrices)
        for i, k in enumerate(chunk):
            if run.modal:
                new_basis = eigen[1][i, 0][:, :size]
                if k == 0:
                    basis = basis0 = new_basis
                else:
                    transfer = _change_basis(mass_prev, new_basis, basis)
                    q, v, basis = transfer @ q, transfer @ v, new_basis
            if k % run.stride == 0:
                saved.append((q.copy(), v.copy(), basis))
            q, v = _integrate_step(run, q, v, (mass[i], damping[i], stiffness[i], load[i]),
                                   basis)
            if run.modal:
                mass_prev = mass[i, -1]
    if run.modal:
        transfer = _change_basis(mass_prev, basis0, basis)
        q, v = transfer @ q, transfer @ v
    return q, v, saved


def _periodic_states(q, v, saved, modal):
    """
    Monodromy matrix P, and U and U' at the output steps of the periodic orbit (shooting).

    The one-revolution map is ``z_T = P z_0 + g``; the periodic start is ``(I - P)^-1 g``.
    """
    size = q.shape[0]
    monodromy = np.vstack([q[:, :-1], v[:, :-1]])
    offset = np.concatenate([q[:, -1], v[:, -1]])
    start = np.linalg.solve(np.eye(2 * size) - monodromy, offset)
    state = np.concatenate([start, [1.0]])
    if modal:
        disp = np.array([b @ (sq @ state) for sq, _, b in saved])
        vel = np.array([b @ (sv @ state) for _, sv, b in saved])
    else:
        disp = np.array([sq @ state for sq, _, _ in saved])
        vel = np.array([sv @ state for _, sv, _ in saved])
    return monodromy, disp, vel


def _residual_flexibility(model, angles, speed, disp, vel, kept, beta=0.0):
    """
    (K_f^-1 - Phi_N Lambda_N^-1 Phi_N^T)(R - C_c U' - K_c U) at output angles, (P, n).

    With ``beta`` the load also loses the damping force ``C_beta U' + D_beta U``.
    """
    system = model.assemble(angles)
    values, shapes = frozen_eigen(system, speed)
    damping, coupling = speed * system.gyroscopic, system.coupling_at(speed)
    if beta:
        c_beta, d_beta = stiffness_damping_terms(model, angles, speed, beta)
        damping, coupling = damping + c_beta, coupling + d_beta
    load = (system.load_at(speed) - np.einsum('kij,kj->ki', damping, vel)
            - np.einsum('kij,kj->ki', coupling, disp))
    dropped = shapes[:, :, kept:]
    modal_load = np.einsum('kim,ki->km', dropped, load)
    return np.einsum('kim,km->ki', dropped, modal_load / values[:, kept:])


def step_convergence(model, speed, steps=(90, 180, 360, 720), reference_steps=2880,
                     points=90, **kwargs):
    """
    Time-step convergence of the periodic response (for reports and tests).

    Parameters
    ----------
    model : FlexibleLinkage
        The FE model (:class:`core.fe.linkage.FlexibleLinkage`).
    speed : float
        Crank speed [rad/s].
    steps : sequence of int
        Steps per revolution to compare, each a multiple of ``points``.
    reference_steps : int
        Finest run, taken as the reference.
    points : int
        Common output points.
    **kwargs
        Passed to :func:`periodic_response`.

    Returns
    -------
    dict
        'steps', 'max_error_m' (max over outputs and points against the reference),
        'observed_order' (log2 of successive error ratios for halved steps), 'scale_m'
        (max |output| of the reference).

    """
    reference = periodic_response(model, speed, steps=reference_steps, points=points, **kwargs)
    errors = []
    for count in steps:
        run = periodic_response(model, speed, steps=count, points=points, **kwargs)
        errors.append(float(np.abs(run.outputs - reference.outputs).max()))
    errors = np.array(errors)
    ratios = np.array(steps[1:], dtype=float) / np.array(steps[:-1], dtype=float)
    order = np.log(errors[:-1] / errors[1:]) / np.log(ratios)
    return {'steps': list(steps), 'reference_steps': reference_steps,
            'max_error_m': errors.tolist(), 'observed_order': order.tolist(),
            'scale_m': float(np.abs(reference.outputs).max())}


__all__ = ['METHODS', 'PeriodicResponse', 'periodic_response', 'frozen_eigen',
           'step_convergence']
