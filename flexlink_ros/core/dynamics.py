"""
Newton-Euler inverse dynamics of the rigid crank-rocker, vectorised over crank angles.

Bodies. The crank, coupler and lever are uniform bars: centre of mass at mid-length, rotary
inertia ``Link.inertia`` about it (the rigid dynamics), mass per length ``mass / length`` (the
distributed inertia of :func:`axial_force`). A joint mass m_j (``Mechanism.joint_masses``) is
a particle at the joint centre, split across the bearing: the fraction ``joint_mass_split`` s
rides on the joint's first member (``JOINT_MEMBERS``), 1 - s on the second (a share on the
ground never moves, so it carries nothing).

Sign convention. The reaction F_j reported at joint j is the force exerted ACROSS the bearing
by the joint's first member on its second member (``JOINT_MEMBERS``), each member including
its share of the joint mass:

* O2: ground on crank,   A: crank on coupler,   B: coupler on lever,   O4: lever on ground.

The input torque T_in is the torque of the ground (motor) on the crank, counter-clockwise
positive. The optional coil spring (Kang, Lee & Yoon 1990, Eq. 1) acts between coupler and
lever with T_s = K (theta_ij - theta0), theta_ij = theta_coupler - theta_lever wrapped to
[0, 2 pi): the spring's potential is K (theta_ij - theta0)^2 / 2, so it exerts -T_s on the
coupler and +T_s on the lever. A crank-rocker's transmission angle stays inside (0, pi), so
theta_ij never crosses the wrap and T_s is smooth.

Equations. Per body k (three force/moment equations about its centre of mass G_k), with the
force of the pin on the bar body ``P_jk = sigma F_j + share m_j (g - a_j)`` (sigma = +1 on
the second member, -1 on the first)::

    sum_j P_jk + m_k g = m_k a_Gk
    sum_j (r_j - r_Gk) x P_jk + tau_k = I_k alpha_k     (tau = T_in, -T_s, T_s for k = 0, 1, 2)

are 9 linear equations A(theta) x = b in x = (F_O2, F_A, F_B, F_O4, T_in). Their exact time
derivative ``A x' = b' - A' x`` uses the joint velocities (A') and the jerk-level kinematics
and the spring rate K (w_coupler - w_lever) (b'), so every reaction rate is analytic.

At a crank angle the reactions are affine in the crank acceleration a and speed squared w^2,
``F = F_1 + a F_a + w^2 F_w2`` (F_1: gravity and spring at rest), which
:func:`reaction_pieces` tabulates with the derivatives dF/dtheta of each piece.
"""

import dataclasses

import numpy as np

from .kinematics import solve_kinematics
from .mechanism import JOINT_MEMBERS
from ..names import JOINT_NAMES

# Unknowns: (Fx, Fy) of O2, A, B, O4, then the input torque.
UNKNOWNS = 9
TORQUE_COLUMN = 8
# Joints at each end of each link body: (first joint, second joint) along the link's x axis.
LINK_JOINTS = (('O2', 'A'), ('A', 'B'), ('O4', 'B'))
# Pieces of the affine dependence on the crank motion (see reduce_samples in
# core/reduction/build.py).
PIECES = ('1', 'a', 'w2')


@dataclasses.dataclass(frozen=True)
class DynamicsResult:
    """
    Reactions, input torque and their time derivatives at n crank angles.

    Attributes
    ----------
    force, force_rate : ndarray, shape (4, n), complex
        Joint reactions Fx + i Fy [N] at O2, A, B, O4 (force of the joint's first member on
        its second, see the module docstring) and their time derivatives [N/s].
    input_torque, input_torque_rate : ndarray, shape (n,)
        Torque of the ground on the crank [N m] and its time derivative [N m/s].
    spring_torque, spring_torque_rate : ndarray, shape (n,)
        T_s = K (theta_ij - theta0) [N m] and its rate [N m/s] (zero without a spring).
    end_forces : tuple of (ndarray, ndarray)
        Per link, the forces of the pins on the bar body (joint-mass shares excluded) at its
        first and second joint [N], complex, shape (n,) each.
    state : LinkageState
        The kinematics the dynamics were solved for.

    """

    force: np.ndarray
    force_rate: np.ndarray
    input_torque: np.ndarray
    input_torque_rate: np.ndarray
    spring_torque: np.ndarray
    spring_torque_rate: np.ndarray
    end_forces: tuple
    state: object

    def reaction(self, joint):
        """Reaction at a joint ('O2', 'A', 'B', 'O4'), complex, shape (n,)."""
        return self.force[JOINT_NAMES.index(joint)]

    def force_xy(self):
        """Reactions as real components, ndarray shape (n, 4, 2)."""
        return _as_xy(self.force)

    def force_rate_xy(self):
        """Reaction rates as real components, ndarray shape (n, 4, 2)."""
        return _as_xy(self.force_rate)


def _as_xy(values):
    return np.stack([values.real.T, values.imag.T], axis=-1)


def joint_motion(state, joint):
    """
    Position, velocity, acceleration and jerk of a joint centre, complex, shape (n,) each.

    Parameters
    ----------
    state : LinkageState
        Kinematics at n crank angles.
    joint : str
        'O2', 'A', 'B' or 'O4'.

    """
    lengths = state.lengths
    if joint == 'O2':
        return state.point(0, 0.0)
    if joint == 'A':
        return state.point(0, lengths[1])
    if joint == 'B':
        return state.point(2, lengths[3])
    return state.point(2, 0.0)


def spring_angle(state):
    """theta_ij = theta_coupler - theta_lever wrapped to [0, 2 pi) [rad], shape (n,)."""
    return np.mod(state.angle[1] - state.angle[2], 2.0 * np.pi)


def _shares(mechanism, joint, body):
    """(sigma, share of the joint mass) of a joint on one of its member bodies."""
    first, second = JOINT_MEMBERS[joint]
    split = mechanism.joint_mass_split
    if body == second:
        return 1.0, 1.0 - split
    if body == first:
        return -1.0, split
    raise ValueError(f'`body` {body} is not a member of joint {joint}')


def _cross(r, f):
    """Return the z component of r x f for complex r, f."""
    return r.real * f.imag - r.imag * f.real


def _system(mechanism, state, gravity, spring_torque, spring_torque_rate):
    """Assemble A, A', b, b' of the Newton-Euler equations (n, 9, 9) x 2 and (n, 9) x 2."""
    n = state.angle.shape[1]
    g = complex(*gravity)
    matrix = np.zeros((n, UNKNOWNS, UNKNOWNS))
    matrix_rate = np.zeros((n, UNKNOWNS, UNKNOWNS))
    rhs = np.zeros((n, UNKNOWNS))
    rhs_rate = np.zeros((n, UNKNOWNS))
    motion = {joint: joint_motion(state, joint) for joint in JOINT_NAMES}
    body_torque = (0.0, -spring_torque, spring_torque)
    body_torque_rate = (0.0, -spring_torque_rate, spring_torque_rate)
    for body, link in enumerate(mechanism.links):
        row = 3 * body
        r_g, v_g, a_g, j_g = state.point(body, 0.5 * link.length)
        force = link.mass * (a_g - g)
        force_rate = link.mass * j_g
        moment = link.inertia * state.alpha[body] - body_torque[body]
        moment_rate = link.inertia * state.jerk[body] - body_torque_rate[body]
        for joint in LINK_JOINTS[body]:
            col = 2 * JOINT_NAMES.index(joint)
            sigma, share = _shares(mechanism, joint, body)
            r_j, v_j, a_j, j_j = motion[joint]
            arm, arm_rate = r_j - r_g, v_j - v_g
            matrix[:, row, col] = sigma
            matrix[:, row + 1, col + 1] = sigma
            matrix[:, row + 2, col] = -sigma * arm.imag
            matrix[:, row + 2, col + 1] = sigma * arm.real
            matrix_rate[:, row + 2, col] = -sigma * arm_rate.imag
            matrix_rate[:, row + 2, col + 1] = sigma * arm_rate.real
            # The joint-mass share moves with the joint: its inertia and weight load the body.
            particle = share * mechanism.joint_masses[joint]
            force = force - particle * (g - a_j)
            force_rate = force_rate + particle * j_j
            moment = moment - particle * _cross(arm, g - a_j)
            moment_rate = moment_rate - particle * (_cross(arm_rate, g - a_j)
                                                    - _cross(arm, j_j))
        rhs[:, row], rhs[:, row + 1], rhs[:, row + 2] = force.real, force.imag, moment
        rhs_rate[:, row], rhs_rate[:, row + 1] = force_rate.real, force_rate.imag
        rhs_rate[:, row + 2] = moment_rate
    matrix[:, 2, TORQUE_COLUMN] = 1.0
    return matrix, matrix_rate, rhs, rhs_rate


def _spring_torques(mechanism, state):
    n = state.angle.shape[1]
    if mechanism.spring is None:
        return np.zeros(n), np.zeros(n)
    stiffness = mechanism.spring.stiffness
    return (stiffness * (spring_angle(state) - mechanism.spring.theta0),
            stiffness * (state.omega[1] - state.omega[2]))


def _solve_pair(matrix, matrix_rate, rhs, rhs_rate):
    """Solve A x = b and A x' = b' - A' x for x and x', shapes (n, 9)."""
    x = np.linalg.solve(matrix, rhs[..., None])[..., 0]
    known = rhs_rate - np.einsum('nij,nj->ni', matrix_rate, x)
    x_rate = np.linalg.solve(matrix, known[..., None])
    return x, x_rate[..., 0]


def solve_dynamics(mechanism, state, gravity=None):
    """
    Joint reactions, input torque and their exact time derivatives.

    Parameters
    ----------
    mechanism : Mechanism
        Links, joint masses and split, gravity, optional spring.
    state : LinkageState
        Kinematics at n crank angles, with crank speed, acceleration and jerk
        (:func:`core.kinematics.solve_kinematics`).
    gravity : tuple of float or None
        Gravity (gx, gy) [m/s^2]; default ``mechanism.gravity``.

    Returns
    -------
    DynamicsResult

    """
    gravity = mechanism.gravity if gravity is None else gravity
    spring_torque, spring_rate = _spring_torques(mechanism, state)
    system = _system(mechanism, state, gravity, spring_torque, spring_rate)
    x, x_rate = _solve_pair(*system)
    force = (x[:, 0:8:2] + 1j * x[:, 1:8:2]).T
    force_rate = (x_rate[:, 0:8:2] + 1j * x_rate[:, 1:8:2]).T
    g = complex(*gravity)
    end_forces = []
    for body in range(3):
        ends = []
        for joint in LINK_JOINTS[body]:
            sigma, share = _shares(mechanism, joint, body)
            accel = joint_motion(state, joint)[2]
            ends.append(sigma * force[JOINT_NAMES.index(joint)]
                        + share * mechanism.joint_masses[joint] * (g - accel))
        end_forces.append(tuple(ends))
    return DynamicsResult(force=force, force_rate=force_rate, input_torque=x[:, TORQUE_COLUMN],
                          input_torque_rate=x_rate[:, TORQUE_COLUMN],
                          spring_torque=spring_torque, spring_torque_rate=spring_rate,
                          end_forces=tuple(end_forces), state=state)


def axial_force(mechanism, state, link, x, result=None):
    """
    Tension along a link bar from its distributed inertia, gravity and end forces.

    With mu = mass / length and e the link's unit x axis, the part [0, x] of the bar gives
    ``N(x) = -P_1 . e - mu ((g - a_1) . e x + w^2 x^2 / 2)``, where P_1 is the force of the
    pin on the bar at its first joint and a_1 that joint's acceleration (the axial
    acceleration of the point x is a_1 . e - w^2 x).

    Parameters
    ----------
    mechanism : Mechanism
        The linkage.
    state : LinkageState
        Kinematics at n crank angles.
    link : int
        0 crank, 1 coupler, 2 lever.
    x : ndarray, shape (m,)
        Material points along the link from its first joint [m].
    result : DynamicsResult or None
        Reuse an existing solution for this mechanism and state.

    Returns
    -------
    ndarray, shape (n, m)
        Tension [N] (negative = compression).

    """
    if link not in (0, 1, 2):
        raise ValueError(f'`link` must be 0, 1 or 2, got {link!r}')
    result = solve_dynamics(mechanism, state) if result is None else result
    body = mechanism.links[link]
    per_length = body.mass / body.length
    axis = np.exp(1j * state.angle[link])
    first_joint = LINK_JOINTS[link][0]
    accel = joint_motion(state, first_joint)[2]
    g = complex(*mechanism.gravity)
    end_tension = -_dot(result.end_forces[link][0], axis)
    along = _dot(g - accel, axis)
    x = np.atleast_1d(np.asarray(x, dtype=float))
    w2 = state.omega[link] ** 2
    return (end_tension[:, None]
            - per_length * (along[:, None] * x[None, :] + 0.5 * w2[:, None] * x[None, :] ** 2))


def _dot(u, v):
    return u.real * v.real + u.imag * v.imag


def reaction_pieces(mechanism, angles):
    """
    Reactions F = F_1 + a F_a + w^2 F_w2 at given crank angles, and dF/dtheta of each piece.

    F_1 is gravity and spring at rest, F_a the reaction per unit crank acceleration and F_w2
    per unit crank speed squared (no gravity, no spring). The angle derivatives are exact:
    along a motion at speed w, acceleration a and crank jerk j,
    ``dF/dt = w F_1' + w a F_a' + w^3 F_w2' + j F_a + 2 w a F_w2`` (' = d/dtheta), so three
    analytic time derivatives (w, a, j) = (1, 0, 0) with and without gravity and spring and
    (1, 1, 0) without give F_1', F_w2' and F_a'.

    Parameters
    ----------
    mechanism : Mechanism
        The linkage (with its optional spring).
    angles : ndarray, shape (N,)
        Crank angles [rad].

    Returns
    -------
    dict
        'force' and 'force_rate': {'1', 'a', 'w2'} -> ndarray, shape (N, 4, 2) [N] and
        [N/rad], joints O2, A, B, O4 (the ``forces`` argument of
        ``core.reduction.build.reduce_samples``); 'torque' and 'torque_rate': the same pieces
        of the input torque, shape (N,) [N m] and [N m/rad].

    """
    theta = np.atleast_1d(np.asarray(angles, dtype=float))
    bare = dataclasses.replace(mechanism, gravity=(0.0, 0.0), spring=None)
    still = solve_dynamics(mechanism, solve_kinematics(mechanism, theta, 0.0, 0.0))
    unit_a = solve_dynamics(bare, solve_kinematics(mechanism, theta, 0.0, 1.0))
    unit_w = solve_dynamics(bare, solve_kinematics(mechanism, theta, 1.0, 0.0))
    full_w = solve_dynamics(mechanism, solve_kinematics(mechanism, theta, 1.0, 0.0))
    both = solve_dynamics(bare, solve_kinematics(mechanism, theta, 1.0, 1.0))

    def pieces(get):
        value = {'1': get(still, False), 'a': get(unit_a, False), 'w2': get(unit_w, False)}
        rate_w2 = get(unit_w, True)
        rate = {'1': get(full_w, True) - rate_w2,
                'a': get(both, True) - rate_w2 - 2.0 * value['w2'],
                'w2': rate_w2}
        return value, rate

    force, force_rate = pieces(lambda r, dt: _as_xy(r.force_rate if dt else r.force))
    torque, torque_rate = pieces(lambda r, dt: r.input_torque_rate if dt else r.input_torque)
    return {'force': force, 'force_rate': force_rate, 'torque': torque,
            'torque_rate': torque_rate}


def mechanical_energy(mechanism, state):
    """
    Kinetic, gravitational and spring energy and its exact time derivative.

    Parameters
    ----------
    mechanism : Mechanism
        The linkage (with its optional spring).
    state : LinkageState
        Kinematics at n crank angles.

    Returns
    -------
    energy, energy_rate : ndarray, shape (n,)
        [J] and [W]; the input power T_in w equals energy_rate (frictionless joints).

    """
    g = complex(*mechanism.gravity)
    energy = np.zeros(state.angle.shape[1])
    rate = np.zeros_like(energy)
    for body, link in enumerate(mechanism.links):
        r, v, a, _ = state.point(body, 0.5 * link.length)
        w, alpha = state.omega[body], state.alpha[body]
        energy += 0.5 * link.mass * np.abs(v) ** 2 + 0.5 * link.inertia * w ** 2
        energy -= link.mass * _dot(g, r)
        rate += link.mass * _dot(v, a) + link.inertia * w * alpha - link.mass * _dot(g, v)
    for joint in JOINT_NAMES:
        r, v, a, _ = joint_motion(state, joint)
        mass = mechanism.joint_masses[joint]
        energy += 0.5 * mass * np.abs(v) ** 2 - mass * _dot(g, r)
        rate += mass * (_dot(v, a) - _dot(g, v))
    if mechanism.spring is not None:
        stretch = spring_angle(state) - mechanism.spring.theta0
        energy += 0.5 * mechanism.spring.stiffness * stretch ** 2
        rate += mechanism.spring.stiffness * stretch * (state.omega[1] - state.omega[2])
    return energy, rate


__all__ = ['DynamicsResult', 'solve_dynamics', 'axial_force', 'reaction_pieces',
           'mechanical_energy', 'joint_motion', 'spring_angle', 'LINK_JOINTS', 'PIECES']
