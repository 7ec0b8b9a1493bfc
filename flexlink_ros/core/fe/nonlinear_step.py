"""
One Radau IIA step of the geometrically nonlinear full order, by Newton's method.

The equation of motion is the linear KED equation (Cho, Park & Lee 1992, Eq. 30) with the
elastic element forces replaced by :mod:`core.fe.nonlinear_strain` ::

    M U'' + C U' + K U + sum_e T_e^T f_e(T_e U, T_e U' + w_L D1_e U) = R

where M, C, K and R hold everything that stays linear (inertia, convective terms, bearings,
modal damping; K_G only with the linear strain) and ``f_e`` the element force on the
link-frame coordinates (``T_e``: the element's rows of the link gather, Eq. 25; ``D1_e``
their derivative in theta_L, so that ``T_e U' + w_L D1_e U`` is the link-frame rate as in
:mod:`core.fe.stiffness_damping`).

The step is the s-stage Radau IIA collocation of :class:`core.integrators.RadauIIA` in stage
accelerations A_i (``Q_i = q + c_i h v + h^2 (a a A)_i``, ``V_i = v + h (a A)_i``), the
residual ``r_i = M_i A_i + C_i V_i + K_i Q_i + F(Q_i, V_i) - R_i`` solved by full Newton:
the Jacobian block (i, j) is ``M_i d_ij + h a_ij (C_i + F_v,i) + h^2 (aa)_ij (K_i + F_q,i)``.
With the linear strain the residual is affine and one iteration gives the linear step
exactly. The step's sensitivity ``d(q_new, v_new)/d(q, v)`` (the linearised step: the
implicit function theorem on the converged residual) is returned on request; its product over
a revolution is the monodromy matrix.
"""

import dataclasses

import numpy as np
import scipy.linalg

from . import corotational_strain
from .nonlinear_strain import (element_coordinates, element_force, element_tangent,
                               project_force, strain_energy)
from ...errors import ConvergenceError

# Newton stops when the stage-acceleration update is this small against the accelerations.
NEWTON_TOLERANCE = 1e-10
NEWTON_ITERATIONS = 40
# Below this relative update a Newton iteration that no longer contracts is at round-off.
ROUND_OFF = 1e-7


@dataclasses.dataclass(frozen=True)
class StageSystem:
    """
    Everything one step needs at its s stage times (see the module notes).

    Attributes
    ----------
    mass, damping, stiffness : ndarray, shape (s, n, n)
        The linear part: M, C, K.
    load : ndarray, shape (s, n)
        R.
    gather, rate_gather : ndarray, shape (s, E, 6, n)
        ``T_e`` and ``w_L D1_e``: q_e = T_e U, q_e' = T_e U' + w_L D1_e U.

    """

    mass: np.ndarray
    damping: np.ndarray
    stiffness: np.ndarray
    load: np.ndarray
    gather: np.ndarray
    rate_gather: np.ndarray


# The nonlinear element strains: co-rotational (exact in an element's rigid turn) or the
# element-averaged von Karman strain (exact to second order in the turn).
STRAINS = ('corotational', 'von-karman')


@dataclasses.dataclass(frozen=True)
class ElementLaw:
    """
    The element force: :class:`nonlinear_strain.Elements`, beta [s], nonlinear or not.

    ``strain`` (one of :data:`STRAINS`) chooses the nonlinear strain; with ``nonlinear``
    False the strain is the linear one whatever ``strain`` says.
    """

    elements: object
    beta: float = 0.0
    nonlinear: bool = True
    strain: str = STRAINS[0]

    def __post_init__(self):
        """Refuse an unknown strain."""
        if self.strain not in STRAINS:
            raise ValueError(f'`strain` must be one of {STRAINS}, got {self.strain!r}')

    def strain_energy(self, q):
        """Strain energy [J] of element coordinates q (..., E, 6), summed over the elements."""
        if self.nonlinear and self.strain == 'corotational':
            return corotational_strain.strain_energy(self.elements, q)
        return strain_energy(self.elements, q, self.nonlinear)

    def force_and_tangent(self, q, rate, tangents=True):
        """Element forces, axial forces and (with ``tangents``) df/dq, df/dq'."""
        if self.nonlinear and self.strain == 'corotational':
            if not tangents:
                return corotational_strain.element_force(self.elements, q, rate,
                                                         self.beta) + (None, None)
            return corotational_strain.force_and_tangent(self.elements, q, rate, self.beta)
        force, axial = element_force(self.elements, q, rate, self.beta, self.nonlinear)
        if not tangents:
            return force, axial, None, None
        return (force, axial) + element_tangent(self.elements, q, rate, self.beta,
                                                self.nonlinear, axial)


def stage_forces(law, stage, disp, vel, tangents=True):
    """
    Element forces at the stages: F (s, n) and, with ``tangents``, F_q and F_v (s, n, n).

    ``disp``, ``vel``: U and U' at the stages, (s, n).
    """
    gather, rate_gather = stage.gather, stage.rate_gather
    shape = gather.shape[:-1]
    q = element_coordinates(gather, disp)
    rate = (element_coordinates(gather, vel) + element_coordinates(rate_gather, disp))
    force, _, k_t, c_t = law.force_and_tangent(q, rate, tangents)
    out = project_force(gather, force)
    if not tangents:
        return out, None, None
    flat = np.swapaxes(gather.reshape(shape[0], -1, gather.shape[-1]), -1, -2)
    f_q = flat @ (k_t @ gather + c_t @ rate_gather).reshape(flat.shape[0], -1, flat.shape[1])
    f_v = flat @ (c_t @ gather).reshape(flat.shape[0], -1, flat.shape[1])
    return out, f_q, f_v


def _stage_states(method, h, q, v, acc):
    """Stage displacements and velocities from stage accelerations, each (s, n)."""
    disp = q[None] + (method.c[:, None] * h) * v[None] + h * h * (method.a2 @ acc)
    vel = v[None] + h * (method.a @ acc)
    return disp, vel


def newton_step(method, h, q, v, stage, law, guess=None, sensitivity=False,
                tolerance=NEWTON_TOLERANCE, iterations=NEWTON_ITERATIONS):
    """
    Advance (q, v) by one step of length h.

    Parameters
    ----------
    method : RadauIIA
        The collocation method.
    h : float
        Step [s].
    q, v : ndarray, shape (n,)
        U and U' at the step's start.
    stage : StageSystem
        The system at the stage times.
    law : ElementLaw
        The element force.
    guess : ndarray, shape (s, n) or None
        Starting stage accelerations (default zero).
    sensitivity : bool
        Also return the linearised step map d(q_new, v_new)/d(q, v), (2 n, 2 n).
    tolerance : float
        Newton stops when the update is this small against the stage accelerations.
    iterations : int
        Newton iterations at most.

    Returns
    -------
    q_new, v_new : ndarray, shape (n,)
    acc : ndarray, shape (s, n)
        The stage accelerations (the next step's guess).
    count : int
        Newton iterations.
    step_map : ndarray, shape (2 n, 2 n) or None

    Raises
    ------
    ConvergenceError
        If Newton does not converge in ``iterations``.

    """
    s, n = stage.mass.shape[0], stage.mass.shape[1]
    acc = np.zeros((s, n)) if guess is None else np.array(guess, dtype=float)
    previous = np.inf
    for count in range(1, iterations + 1):
        disp, vel = _stage_states(method, h, q, v, acc)
        force, f_q, f_v = stage_forces(law, stage, disp, vel)
        residual = (np.einsum('sij,sj->si', stage.mass, acc)
                    + np.einsum('sij,sj->si', stage.damping, vel)
                    + np.einsum('sij,sj->si', stage.stiffness, disp) + force - stage.load)
        stiffness, damping = stage.stiffness + f_q, stage.damping + f_v
        factor = scipy.linalg.lu_factor(method.step_matrix(h, stage.mass, damping, stiffness),
                                        check_finite=False)
        update = scipy.linalg.lu_solve(factor, -residual.ravel(), check_finite=False)
        acc = acc + update.reshape(s, n)
        size = np.abs(update).max()
        scale = np.abs(acc).max()
        # converged, or stalled at round-off (no longer halving, already tiny)
        if size <= tolerance * scale or size == 0.0 or (
                size > 0.5 * previous and size <= ROUND_OFF * scale):
            break
        previous = size
        if not np.isfinite(size):
            count = iterations
            break
    else:
        count = iterations + 1
    if count > iterations or not np.all(np.isfinite(acc)):
        raise ConvergenceError('the nonlinear Radau step (Newton)', iterations, float(size))
    q_new = q + h * v + h * h * (method.a2[-1] @ acc)
    v_new = v + h * (method.a[-1] @ acc)
    step_map = (_step_map(method, h, factor, stiffness, damping) if sensitivity else None)
    return q_new, v_new, acc, count, step_map


def _step_map(method, h, factor, stiffness, damping):
    """
    Return the linearised step ``d(q_new, v_new)/d(q, v)`` from the last Jacobian, (2n, 2n).

    dr_i/dq = K_i, dr_i/dv = C_i + c_i h K_i (tangents included), so
    ``dA/d(q, v) = -J^-1 [K_i | C_i + c_i h K_i]``.
    """
    s, n = stiffness.shape[0], stiffness.shape[1]
    ch = (method.c * h)[:, None, None]
    operator = -np.concatenate([stiffness, damping + ch * stiffness], axis=2)
    sens = scipy.linalg.lu_solve(factor, operator.reshape(s * n, 2 * n),
                                 check_finite=False).reshape(s, n, 2 * n)
    out = np.zeros((2 * n, 2 * n))
    out[:n, :n] = np.eye(n)
    out[:n, n:] = h * np.eye(n)
    out[n:, n:] = np.eye(n)
    out[:n] += h * h * np.tensordot(method.a2[-1], sens, axes=1)
    out[n:] += h * np.tensordot(method.a[-1], sens, axes=1)
    return out


__all__ = ['NEWTON_TOLERANCE', 'NEWTON_ITERATIONS', 'StageSystem', 'ElementLaw',
           'stage_forces', 'newton_step']
