"""
Rigid-body kinematics of the four-bar linkage, vectorised over crank angles.

Positions are complex numbers x + iy in the ground frame. The loop closure is
``a e^{i th2} + b e^{i th3} - c e^{i th4} = g`` with th2 the crank angle, th3 the coupler
angle (A->B) and th4 the lever angle (O4->B). Its time derivatives of order n are linear in
the unknown n-th derivatives of th3 and th4 with one and the same 2x2 matrix, so angles,
angular velocities, accelerations and jerks are all solved exactly (no finite differences).
The matrix is singular when coupler and lever are collinear (transmission angle 0 or 180
degrees), which a Grashof crank-rocker never reaches; such a state raises LoopClosureError.
"""

import dataclasses

import numpy as np

from ..errors import LoopClosureError
from ..names import JOINT_NAMES

# sin(transmission angle) below this is treated as a locked (singular) linkage.
SINGULAR_SIN = 1e-9


@dataclasses.dataclass(frozen=True)
class LinkageState:
    """
    Rigid-body state of the linkage at n crank angles.

    Attributes
    ----------
    angle, omega, alpha, jerk : ndarray, shape (3, n)
        Angle [rad], angular velocity [rad/s], acceleration [rad/s^2] and jerk [rad/s^3] of
        crank, coupler and lever (each link's x axis from its first joint to its second).
    joints : dict of str to ndarray, shape (n,), complex
        Positions of O2, A, B, O4 [m].
    lengths : tuple of float
        Ground, crank, coupler, lever lengths [m].

    """

    angle: np.ndarray
    omega: np.ndarray
    alpha: np.ndarray
    jerk: np.ndarray
    joints: dict
    lengths: tuple

    @property
    def crank_angle(self):
        """Crank angle [rad], shape (n,)."""
        return self.angle[0]

    @property
    def transmission_angle(self):
        """Angle between coupler and lever [rad] in [0, pi], shape (n,)."""
        return np.abs(np.angle(np.exp(1j * (self.angle[1] - self.angle[2]))))

    def origin(self, link):
        """Position of a link's first joint (O2, A, O4) [m], complex, shape (n,)."""
        return self.joints[('O2', 'A', 'O4')[link]]

    def point(self, link, x, y=0.0):
        """
        Motion of a link's material point at x, y in its frame, as a complex Taylor tuple.

        Parameters
        ----------
        link : int
            0 crank, 1 coupler, 2 lever.
        x, y : float or ndarray
            Coordinates [m] along and across the link, from its first joint.

        Returns
        -------
        position, velocity, acceleration, jerk : ndarray, shape (n,), complex
            In the ground frame [m, m/s, m/s^2, m/s^3].

        """
        local = (x + 1j * y) * np.exp(1j * self.angle[link])
        w, a, j = self.omega[link], self.alpha[link], self.jerk[link]
        rel = (local, 1j * w * local, (1j * a - w ** 2) * local,
               (1j * (j - w ** 3) - 3.0 * w * a) * local)
        if link == 1:  # the coupler's origin A moves with the crank
            base = self.point(0, self.lengths[1])
            return tuple(b + r for b, r in zip(base, rel))
        return (self.origin(link) + rel[0],) + rel[1:]


def _branch_sign(branch):
    return 1.0 if branch == 'open' else -1.0


def solve_positions(lengths, crank_angle, branch='open'):
    """
    Coupler and lever angles for given crank angles (loop closure).

    Parameters
    ----------
    lengths : tuple of float
        Ground g, crank a, coupler b, lever c [m].
    crank_angle : ndarray, shape (n,)
        Crank angles [rad], counter-clockwise from O2->O4.
    branch : str
        'open' puts B to the left of A->O4 (above the ground line), 'crossed' to the right.

    Returns
    -------
    coupler_angle, lever_angle : ndarray, shape (n,)
    joints : dict of str to complex ndarray, shape (n,)

    """
    g, a, b, c = lengths
    theta = np.asarray(crank_angle, dtype=float)
    pos_a = a * np.exp(1j * theta)
    pos_o4 = np.full_like(pos_a, g)
    chord = pos_o4 - pos_a
    dist = np.abs(chord)
    along = (b ** 2 - c ** 2 + dist ** 2) / (2.0 * dist)
    h2 = b ** 2 - along ** 2
    if np.any(h2 < 0.0) or np.any(~np.isfinite(h2)):
        bad = np.flatnonzero((h2 < 0.0) | ~np.isfinite(h2))[0]
        raise LoopClosureError(float(np.ravel(theta)[bad]),
                               'coupler and lever cannot reach each other')
    unit = chord / dist
    pos_b = pos_a + unit * (along + 1j * _branch_sign(branch) * np.sqrt(h2))
    joints = {'O2': np.zeros_like(pos_a), 'A': pos_a, 'B': pos_b, 'O4': pos_o4}
    return np.angle(pos_b - pos_a), np.angle(pos_b - pos_o4), joints


def _solve_rates(lengths, angle, rhs):
    """Solve b q3 i e^{i th3} - c q4 i e^{i th4} = rhs for real (q3, q4); vectorised."""
    _, _, b, c = lengths
    e3 = 1j * b * np.exp(1j * angle[1])
    e4 = -1j * c * np.exp(1j * angle[2])
    det = e3.real * e4.imag - e3.imag * e4.real  # = b c sin(th3 - th4)
    sin_mu = det / (b * c)
    if np.any(np.abs(sin_mu) < SINGULAR_SIN):
        bad = np.flatnonzero(np.abs(sin_mu) < SINGULAR_SIN)[0]
        raise LoopClosureError(float(angle[0][bad]),
                               'coupler and lever are collinear (toggle): velocities undefined')
    q3 = (rhs.real * e4.imag - rhs.imag * e4.real) / det
    q4 = (e3.real * rhs.imag - e3.imag * rhs.real) / det
    return q3, q4


def solve_kinematics(mechanism, crank_angle, crank_speed=0.0, crank_accel=0.0, crank_jerk=0.0):
    """
    Angles, angular velocities, accelerations and jerks of all links.

    Parameters
    ----------
    mechanism : Mechanism
        Geometry and branch.
    crank_angle : float or ndarray, shape (n,)
        Crank angle [rad].
    crank_speed, crank_accel, crank_jerk : float or ndarray, shape (n,)
        Crank angular velocity [rad/s], acceleration [rad/s^2], jerk [rad/s^3].

    Returns
    -------
    LinkageState

    Raises
    ------
    LoopClosureError
        If the linkage cannot assemble or is at a toggle of coupler and lever.

    """
    lengths = mechanism.lengths
    theta = np.atleast_1d(np.asarray(crank_angle, dtype=float))
    n = theta.shape[0]
    w2, a2, j2 = (np.broadcast_to(np.asarray(v, dtype=float), (n,)).copy()
                  for v in (crank_speed, crank_accel, crank_jerk))
    th3, th4, joints = solve_positions(lengths, theta, mechanism.branch)
    angle = np.stack([theta, th3, th4])
    signs = np.array([1.0, 1.0, -1.0])[:, None]
    z = signs * np.array(lengths[1:])[:, None] * np.exp(1j * angle)  # signed link vectors

    # First derivative: sum_k i w_k z_k = 0.
    w3, w4 = _solve_rates(lengths, angle, -(1j * w2 * z[0]))
    omega = np.stack([w2, w3, w4])
    # Second: sum_k (i a_k - w_k^2) z_k = 0.
    known = 1j * a2 * z[0] - (omega ** 2 * z).sum(axis=0)
    a3, a4 = _solve_rates(lengths, angle, -known)
    alpha = np.stack([a2, a3, a4])
    # Third: sum_k (i (j_k - w_k^3) - 3 w_k a_k) z_k = 0.
    known = 1j * j2 * z[0] + ((-1j * omega ** 3 - 3.0 * omega * alpha) * z).sum(axis=0)
    j3, j4 = _solve_rates(lengths, angle, -known)
    jerk = np.stack([j2, j3, j4])
    return LinkageState(angle=angle, omega=omega, alpha=alpha, jerk=jerk, joints=joints,
                        lengths=lengths)


def dead_centres(mechanism):
    """
    Crank angles [rad] of the two dead-centre (limit) positions of the lever.

    There crank and coupler are collinear, extended (first) and folded (second), and the
    lever's angular velocity passes through zero. Returned in [0, 2 pi).
    """
    g, a, b, c = mechanism.lengths
    out = []
    for reach in (b + a, b - a):  # O2-B distance: extended, folded
        # B lies at distance `reach` from O2 and c from O4, on the mechanism's branch.
        x = (reach ** 2 - c ** 2 + g ** 2) / (2.0 * g)
        y = _branch_sign(mechanism.branch) * np.sqrt(max(reach ** 2 - x ** 2, 0.0))
        direction = np.arctan2(y, x) if reach > 0 else 0.0
        crank = direction if reach == b + a else direction + np.pi
        out.append(float(np.mod(crank, 2.0 * np.pi)))
    return tuple(out)


def transmission_extremes(mechanism, samples=3601):
    """Minimum and maximum transmission angle [rad] over a revolution, sampled finely."""
    theta = np.linspace(0.0, 2.0 * np.pi, samples)
    state = solve_kinematics(mechanism, theta)
    mu = state.transmission_angle
    return float(mu.min()), float(mu.max())


__all__ = ['LinkageState', 'solve_positions', 'solve_kinematics', 'dead_centres',
           'transmission_extremes', 'JOINT_NAMES']
