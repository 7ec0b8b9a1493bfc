"""
Ground-frame deflections of material points of the flexible four-bar, per system DOF.

The elastic deflection of the material point x of a link is ``d = R(theta_L) H(x) u^L`` with
``u^L = T^T U`` (Cho, Park & Lee 1992, Eqs. 2, A.1, 25): linear in the system vector U. The
operators here give it per DOF for the published outputs (lever tip, coupler mid-point), for
any point and for drawing whole links; :func:`element_axial_forces` gives the element forces
of a system vector. Each takes a :class:`core.fe.linkage.FlexibleLinkage`.
"""

import numpy as np

from . import beam
from ..kinematics import solve_kinematics


def points_operator(linkage, link, xs, link_angle):
    """
    Deflection operator of points on a modelled link.

    Parameters
    ----------
    linkage : FlexibleLinkage
        The model (its link matrices and gathers).
    link : int
        A modelled link.
    xs : sequence of float
        Positions along the link [m].
    link_angle : ndarray, shape (N,)
        theta_L [rad].

    Returns
    -------
    ndarray, shape (N, len(xs), 2, n)

    """
    mats = linkage.link_matrices[link]
    le = mats.element_length
    element = np.minimum((np.asarray(xs) / le).astype(int), mats.elements - 1)
    local = np.asarray(xs) - element * le
    t0 = linkage.gather(link, link_angle, 0)
    c, s = np.cos(link_angle), np.sin(link_angle)
    rot = np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)   # (N, 2, 2)
    out = np.empty((link_angle.shape[0], len(xs), 2, linkage.size))
    for p, (e, xe) in enumerate(zip(element, local)):
        h = beam.shape_functions(np.array([xe]), le)[0]               # (2, 6)
        rows = t0[:, 3 * e:3 * e + 6, :]                                # (N, 6, n)
        out[:, p] = np.einsum('kij,jl,kln->kin', rot, h, rows)
    return out


def point_operator(linkage, link, x, crank_angle):
    """
    Ground-frame elastic deflection of the material point x of a link, per DOF.

    ``d = R(theta_L) H(x) u^L`` with ``u^L = T^T U`` (Eqs. 2, A.1, 25).

    Parameters
    ----------
    linkage : FlexibleLinkage
        The model (its mechanism, links and gathers).
    link : int
        Link index (0 crank, 1 coupler, 2 lever).
    x : float
        Position along the link [m], 0 <= x <= L.
    crank_angle : ndarray, shape (N,)
        Crank angles [rad].

    Returns
    -------
    ndarray, shape (N, 2, n)
        Rows dX, dY; zero for a link that is not modelled (rigid crank).

    """
    theta = np.atleast_1d(np.asarray(crank_angle, dtype=float))
    if link not in linkage.links:
        return np.zeros((theta.shape[0], 2, linkage.size))
    angle = solve_kinematics(linkage.mechanism, theta).angle[link]
    return points_operator(linkage, link, np.atleast_1d(x), angle)[:, 0]


def output_operator(linkage, crank_angle):
    """
    Lever tip (lever side of B) and coupler mid-point deflections, per DOF.

    Parameters
    ----------
    linkage : FlexibleLinkage
        The model.
    crank_angle : ndarray, shape (N,)
        Crank angles [rad].

    Returns
    -------
    ndarray, shape (N, 4, n)
        Rows in :data:`names.OUTPUT_NAMES` order (ground frame, m per unit DOF).

    """
    lengths = linkage.mechanism.lengths
    tip = point_operator(linkage, 2, lengths[3], crank_angle)
    mid = point_operator(linkage, 1, 0.5 * lengths[2], crank_angle)
    return np.concatenate([tip, mid], axis=1)


def shape_operator(linkage, crank_angle, points_per_element=8):
    """
    Rigid positions and deflection operators of points along every link (for drawing).

    Parameters
    ----------
    linkage : FlexibleLinkage
        The model.
    crank_angle : ndarray, shape (N,)
        Crank angles [rad].
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
    mechanism = linkage.mechanism
    state = solve_kinematics(mechanism, theta)
    count = mechanism.elements_per_link * points_per_element + 1
    positions = np.zeros((theta.shape[0], 3, count, 2))
    operator = np.zeros((theta.shape[0], 3, count, 2, linkage.size))
    for link in range(3):
        xs = np.linspace(0.0, mechanism.links[link].length, count)
        pos = np.stack([state.point(link, x)[0] for x in xs], axis=1)
        positions[:, link, :, 0], positions[:, link, :, 1] = pos.real, pos.imag
        if link in linkage.links:
            operator[:, link] = points_operator(linkage, link, xs, state.angle[link])
    return positions, operator


def element_axial_forces(linkage, displacement, crank_angle):
    """
    Axial force EA (u2 - u1) / l_e of every element (tension > 0) for a system vector.

    Parameters
    ----------
    linkage : FlexibleLinkage
        The model.
    displacement : ndarray, shape (N, n)
        System vectors U.
    crank_angle : ndarray, shape (N,)
        Crank angles [rad].

    Returns
    -------
    dict of int to ndarray, shape (N, e)

    """
    theta = np.atleast_1d(np.asarray(crank_angle, dtype=float))
    mechanism = linkage.mechanism
    angle = solve_kinematics(mechanism, theta).angle
    out = {}
    for link in linkage.links:
        spec, mats = mechanism.links[link], linkage.link_matrices[link]
        local = np.einsum('kan,kn->ka', linkage.gather(link, angle[link]),
                          np.atleast_2d(displacement))
        axial = local[:, 0::3]
        out[link] = (mechanism.youngs_modulus * spec.area / mats.element_length
                     * np.diff(axial, axis=1))
    return out
