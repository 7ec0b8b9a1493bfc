"""
One link of the FE model of Cho, Park & Lee (1992): its matrices in its moving frame.

A modelled link is a chain of equal beam elements (:mod:`core.fe.beam`), node i with DOFs
(u, v, phi) at 3i, 3i+1, 3i+2. This module assembles the link's mass, skew mass, rigid-body
mass and stiffness (Eqs. 17, 19, 20, A.3-A.9) and its geometric stiffness from the axial force
at Gauss points (A.4).
"""

import dataclasses

import numpy as np

from . import beam

# Gauss-Legendre points per element for the geometric stiffness: exact for F(x) v'^2 of degree 6.
GAUSS_POINTS = 4
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


def link_matrices(E, A, second_moment, rho, length, elements, end_masses=(0.0, 0.0)):
    """
    Assemble the beam elements of one uniform link (Eqs. 17, 19, 20, A.3-A.9).

    Parameters
    ----------
    E, A, second_moment, rho : float
        Young's modulus [Pa], area [m^2], second moment of area I [m^4], density [kg/m^3].
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
               'mr': beam.beam_mass_rigid(rho, A, le),
               'k': beam.beam_stiffness(E, A, second_moment, le)}
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


def gauss_positions(matrices):
    """Gauss points of every element of a link [m], shape (e, GAUSS_POINTS)."""
    x, _ = gauss_points(matrices.element_length)
    return matrices.nodes[:-1, None] + x[None, :]


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


def link_geometric_stiffness(matrices, forces):
    """
    Link-frame geometric stiffness K_G^L (A.4) of a link from its axial forces.

    Parameters
    ----------
    matrices : LinkMatrices
        The link (element length and count).
    forces : ndarray, shape (N, e, GAUSS_POINTS)
        Axial force (tension > 0) [N] at the Gauss points of every element, N angles.

    Returns
    -------
    ndarray, shape (N, 3 (e + 1), 3 (e + 1))

    """
    element = element_geometric_stiffness(forces, matrices.element_length)
    size = 3 * (matrices.elements + 1)
    out = np.zeros((forces.shape[0], size, size))
    for e in range(matrices.elements):
        out[:, 3 * e:3 * e + 6, 3 * e:3 * e + 6] += element[:, e]
    return out
