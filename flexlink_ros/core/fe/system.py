"""
System equation of the flexible four-bar (Cho, Park & Lee 1992, Eqs. 30-35 and A.4).

Derivation of the system terms. The link equation (Eq. 22, print typos corrected: Eq. 18's M_a
is M_s, right side M_r (g - u_r'') + F_c) is ::

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

One function per equation gives one link's share at N crank angles from its gathers
(t0 = T^T, t1 = D1^T, t2 = D2^T, each (N, 3 (e + 1), n)) and its :class:`LinkMatrices`;
:meth:`core.fe.linkage.FlexibleLinkage.assemble` sums the shares over the links.
"""

import dataclasses

import numpy as np

from .link import link_geometric_stiffness

# Load and geometric-stiffness pieces: gravity, crank acceleration, crank speed squared.
PIECES = ('1', 'a', 'w2')


@dataclasses.dataclass(frozen=True)
class FrozenSystem:
    """
    Coefficient matrices of Eq. 30 at N crank angles, affine in (w, w^2, a).

    At crank speed w and acceleration a ::

        M U'' + (w C1 + C_d) U' + (K + K_G + a Ka + w^2 Kw2) U = R
        K_G = K_G['1'] + a K_G['a'] + w^2 K_G['w2'],  R = R['1'] + a R['a'] + w^2 R['w2']

    ('1' is the gravity part). C_d (modal damping) is built from the frozen modes
    (:mod:`core.fe.modes`).

    Attributes
    ----------
    crank_angle : ndarray, shape (N,)
        Crank angles [rad].
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
        """Return the number of DOFs n."""
        return self.mass.shape[-1]

    def __len__(self):
        """Return the number of crank angles N."""
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


def sandwich(left_t, matrix, right_t):
    """
    T_left X T_right^T from gathers: sum over a, b of left_t[k, a, i] X[a, b] right_t[k, b, j].

    ``matrix`` is one (a, b) matrix for every angle k, or one per angle, shape (k, a, b).
    """
    if matrix.ndim == 3:
        return np.einsum('kai,kab,kbj->kij', left_t, matrix, right_t, optimize=True)
    return np.einsum('kai,ab,kbj->kij', left_t, matrix, right_t, optimize=True)


def system_mass(t0, matrices):
    """One link's share T M T^T of the system mass matrix (Eq. 31), shape (N, n, n)."""
    return sandwich(t0, matrices.mass, t0)


def system_stiffness(t0, matrices):
    """One link's elastic share T K T^T of the system stiffness (Eq. 32), shape (N, n, n)."""
    return sandwich(t0, matrices.stiffness, t0)


def transport_matrix(t0, t1, matrices):
    """T M D1^T + T M_s T^T of one link: the factor Eqs. 34 and 35 share, shape (N, n, n)."""
    return sandwich(t0, matrices.mass, t1) + sandwich(t0, matrices.mass_skew, t0)


def convective_damping(p1, transport):
    """
    One link's share of C1 = C_c / w (Eq. 34): 2 g1 (T M D1^T + T M_s T^T).

    Parameters
    ----------
    p1 : ndarray, shape (N, 1, 1)
        g1 = dtheta_L/dtheta of the link.
    transport : ndarray, shape (N, n, n)
        From :func:`transport_matrix`.

    Returns
    -------
    ndarray, shape (N, n, n)

    """
    return 2.0 * p1 * transport


def convective_stiffness(t0, t1, t2, matrices, p1, p2, transport, mass):
    """
    One link's share of K_c = a Ka + w^2 Kw2 (Eq. 35, a_L read as alpha_L).

    Ka = g1 (T M D1^T + T M_s T^T) and
    Kw2 = g2 (T M D1^T + T M_s T^T) + g1^2 (T M D2^T + 2 T M_s D1^T - T M T^T).

    Parameters
    ----------
    t0, t1, t2 : ndarray, shape (N, 3 (e + 1), n)
        The link's gather T^T and its first and second derivatives in theta_L.
    matrices : LinkMatrices
        The link's matrices (M and M_s are read).
    p1, p2 : ndarray, shape (N, 1, 1)
        g1 = dtheta_L/dtheta and g2 = d^2theta_L/dtheta^2.
    transport : ndarray, shape (N, n, n)
        From :func:`transport_matrix`.
    mass : ndarray, shape (N, n, n)
        The link's T M T^T (:func:`system_mass`).

    Returns
    -------
    dict of str to ndarray, shape (N, n, n)
        'a': Ka, 'w2': Kw2.

    """
    rotation = (sandwich(t0, matrices.mass, t2) + 2.0 * sandwich(t0, matrices.mass_skew, t1)
                - mass)
    return {'a': p1 * transport, 'w2': p2 * transport + p1 ** 2 * rotation}


def system_load(t0, matrices, link_angle, gravity, accelerations):
    """
    One link's share of R (Eq. 33 with M_r): T M_r (g^L - u_r''^L), per piece.

    Parameters
    ----------
    t0 : ndarray, shape (N, 3 (e + 1), n)
        The link's gather T^T.
    matrices : LinkMatrices
        The link's matrices (M_r and the node count are read).
    link_angle : ndarray, shape (N,)
        theta_L [rad].
    gravity : complex
        Gravity (x + i y) [m/s^2] in the ground frame.
    accelerations : dict of str to complex ndarray, shape (N, e + 1)
        Ground-frame rigid-body accelerations of the nodes for the pieces 'a' (unit crank
        acceleration) and 'w2' (unit crank speed squared) [m/s^2].

    Returns
    -------
    dict of str to ndarray, shape (N, n)
        Pieces '1' (gravity), 'a', 'w2'.

    """
    count = t0.shape[0]
    rotate = np.exp(-1j * link_angle)[:, None]
    accel = {'1': np.broadcast_to(gravity * rotate, (count, matrices.elements + 1))}
    for piece in ('a', 'w2'):
        accel[piece] = -accelerations[piece] * rotate
    out = {}
    for piece, values in accel.items():
        nodal = np.zeros((count, matrices.elements + 1, 3))
        nodal[..., 0], nodal[..., 1] = values.real, values.imag
        local = nodal.reshape(count, -1) @ matrices.mass_rigid.T
        out[piece] = np.einsum('kai,ka->ki', t0, local)
    return out


def geometric_stiffness(t0, matrices, forces):
    """
    One link's share T K_G^L T^T of the geometric stiffness (A.4), per piece.

    Parameters
    ----------
    t0 : ndarray, shape (N, 3 (e + 1), n)
        The link's gather T^T.
    matrices : LinkMatrices
        The link's matrices (element length and count are read).
    forces : dict of str to ndarray, shape (N, e, GAUSS_POINTS)
        Axial force (tension > 0) [N] at the link's Gauss points per piece '1', 'a', 'w2'.

    Returns
    -------
    dict of str to ndarray, shape (N, n, n)

    """
    return {piece: sandwich(t0, link_geometric_stiffness(matrices, forces[piece]), t0)
            for piece in PIECES}
