"""
Second-order geometry of a bent link: chord shortening and loop closure.

Derivation. Take a link of length L in its nominal (rigid-body) frame, x along the nominal chord
from its first joint, with the linear FE deflections u(x) (axial) and v(x) (transverse) that
``u^L = T^T U`` gives (:meth:`core.fe.linkage.FlexibleLinkage.gather`: interior nodes in the link
frame, end-node translations rotated into it). With the material strain eps = u' + v'^2 / 2 of
a Bernoulli-Euler beam and the slope psi ~ v', the position of the material point x is, to
second order, ::

    r(x) - r(0) = (x + int_0^x eps ds - 1/2 int_0^x v'^2 ds) e + (v(x) - v(0)) n

(e, n the nominal unit vectors along and across the link). The linear model carries
``int eps = u(x) - u(0)``; what it lacks is the axial term ::

    S(x) = 1/2 int_0^x v'^2 ds,        S = S(L) = 1/2 u^T G u                          (1)

with G the geometric stiffness of the link's elements for unit tension (A.4, ``integral
v'^T v' dx``). S is measured in the NOMINAL frame: it includes the chord's own rotation
c = (v(L) - v(0)) / L, and splits into the chord shortening proper (the shape relative to the
chord, rigid rotation removed) and the rigid-rotation term of the linear kinematics ::

    S = delta + (v(L) - v(0))^2 / (2 L),   delta = 1/2 int (v' - c)^2 dx                  (2)

since int v' dx = v(L) - v(0). Both pieces matter for the loop closure: a linear solution
that rotates a chord by c leaves the chord too long by L c^2 / 2 (the linearised constraint),
so the second-order joint motion solves, with the nominal unit vectors, ::

    e_c . (dB - dA) = -S_c,   e_l . dB = -S_l,   dA = -S_k e_k (flexible crank, else 0)   (3)

(c coupler A->B, l lever O4->B, k crank O2->A). The simpler form ``[e_c; e_l] dB = -[delta_c;
delta_l]`` is (3) with the rotation term left out; with rigid bearings B's linear motion is
2-5 um, so the term is 1e-11 m there, but with bearing springs it is not negligible in
principle. test/core/fe/test_second_order_geometry.py checks (3) against the exact
intersection of two circles.
With bearing springs the frame is statically determinate (rigid crank pin, two bars), so the
second-order shortening changes no spring force and (3) holds with the members' end nodes.

The coupler's material point x then moves by ::

    dP(x) = dA - S_c(x) e_c + (x / L) (n_c . (dB - dA)) n_c                                  (4)

(the axial term of (1) and the rigid rotation that brings the chord to dB); x = L / 2 is the
published coupler mid-point. The lever tip is dB.
"""

import numpy as np

from . import beam
from .link import transverse_slopes
from ..kinematics import solve_kinematics

# Sums S of the second-order outputs, in order: crank, coupler, lever (S(L) each), and the
# coupler's S(L/2) for the mid-point.
FORMS = ('crank', 'coupler', 'lever', 'coupler_half')
# Gauss points for a partial element: v'^2 is a quartic, 3 points integrate it exactly.
_PARTIAL_GAUSS = 3


def unit_geometric_stiffness(element_length, elements, upto=None):
    """
    G = integral_0^upto v'^T v' dx of a chain of equal beam elements (A.4 for unit tension).

    Parameters
    ----------
    element_length : float
        Element length [m].
    elements : int
        Number of elements e (node i has DOFs 3i, 3i+1, 3i+2: u, v, phi).
    upto : float or None
        Upper limit x [m] (None: the whole link, e * element_length).

    Returns
    -------
    ndarray, shape (3 (e + 1), 3 (e + 1))
        Symmetric, positive semi-definite; ``1/2 u^T G u = 1/2 int_0^upto v'^2 dx``.

    """
    size = 3 * (elements + 1)
    out = np.zeros((size, size))
    full = beam.beam_geometric_stiffness(1.0, element_length)
    end = elements * element_length if upto is None else float(upto)
    if not 0.0 <= end <= elements * element_length * (1.0 + 1e-12):
        raise ValueError(f'`upto` must lie on the link, got {upto!r}')
    for e in range(elements):
        start = e * element_length
        block = slice(3 * e, 3 * e + 6)
        if end >= start + element_length * (1.0 - 1e-12):
            out[block, block] += full
        elif end > start:
            xg, wg = np.polynomial.legendre.leggauss(_PARTIAL_GAUSS)
            span = end - start
            x, w = 0.5 * span * (xg + 1.0), 0.5 * span * wg
            slopes = transverse_slopes(x, element_length)
            out[block, block] += np.einsum('g,gi,gj->ij', w, slopes, slopes)
    return out


def bending_integral(local, gmatrix):
    """
    Eq. (1): S = 1/2 int v'^2 dx = 1/2 u^T G u, the axial shortening of a link's end.

    S is measured relative to the link's first end in the nominal link frame (chord rotation
    included).

    Parameters
    ----------
    local : ndarray, shape (..., 3 (e + 1))
        Link-frame nodal vector u^L (u, v, phi per node).
    gmatrix : ndarray, shape (3 (e + 1), 3 (e + 1))
        From :func:`unit_geometric_stiffness`.

    Returns
    -------
    ndarray, shape (...)
        S [m], >= 0.

    """
    return 0.5 * np.einsum('...i,ij,...j->...', local, gmatrix, local)


def chord_shortening(local, gmatrix, length):
    """
    Eq. (2): the chord shortening delta of the bent link, its rigid rotation removed.

    ``delta = 1/2 int (v' - c)^2 dx = 1/2 u^T G u - (v(L) - v(0))^2 / (2 L)`` with the chord
    rotation ``c = (v(L) - v(0)) / L``.

    Parameters
    ----------
    local : ndarray, shape (..., 3 (e + 1))
        Link-frame nodal vector u^L.
    gmatrix : ndarray
        G of the whole link (:func:`unit_geometric_stiffness` without ``upto``).
    length : float
        Link length L [m].

    Returns
    -------
    ndarray, shape (...)
        delta [m] (equal to ``bending_integral`` of ``local`` minus its chord rotation).

    """
    chord = local[..., -2] - local[..., 1]
    return bending_integral(local, gmatrix) - chord ** 2 / (2.0 * length)


def loop_closure_second_order(e_coupler, e_lever, s_coupler, s_lever, d_a=0.0):
    """
    Eq. (3): joint B's second-order displacement dB from e_c . (dB - dA) = -S_c, e_l . dB = -S_l.

    Parameters
    ----------
    e_coupler, e_lever : complex ndarray, shape (N,)
        Nominal unit vectors A->B and O4->B (x + i y).
    s_coupler, s_lever : ndarray, shape (N, ...)
        Axial shortenings S of coupler and lever [m] (trailing axes broadcast).
    d_a : complex ndarray, shape (N, ...), or 0
        Second-order displacement of crank pin A [m] (0 for a rigid crank).

    Returns
    -------
    complex ndarray, shape (N, ...)
        dB [m], ground frame (x + i y).

    """
    ec, el = np.asarray(e_coupler), np.asarray(e_lever)
    extra = np.ndim(s_coupler) - 1
    ec, el = (v.reshape(v.shape + (1,) * extra) for v in (ec, el))
    rhs_c = -np.asarray(s_coupler) + (np.conj(ec) * d_a).real   # e_c . dA
    rhs_l = -np.asarray(s_lever)
    det = ec.real * el.imag - ec.imag * el.real              # e_c x e_l
    dx = (rhs_c * el.imag - rhs_l * ec.imag) / det
    dy = (ec.real * rhs_l - el.real * rhs_c) / det
    return dx + 1j * dy


def coupler_point_second_order(e_coupler, fraction, s_partial, d_b, d_a=0.0):
    """
    Eq. (4): dP = dA - S_c(x) e_c + (x / L) (n_c . (dB - dA)) n_c for the coupler point x.

    Parameters
    ----------
    e_coupler : complex ndarray, shape (N,)
        Nominal unit vector A->B.
    fraction : float
        x / L (1/2 for the mid-point).
    s_partial : ndarray, shape (N, ...)
        S_c(x) = 1/2 int_0^x v_c'^2 ds [m].
    d_b, d_a : complex ndarray, shape (N, ...), or 0 for d_a
        Second-order displacements of B and A [m].

    Returns
    -------
    complex ndarray, shape (N, ...)

    """
    ec = np.asarray(e_coupler)
    ec = ec.reshape(ec.shape + (1,) * (np.ndim(s_partial) - 1))
    nc = 1j * ec
    across = (np.conj(nc) * (d_b - d_a)).real
    return d_a - s_partial * ec + fraction * across * nc


def output_coefficients(mechanism, crank_angle):
    """
    kappa(theta): second-order outputs = kappa @ [S_crank, S_coupler, S_lever, S_coupler(L/2)].

    Eqs. (3)-(4) are linear in the four sums S, with coefficients that depend on the crank angle
    only; the column of S_j is the output for S_j = 1, the others 0.

    Returns
    -------
    ndarray, shape (N, 4, 4)
        Rows :data:`OUTPUT_NAMES`, columns :data:`FORMS`.

    """
    theta = np.atleast_1d(np.asarray(crank_angle, dtype=float))
    angle = solve_kinematics(mechanism, theta).angle
    unit = np.exp(1j * angle)                                  # e_k, e_c, e_l
    eye = np.eye(len(FORMS))[None, :, :] * np.ones((theta.shape[0], 1, 1))
    d_a = -eye[:, 0] * unit[0][:, None]                        # Eq. (3): dA = -S_k e_k
    d_b = loop_closure_second_order(unit[1], unit[2], eye[:, 1], eye[:, 2], d_a)
    d_p = coupler_point_second_order(unit[1], 0.5, eye[:, 3], d_b, d_a)
    return np.stack([d_b.real, d_b.imag, d_p.real, d_p.imag], axis=1)
