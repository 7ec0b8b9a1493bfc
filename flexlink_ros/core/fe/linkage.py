"""
Finite-element model of the flexible four-bar of Cho, Park & Lee (1992), Eqs. 22-36.

Each modelled link is a chain of beam elements (:mod:`core.beam`) in its moving frame (x from
its first joint to its second). Interior nodes keep moving-frame DOFs (u, v, phi); the end
nodes at the joints carry ground-frame translations (X, Y) and their own rotation phi
(Fig. 3 of the paper). A link's vector u^L and the system vector U are related by
``u^L = T^T U`` (Eq. 25), where T^T is a gather matrix whose end-translation blocks are
R(theta_L)^T. Joints are either exact pins (members share X, Y; separate rotations; fixed at
O2 and O4) or isotropic bearing springs k (Eq. 23) between the members' own end nodes. The
input shaft is clamped (crank rotation at O2 fixed) or a torsional spring k_t. With a rigid
crank, crank pin A is a fixed point of the frozen structure (a flexible bearing at A then
ties the coupler's end to that point).

Derivation of the system terms (Eqs. 30-35). The link equation (Eq. 22, print typos
corrected: Eq. 18's M_a is M_s, right side M_r (g - u_r'') + F_c) is ::

    M u'' + 2 w_L M_s u' + (K - w_L^2 M + a_L M_s) u = M_r (g - u_r'')

It follows from the absolute acceleration of a material point,
``R^T a = R^T a_r + H u'' + 2 w_L S H u' + (a_L S - w_L^2) H u`` (S = I_s of Eq. 21), since
R' = w_L R S and R'' = a_L R S - w_L^2 R. With u = T^T U, u' = T'^T U + T^T U' and
u'' = T''^T U + 2 T'^T U' + T^T U'' (Eqs. 26-27), premultiplying by T (virtual work,
delta u = T^T delta U) gives ::

    M_sys   = sum T M T^T                                              (Eq. 31)
    C_c     = sum 2 T M T'^T + 2 w_L T M_s T^T                         (Eq. 34)
    K_c     = sum T M T''^T + 2 w_L T M_s T'^T - w_L^2 T M T^T + a_L T M_s T^T   (Eq. 35)
    R       = sum T M_r (g^L - u_r''^L)                                (Eq. 33, M_r)

With D1 = dT/dtheta_L and D2 = d^2T/dtheta_L^2: T' = w_L D1 and T'' = a_L D1 + w_L^2 D2.
At a crank angle theta the link rates are w_L = w g1_L and a_L = a g1_L + w^2 g2_L with
g1 = dtheta_L/dtheta, g2 = d^2theta_L/dtheta^2 (crank speed w, acceleration a), so ::

    C_c = w C1,          C1  = sum g1 (2 T M D1^T + 2 T M_s T^T)
    K_c = a Ka + w^2 Kw2, Ka = sum g1 (T M D1^T + T M_s T^T)
                          Kw2 = sum g2 (T M D1^T + T M_s T^T)
                                + g1^2 (T M D2^T + 2 T M_s D1^T - T M T^T)

and the rigid-body accelerations and quasi-static axial forces are linear in (g, a, w^2).
For a point mass on a ground-frame node these terms cancel exactly (no apparent forces in
the ground frame), as they must.

Geometric stiffness (A.4): the element matrix is ``integral F(x) v'^T v' dx`` with the axial
force F(x) of the rigid-body analysis (:func:`core.dynamics.axial_force`), integrated by
4-point Gauss (exact for the quadratic F of a uniform link); for constant F it is A.4.
"""

import dataclasses

import numpy as np

from ...names import OUTPUT_NAMES
from . import beam
from ..kinematics import solve_kinematics
from ..options import ModelOptions
from ..mechanism import JOINT_MEMBERS, JOINT_NAMES, LINK_NAMES

BEARING_MODELS = ('rigid', 'flexible')
# Gauss-Legendre points per element for the geometric stiffness: exact for F(x) v'^2 of degree 6.
GAUSS_POINTS = 4
# Output channels of :meth:`FlexibleLinkage.output_operator`, in order.
# Load and geometric-stiffness pieces: gravity, crank acceleration, crank speed squared.
PIECES = ('1', 'a', 'w2')
_GAUSS_X, _GAUSS_W = np.polynomial.legendre.leggauss(GAUSS_POINTS)


@dataclasses.dataclass(frozen=True)
class LinkMatrices:
    """
    Assembled matrices of one link in its moving frame (node i has DOFs 3i, 3i+1, 3i+2).

    Attributes
    ----------
    mass, mass_skew, mass_rigid, stiffness : ndarray, shape (3 (e + 1), 3 (e + 1))
        M^L (Eq. 19), M_s^L (Eq. 20), M_r^L (Eq. 17) including end point masses (A.8, A.9),
        and K^L (A.3).
    element_length : float
        Length of each of the e elements [m].
    elements : int
        Number of elements e.

    """

    mass: np.ndarray
    mass_skew: np.ndarray
    mass_rigid: np.ndarray
    stiffness: np.ndarray
    element_length: float
    elements: int

    @property
    def nodes(self):
        """Node positions along the link [m], shape (e + 1,)."""
        return self.element_length * np.arange(self.elements + 1)


def link_matrices(E, A, I, rho, length, elements, end_masses=(0.0, 0.0)):
    """
    Assemble the beam elements of one uniform link (Eqs. 17, 19, 20, A.3-A.9).

    Parameters
    ----------
    E, A, I, rho : float
        Young's modulus [Pa], area [m^2], second moment [m^4], density [kg/m^3].
    length : float
        Link length [m].
    elements : int
        Number of equal elements.
    end_masses : tuple of float
        Point masses [kg] at the first and last node (A.8, A.9).

    Returns
    -------
    LinkMatrices

    """
    if elements < 1:
        raise ValueError(f'`elements` must be >= 1, got {elements}')
    le = length / elements
    size = 3 * (elements + 1)
    out = {name: np.zeros((size, size)) for name in ('m', 'ms', 'mr', 'k')}
    element = {'m': beam.beam_mass(rho, A, le), 'ms': beam.beam_mass_skew(rho, A, le),
               'mr': beam.beam_mass_rigid(rho, A, le), 'k': beam.beam_stiffness(E, A, I, le)}
    for e in range(elements):
        block = slice(3 * e, 3 * e + 6)
        for name, matrix in element.items():
            out[name][block, block] += matrix
    last = 3 * elements
    for node, mass in ((0, end_masses[0]), (last, end_masses[1])):
        out['m'][node:node + 2, node:node + 2] += mass * np.eye(2)
        out['mr'][node:node + 2, node:node + 2] += mass * np.eye(2)
        out['ms'][node:node + 2, node:node + 2] += mass * beam.SKEW
    return LinkMatrices(mass=out['m'], mass_skew=out['ms'], mass_rigid=out['mr'],
                        stiffness=out['k'], element_length=le, elements=elements)


def gauss_points(element_length):
    """Gauss-Legendre abscissae [m] and weights [m] on one element, shape (GAUSS_POINTS,)."""
    return 0.5 * element_length * (_GAUSS_X + 1.0), 0.5 * element_length * _GAUSS_W


def transverse_slopes(x, length):
    """
    Slope v'(x) per element DOF of the Hermite interpolation (A.2), shape (n, 6).

    Parameters
    ----------
    x : ndarray, shape (n,)
        Positions along the element [m].
    length : float
        Element length [m].

    """
    xi = np.asarray(x, dtype=float) / length
    eta = 1.0 - xi
    out = np.zeros(xi.shape + (6,))
    out[..., 1] = -6.0 * xi * eta / length    # h2'
    out[..., 2] = eta ** 2 - 2.0 * xi * eta   # h3'
    out[..., 4] = 6.0 * xi * eta / length     # h5'
    out[..., 5] = xi ** 2 - 2.0 * xi * eta    # h6'
    return out


def element_geometric_stiffness(forces, length):
    """
    Geometric stiffness ``integral F(x) v'^T v' dx`` of one element (A.4 for constant F).

    Parameters
    ----------
    forces : ndarray, shape (..., GAUSS_POINTS)
        Axial force (tension > 0) [N] at :func:`gauss_points`.
    length : float
        Element length [m].

    Returns
    -------
    ndarray, shape (..., 6, 6)

    """
    x, w = gauss_points(length)
    slopes = transverse_slopes(x, length)
    return np.einsum('...g,g,gi,gj->...ij', forces, w, slopes, slopes)


def _sandwich(left_t, matrix, right_t):
    """
    T_left X T_right^T from gathers: sum over a, b of left_t[k, a, i] X[a, b] right_t[k, b, j].

    ``matrix`` is one (a, b) matrix for every angle k, or one per angle, shape (k, a, b).
    """
    if matrix.ndim == 3:
        return np.einsum('kai,kab,kbj->kij', left_t, matrix, right_t, optimize=True)
    return np.einsum('kai,ab,kbj->kij', left_t, matrix, right_t, optimize=True)


@dataclasses.dataclass(frozen=True)
class FrozenSystem:
    """
    Coefficient matrices of Eq. 30 at N crank angles, affine in (w, w^2, a).

    At crank speed w and acceleration a ::

        M U'' + (w C1 + C_d) U' + (K + K_G + a Ka + w^2 Kw2) U = R
        K_G = K_G['1'] + a K_G['a'] + w^2 K_G['w2'],  R = R['1'] + a R['a'] + w^2 R['w2']

    ('1' is the gravity part). C_d (modal damping) is built from the frozen modes
    (:mod:`core.modes`).

    Attributes
    ----------
    crank_angle : ndarray, shape (N,)
    mass, stiffness, gyroscopic : ndarray, shape (N, n, n)
        M (Eq. 31), K (Eq. 32: elastic, bearings, shaft), C1 (Eq. 34 per unit w).
    coupling : dict of str to ndarray, shape (N, n, n)
        'a': Ka, 'w2': Kw2 (Eq. 35).
    geometric : dict of str to ndarray, shape (N, n, n)
        K_G pieces '1', 'a', 'w2' (zero if geometric stiffness is off).
    load : dict of str to ndarray, shape (N, n)
        R pieces '1', 'a', 'w2' (Eq. 33).
    link_mass, link_stiffness : ndarray, shape (N, 3, n, n)
        Each link's share of M and of the elastic K (zero for a rigid crank), for energies.

    """

    crank_angle: np.ndarray
    mass: np.ndarray
    stiffness: np.ndarray
    gyroscopic: np.ndarray
    coupling: dict
    geometric: dict
    load: dict
    link_mass: np.ndarray
    link_stiffness: np.ndarray

    @property
    def size(self):
        """Number of DOFs n."""
        return self.mass.shape[-1]

    def __len__(self):
        return self.crank_angle.shape[0]

    def geometric_at(self, w, a=0.0):
        """K_G at speed ``w`` [rad/s] and acceleration ``a`` [rad/s^2], shape (N, n, n)."""
        g = self.geometric
        return g['1'] + a * g['a'] + w * w * g['w2']

    def load_at(self, w, a=0.0):
        """R at (w, a), shape (N, n)."""
        r = self.load
        return r['1'] + a * r['a'] + w * w * r['w2']

    def coupling_at(self, w, a=0.0):
        """K_c = a Ka + w^2 Kw2, shape (N, n, n)."""
        return a * self.coupling['a'] + w * w * self.coupling['w2']

    def frozen_stiffness(self, w, a=0.0, centrifugal=False):
        """
        Symmetric stiffness of the frozen eigenproblem, K + K_G(w, a), shape (N, n, n).

        With ``centrifugal`` the symmetric part of K_c(w, a) is added (in a link's own frame
        that is the centrifugal softening -w_L^2 M); the paper's eigenproblem omits it.
        """
        out = self.stiffness + self.geometric_at(w, a)
        if centrifugal:
            kc = self.coupling_at(w, a)
            out = out + 0.5 * (kc + np.swapaxes(kc, -1, -2))
        return out

    def evaluate(self, w, a=0.0):
        """
        M, C_c, K + K_G + K_c and R at (w, a), without modal damping.

        Returns
        -------
        mass, damping, stiffness : ndarray, shape (N, n, n)
        load : ndarray, shape (N, n)

        """
        stiffness = self.stiffness + self.geometric_at(w, a) + self.coupling_at(w, a)
        return self.mass, w * self.gyroscopic, stiffness, self.load_at(w, a)


class FlexibleLinkage:
    """
    DOF layout and assembly of the flexible four-bar (Cho, Park & Lee 1992, Secs. 2.2-2.3).

    Parameters
    ----------
    mechanism : Mechanism
        Needs material, sections and ``elements_per_link``; ``bearing_stiffness`` for
        flexible bearings.
    options : ModelOptions

    Attributes
    ----------
    links : tuple of int
        Modelled links (0 crank, 1 coupler, 2 lever).
    size : int
        Number of system DOFs n.
    dof_names : tuple of str
        Name of each DOF ('A.X', 'coupler.n1.v', 'B.lever.phi', ...).
    link_matrices : dict of int to LinkMatrices
    bearing_stiffness : ndarray, shape (n, n)
        Bearing springs (Eq. 23) and the shaft spring k_t.

    """

    def __init__(self, mechanism, options=None):
        options = ModelOptions.full_model() if options is None else options
        if options.bearings not in BEARING_MODELS:
            raise ValueError(f'`bearings` must be one of {BEARING_MODELS}, '
                             f'got {options.bearings!r}')
        if not mechanism.is_flexible:
            raise ValueError('`mechanism` lacks the material or section data of the FE model')
        if options.bearings == 'flexible' and not mechanism.bearing_stiffness:
            raise ValueError('flexible bearings need `bearing_stiffness` in the mechanism')
        if not options.gravity:
            mechanism = dataclasses.replace(mechanism, gravity=(0.0, 0.0))
        self.mechanism = mechanism
        self.options = options
        self.links = (1, 2) if options.rigid_crank else (0, 1, 2)
        self._number_dofs()
        self._build_link_matrices()

    # -- DOF layout -------------------------------------------------------------------------

    def _number_dofs(self):
        mech, opts = self.mechanism, self.options
        elements = mech.elements_per_link
        names = []

        def new(name):
            names.append(name)
            return len(names) - 1

        # local index -> global index (-1 = fixed); per link, node-major (u, v, phi)
        self._gather = {link: -np.ones(3 * (elements + 1), dtype=int) for link in self.links}
        self._end_nodes = {link: [] for link in self.links}   # (local u index, gx, gy)
        springs, self._end_mass = [], {link: [0.0, 0.0] for link in self.links}
        for joint in JOINT_NAMES:
            members = [m for m in JOINT_MEMBERS[joint] if m in self.links]
            grounded = -1 in JOINT_MEMBERS[joint] or (joint == 'A' and opts.rigid_crank)
            flexible = opts.bearings == 'flexible' and joint in mech.bearing_joints
            mass = mech.joint_masses.get(joint, 0.0)
            if flexible:
                pairs = [(new(f'{joint}.{LINK_NAMES[m]}.X'), new(f'{joint}.{LINK_NAMES[m]}.Y'))
                         for m in members]
                shares = dict(zip(JOINT_MEMBERS[joint],
                                  (mech.joint_mass_split, 1.0 - mech.joint_mass_split)))
                for m in members:
                    self._end_mass[m][self._end_index(m, joint)] += shares[m] * mass
                if grounded:
                    springs.extend((pair, None) for pair in pairs)
                elif len(pairs) == 2:
                    springs.append((pairs[0], pairs[1]))
            else:
                shared = None if grounded else (new(f'{joint}.X'), new(f'{joint}.Y'))
                pairs = [shared] * len(members)
                if members:
                    self._end_mass[members[0]][self._end_index(members[0], joint)] += mass
            for m, pair in zip(members, pairs):
                node = 0 if self._end_index(m, joint) == 0 else elements
                if pair is not None:
                    self._gather[m][3 * node:3 * node + 2] = pair
                    self._end_nodes[m].append((3 * node, pair[0], pair[1]))
                clamped = joint == 'O2' and m == 0 and mech.shaft_stiffness is None
                if not clamped:
                    self._gather[m][3 * node + 2] = new(f'{joint}.{LINK_NAMES[m]}.phi')
        for link in self.links:
            for node in range(1, elements):
                for c, comp in enumerate('uvp'):
                    label = {'u': 'u', 'v': 'v', 'p': 'phi'}[comp]
                    self._gather[link][3 * node + c] = new(f'{LINK_NAMES[link]}.n{node}.{label}')
        self.size = len(names)
        self.dof_names = tuple(names)
        k_bearing = np.zeros((self.size, self.size))
        k = mech.bearing_stiffness or 0.0
        for first, second in springs:
            for i in range(2):
                k_bearing[first[i], first[i]] += k
                if second is not None:
                    k_bearing[second[i], second[i]] += k
                    k_bearing[first[i], second[i]] -= k
                    k_bearing[second[i], first[i]] -= k
        if 0 in self.links and mech.shaft_stiffness is not None:
            phi = self._gather[0][2]
            k_bearing[phi, phi] += mech.shaft_stiffness
        self.bearing_stiffness = k_bearing

    @staticmethod
    def _end_index(link, joint):
        """0 if ``joint`` is the link's first joint, 1 if its second."""
        first = {0: 'O2', 1: 'A', 2: 'O4'}[link]
        return 0 if joint == first else 1

    def _build_link_matrices(self):
        mech = self.mechanism
        self.link_matrices = {}
        for link in self.links:
            spec = mech.links[link]
            self.link_matrices[link] = link_matrices(
                mech.youngs_modulus, spec.area, spec.second_moment, mech.density, spec.length,
                mech.elements_per_link, tuple(self._end_mass[link]))

    def end_masses(self, link):
        """Point masses [kg] at the first and last node of a modelled link (joint shares)."""
        return tuple(self._end_mass[link])

    def dof_index(self, name):
        """Index of the DOF called ``name`` (see ``dof_names``)."""
        return self.dof_names.index(name)

    # -- transformations --------------------------------------------------------------------

    def gather(self, link, link_angle, order=0):
        """
        T^T of a link (Eq. 25) or its derivative in theta_L, at N link angles.

        Parameters
        ----------
        link : int
        link_angle : ndarray, shape (N,)
            theta_L [rad].
        order : int
            0 for T^T, 1 for dT^T/dtheta_L, 2 for d^2T^T/dtheta_L^2.

        Returns
        -------
        ndarray, shape (N, 3 (e + 1), n)

        """
        angle = np.atleast_1d(np.asarray(link_angle, dtype=float))
        gather = self._gather[link]
        out = np.zeros((angle.shape[0], gather.shape[0], self.size))
        if order == 0:
            rows = np.flatnonzero(gather >= 0)
            out[:, rows, gather[rows]] = 1.0
        c, s = np.cos(angle), np.sin(angle)
        # u_local = R^T U_ground and its derivatives in theta (R^T = [[c, s], [-s, c]])
        block = {0: ((c, s), (-s, c)), 1: ((-s, c), (-c, -s)), 2: ((-c, -s), (s, -c))}[order]
        for row, gx, gy in self._end_nodes[link]:
            out[:, row, gx], out[:, row, gy] = block[0]
            out[:, row + 1, gx], out[:, row + 1, gy] = block[1]
        return out

    # -- assembly ---------------------------------------------------------------------------

    def kinematic_coefficients(self, crank_angle):
        """
        Link angles and the coefficients g1 = dtheta_L/dtheta, g2 = d^2theta_L/dtheta^2.

        Returns
        -------
        angle, g1, g2 : ndarray, shape (3, N)
        states : dict
            LinkageState per unit piece: 'w2' (speed 1, accel 0), 'a' (speed 0, accel 1).

        """
        theta = np.atleast_1d(np.asarray(crank_angle, dtype=float))
        unit_speed = solve_kinematics(self.mechanism, theta, 1.0, 0.0)
        unit_accel = solve_kinematics(self.mechanism, theta, 0.0, 1.0)
        return (unit_speed.angle, unit_speed.omega, unit_speed.alpha,
                {'w2': unit_speed, 'a': unit_accel})

    def assemble(self, crank_angle):
        """
        Frozen system at crank angles (Eqs. 31-35 and A.4), see :class:`FrozenSystem`.

        Parameters
        ----------
        crank_angle : float or ndarray, shape (N,)
            Crank angles [rad].

        Returns
        -------
        FrozenSystem

        """
        theta = np.atleast_1d(np.asarray(crank_angle, dtype=float))
        count, n = theta.shape[0], self.size
        angle, g1, g2, states = self.kinematic_coefficients(theta)
        zeros = lambda: np.zeros((count, n, n))  # noqa: E731
        mass, stiffness, gyro = zeros(), zeros(), zeros()
        coupling = {'a': zeros(), 'w2': zeros()}
        geometric = {piece: zeros() for piece in PIECES}
        load = {piece: np.zeros((count, n)) for piece in PIECES}
        link_mass = np.zeros((count, 3, n, n))
        link_stiffness = np.zeros((count, 3, n, n))
        forces = self._axial_forces(theta, states) if self.options.geometric_stiffness else None
        gravity = complex(*self.mechanism.gravity)
        for link in self.links:
            mats = self.link_matrices[link]
            t0 = self.gather(link, angle[link], 0)
            t1 = self.gather(link, angle[link], 1)
            t2 = self.gather(link, angle[link], 2)
            p1, p2 = g1[link][:, None, None], g2[link][:, None, None]
            m_tt = _sandwich(t0, mats.mass, t0)
            link_mass[:, link] = m_tt
            link_stiffness[:, link] = _sandwich(t0, mats.stiffness, t0)
            mass += m_tt
            stiffness += link_stiffness[:, link]
            transport = _sandwich(t0, mats.mass, t1) + _sandwich(t0, mats.mass_skew, t0)
            gyro += 2.0 * p1 * transport
            coupling['a'] += p1 * transport
            coupling['w2'] += p2 * transport + p1 ** 2 * (
                _sandwich(t0, mats.mass, t2) + 2.0 * _sandwich(t0, mats.mass_skew, t1) - m_tt)
            # Eq. 33: nodal gravity and rigid-body accelerations in the link frame, via M_r.
            rotate = np.exp(-1j * angle[link])[:, None]
            accel = {'1': np.broadcast_to(gravity * rotate, (count, mats.elements + 1))}
            for piece in ('a', 'w2'):
                accel[piece] = -np.stack([states[piece].point(link, x)[2] for x in mats.nodes],
                                         axis=1) * rotate
            for piece, values in accel.items():
                nodal = np.zeros((count, mats.elements + 1, 3))
                nodal[..., 0], nodal[..., 1] = values.real, values.imag
                local = nodal.reshape(count, -1) @ mats.mass_rigid.T
                load[piece] += np.einsum('kai,ka->ki', t0, local)
            if forces is not None:
                for piece in PIECES:
                    kg_local = self._link_geometric(link, forces[piece][link])
                    geometric[piece] += _sandwich(t0, kg_local, t0)
        stiffness += self.bearing_stiffness
        return FrozenSystem(crank_angle=theta, mass=mass, stiffness=stiffness, gyroscopic=gyro,
                            coupling=coupling, geometric=geometric, load=load,
                            link_mass=link_mass, link_stiffness=link_stiffness)

    def _link_geometric(self, link, forces):
        """Link K_G from axial forces at Gauss points, forces shape (N, e, GAUSS_POINTS)."""
        mats = self.link_matrices[link]
        element = element_geometric_stiffness(forces, mats.element_length)
        out = np.zeros((forces.shape[0], 3 * (mats.elements + 1), 3 * (mats.elements + 1)))
        for e in range(mats.elements):
            out[:, 3 * e:3 * e + 6, 3 * e:3 * e + 6] += element[:, e]
        return out

    def gauss_positions(self, link):
        """Gauss points of every element of a link [m], shape (e, GAUSS_POINTS)."""
        mats = self.link_matrices[link]
        x, _ = gauss_points(mats.element_length)
        return mats.nodes[:-1, None] + x[None, :]

    def _axial_forces(self, theta, states):
        """
        Axial forces at the Gauss points per piece: {piece: {link: (N, e, GAUSS_POINTS)}}.

        From the rigid-body analysis, linear in (gravity, a, w^2): '1' = gravity at rest,
        'a' and 'w2' = unit crank acceleration and unit speed squared without gravity.
        ``dynamics.axial_force(mechanism, state, link, x)`` is called with x of shape (m,)
        and must return the tension [N], shape (N, m) for the N angles of ``state``.
        """
        from ..dynamics import axial_force
        still = solve_kinematics(self.mechanism, theta, 0.0, 0.0)
        weightless = dataclasses.replace(self.mechanism, gravity=(0.0, 0.0))
        cases = {'1': (self.mechanism, still), 'a': (weightless, states['a']),
                 'w2': (weightless, states['w2'])}
        out = {}
        for piece, (mech, state) in cases.items():
            out[piece] = {}
            for link in self.links:
                x = self.gauss_positions(link)
                values = np.asarray(axial_force(mech, state, link, x.ravel()), dtype=float)
                out[piece][link] = values.reshape(theta.shape[0], *x.shape)
        return out

    # -- outputs ----------------------------------------------------------------------------

    def point_operator(self, link, x, crank_angle):
        """
        Ground-frame elastic deflection of the material point x of a link, per DOF.

        ``d = R(theta_L) H(x) u^L`` with ``u^L = T^T U`` (Eqs. 2, A.1, 25).

        Parameters
        ----------
        link : int
        x : float
            Position along the link [m], 0 <= x <= L.
        crank_angle : ndarray, shape (N,)

        Returns
        -------
        ndarray, shape (N, 2, n)
            Rows dX, dY; zero for a link that is not modelled (rigid crank).

        """
        theta = np.atleast_1d(np.asarray(crank_angle, dtype=float))
        if link not in self.links:
            return np.zeros((theta.shape[0], 2, self.size))
        angle = solve_kinematics(self.mechanism, theta).angle[link]
        return self._point_operator(link, np.atleast_1d(x), angle)[:, 0]

    def _point_operator(self, link, xs, link_angle):
        """(N, len(xs), 2, n) deflection operator of points xs on a modelled link."""
        mats = self.link_matrices[link]
        le = mats.element_length
        element = np.minimum((np.asarray(xs) / le).astype(int), mats.elements - 1)
        local = np.asarray(xs) - element * le
        t0 = self.gather(link, link_angle, 0)
        c, s = np.cos(link_angle), np.sin(link_angle)
        rot = np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)   # (N, 2, 2)
        out = np.empty((link_angle.shape[0], len(xs), 2, self.size))
        for p, (e, xe) in enumerate(zip(element, local)):
            h = beam.shape_functions(np.array([xe]), le)[0]               # (2, 6)
            rows = t0[:, 3 * e:3 * e + 6, :]                                # (N, 6, n)
            out[:, p] = np.einsum('kij,jl,kln->kin', rot, h, rows)
        return out

    def output_operator(self, crank_angle):
        """
        Lever tip (lever side of B) and coupler mid-point deflections, per DOF.

        Returns
        -------
        ndarray, shape (N, 4, n)
            Rows in :data:`OUTPUT_NAMES` order (ground frame, m per unit DOF).

        """
        lengths = self.mechanism.lengths
        tip = self.point_operator(2, lengths[3], crank_angle)
        mid = self.point_operator(1, 0.5 * lengths[2], crank_angle)
        return np.concatenate([tip, mid], axis=1)

    def shape_operator(self, crank_angle, points_per_element=8):
        """
        Rigid positions and deflection operators of points along every link (for drawing).

        Parameters
        ----------
        crank_angle : ndarray, shape (N,)
        points_per_element : int
            Equal divisions of each element (the paper draws 8).

        Returns
        -------
        positions : ndarray, shape (N, 3, P, 2)
            Ground-frame rigid positions [m], P = e * points_per_element + 1 per link.
        operator : ndarray, shape (N, 3, P, 2, n)
            Ground-frame deflection per DOF (zero for a rigid crank).

        """
        theta = np.atleast_1d(np.asarray(crank_angle, dtype=float))
        state = solve_kinematics(self.mechanism, theta)
        elements = self.mechanism.elements_per_link
        count = elements * points_per_element + 1
        positions = np.zeros((theta.shape[0], 3, count, 2))
        operator = np.zeros((theta.shape[0], 3, count, 2, self.size))
        for link in range(3):
            xs = np.linspace(0.0, self.mechanism.links[link].length, count)
            pos = np.stack([state.point(link, x)[0] for x in xs], axis=1)
            positions[:, link, :, 0], positions[:, link, :, 1] = pos.real, pos.imag
            if link in self.links:
                operator[:, link] = self._point_operator(link, xs, state.angle[link])
        return positions, operator

    def element_axial_forces(self, displacement, crank_angle):
        """
        Axial force EA (u2 - u1) / l_e of every element (tension > 0) for a system vector.

        Parameters
        ----------
        displacement : ndarray, shape (N, n)
        crank_angle : ndarray, shape (N,)

        Returns
        -------
        dict of int to ndarray, shape (N, e)

        """
        theta = np.atleast_1d(np.asarray(crank_angle, dtype=float))
        angle = solve_kinematics(self.mechanism, theta).angle
        out = {}
        for link in self.links:
            spec, mats = self.mechanism.links[link], self.link_matrices[link]
            local = np.einsum('kan,kn->ka', self.gather(link, angle[link]),
                              np.atleast_2d(displacement))
            axial = local[:, 0::3]
            out[link] = (self.mechanism.youngs_modulus * spec.area / mats.element_length
                         * np.diff(axial, axis=1))
        return out


__all__ = ['BEARING_MODELS', 'OUTPUT_NAMES', 'PIECES', 'ModelOptions', 'LinkMatrices',
           'link_matrices', 'gauss_points', 'transverse_slopes', 'element_geometric_stiffness',
           'FrozenSystem', 'FlexibleLinkage']
