"""
Planar two-node beam element of Cho, Park & Lee (1992), Appendix A.1-A.10.

Element DOF order (per node: axial u, transverse v, rotation phi, in the link's moving frame)::

    q = [u1, v1, phi1, u2, v2, phi2]

with x from node 1 (x = 0) to node 2 (x = L). Departures from the print (papers.md):
A.1 uses h2, not h1, for v1 (A.2 defines h2 and never uses it otherwise); A.9's node-1 block is
[[0, -m1], [m1, 0]] (skew-symmetric, as the integral of H^T I_s H of a point mass gives), and
its "m^2" is m2. A.3-A.7 are as printed. Every matrix here equals the integral stated in its
docstring (checked by quadrature of :func:`shape_functions` in test/core/fe/test_beam.py).
"""

import numpy as np

# Rotation by +90 degrees, [I_s] of Eq. 21.
SKEW = np.array([[0.0, -1.0], [1.0, 0.0]])


def shape_functions(x, length):
    """
    Displacement interpolation [H] of Eq. A.1 (corrected) with the functions of Eq. A.2.

    Parameters
    ----------
    x : ndarray, shape (n,)
        Positions along the element [m], 0 <= x <= L.
    length : float
        Element length L [m].

    Returns
    -------
    ndarray, shape (n, 2, 6)
        Rows (u_x, u_y) of the displacement at x per element DOF.

    """
    x = np.atleast_1d(np.asarray(x, dtype=float))
    xi = x / length
    eta = 1.0 - xi
    h = np.zeros((x.shape[0], 2, 6))
    h[:, 0, 0] = eta                                  # h1
    h[:, 0, 3] = xi                                   # h4
    h[:, 1, 1] = 3.0 * eta ** 2 - 2.0 * eta ** 3      # h2 (the print has h1 here)
    h[:, 1, 2] = x * eta ** 2                         # h3
    h[:, 1, 4] = 3.0 * xi ** 2 - 2.0 * xi ** 3        # h5
    h[:, 1, 5] = -(length - x) * xi ** 2              # h6
    return h


def rigid_shape_functions(x, length):
    """
    Interpolation [H_r] of nodal rigid-body accelerations, Eq. A.10.

    Returns
    -------
    ndarray, shape (n, 2, 6)

    """
    x = np.atleast_1d(np.asarray(x, dtype=float))
    xi = x / length
    h = np.zeros((x.shape[0], 2, 6))
    h[:, 0, 0] = h[:, 1, 1] = 1.0 - xi
    h[:, 0, 3] = h[:, 1, 4] = xi
    return h


def beam_stiffness(E, A, second_moment, length):
    """
    Elastic stiffness [K^m], Eq. A.3 (axial bar plus Euler-Bernoulli bending).

    Parameters
    ----------
    E, A, second_moment : float
        Young's modulus [Pa], area [m^2] and second moment of area I [m^4].
    length : float
        Element length [m].

    Returns
    -------
    ndarray, shape (6, 6)

    """
    L = length
    axial = E * A / L
    k = E * second_moment / L ** 3
    return np.array([
        [axial, 0.0, 0.0, -axial, 0.0, 0.0],
        [0.0, 12 * k, 6 * L * k, 0.0, -12 * k, 6 * L * k],
        [0.0, 6 * L * k, 4 * L ** 2 * k, 0.0, -6 * L * k, 2 * L ** 2 * k],
        [-axial, 0.0, 0.0, axial, 0.0, 0.0],
        [0.0, -12 * k, -6 * L * k, 0.0, 12 * k, -6 * L * k],
        [0.0, 6 * L * k, 2 * L ** 2 * k, 0.0, -6 * L * k, 4 * L ** 2 * k],
    ])


def beam_geometric_stiffness(axial_force, length):
    """
    Geometric stiffness [K_c^m] of an element under axial force F (tension > 0), Eq. A.4.

    Equals F * integral of v' v' over the element (cubic transverse interpolation).

    Returns
    -------
    ndarray, shape (6, 6)

    """
    L = length
    return axial_force / L * np.array([
        [0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        [0.0, 6 / 5, L / 10, 0.0, -6 / 5, L / 10],
        [0.0, L / 10, 2 * L ** 2 / 15, 0.0, -L / 10, -L ** 2 / 30],
        [0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        [0.0, -6 / 5, -L / 10, 0.0, 6 / 5, -L / 10],
        [0.0, L / 10, -L ** 2 / 30, 0.0, -L / 10, 2 * L ** 2 / 15],
    ])


def beam_mass(rho, A, length):
    """
    Consistent mass [M^m] = integral of rho H^T H dv, Eq. A.6 (Eq. 19 per element).

    Returns
    -------
    ndarray, shape (6, 6)

    """
    L = length
    return rho * A * L * np.array([
        [1 / 3, 0.0, 0.0, 1 / 6, 0.0, 0.0],
        [0.0, 13 / 35, 11 * L / 210, 0.0, 9 / 70, -13 * L / 420],
        [0.0, 11 * L / 210, L ** 2 / 105, 0.0, 13 * L / 420, -L ** 2 / 140],
        [1 / 6, 0.0, 0.0, 1 / 3, 0.0, 0.0],
        [0.0, 9 / 70, 13 * L / 420, 0.0, 13 / 35, -11 * L / 210],
        [0.0, -13 * L / 420, -L ** 2 / 140, 0.0, -11 * L / 210, L ** 2 / 105],
    ])


def beam_mass_skew(rho, A, length):
    """
    Skew mass [M_s^m] = integral of rho H^T I_s H dv, Eq. A.7 (Eq. 20 per element).

    Multiplies 2 omega (Coriolis) and alpha (tangential) in Eq. 22.

    Returns
    -------
    ndarray, shape (6, 6), antisymmetric

    """
    L = length
    return rho * A * L * np.array([
        [0.0, -7 / 20, -L / 20, 0.0, -3 / 20, L / 30],
        [7 / 20, 0.0, 0.0, 3 / 20, 0.0, 0.0],
        [L / 20, 0.0, 0.0, L / 30, 0.0, 0.0],
        [0.0, -3 / 20, -L / 30, 0.0, -7 / 20, L / 20],
        [3 / 20, 0.0, 0.0, 7 / 20, 0.0, 0.0],
        [-L / 30, 0.0, 0.0, -L / 20, 0.0, 0.0],
    ])


def beam_mass_rigid(rho, A, length):
    """
    Rigid-load mass [M_r^m] = integral of rho H^T H_r dv, Eq. A.5 (Eq. 17 per element).

    Maps nodal rigid-body (or gravity) accelerations, in the u/v slots, to nodal loads.

    Returns
    -------
    ndarray, shape (6, 6); columns 2 and 5 (rotations) are zero

    """
    L = length
    return rho * A * L * np.array([
        [1 / 3, 0.0, 0.0, 1 / 6, 0.0, 0.0],
        [0.0, 7 / 20, 0.0, 0.0, 3 / 20, 0.0],
        [0.0, L / 20, 0.0, 0.0, L / 30, 0.0],
        [1 / 6, 0.0, 0.0, 1 / 3, 0.0, 0.0],
        [0.0, 3 / 20, 0.0, 0.0, 7 / 20, 0.0],
        [0.0, -L / 30, 0.0, 0.0, -L / 20, 0.0],
    ])


def lumped_mass(m1, m2):
    """
    Point masses at the element's ends, [M^m]_c = [M_r^m]_c of Eq. A.8.

    Returns
    -------
    ndarray, shape (6, 6)

    """
    return np.diag([m1, m1, 0.0, m2, m2, 0.0])


def lumped_mass_skew(m1, m2):
    """
    Skew mass of end point masses, [M_s^m]_c of Eq. A.9 (node-1 block corrected).

    Returns
    -------
    ndarray, shape (6, 6), antisymmetric

    """
    out = np.zeros((6, 6))
    out[0, 1], out[1, 0] = -m1, m1
    out[3, 4], out[4, 3] = -m2, m2
    return out


def bearing_stiffness(k):
    """
    Isotropic revolute-bearing spring between two coincident nodes, Eq. 23 (entry (5,5) +k).

    DOF order: (X1, Y1, phi1, X2, Y2, phi2) in the ground frame; rotations are free.

    Returns
    -------
    ndarray, shape (6, 6)

    """
    block = np.diag([k, k, 0.0])
    return np.block([[block, -block], [-block, block]])
