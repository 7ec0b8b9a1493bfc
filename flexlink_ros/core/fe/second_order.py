"""
Second-order (quasi-static) motion of the flexible four-bar from its linear KED state (issue 14).

The linear kineto-elastodynamic model of Cho, Park & Lee (1992) (:mod:`core.assembly`,
:mod:`core.simulate`) keeps each link's axial and transverse deflections to first order. A bent
link is also shorter along its chord, by an amount quadratic in its bending; with rigid bearings
joint B moves mainly by that shortening of the coupler and the lever (the linear lever tip is
89-100 % low against a geometrically exact peer, :mod:`studies.peer_exudyn`). This module adds
that motion, computed from the linear state, without any further dynamics (the inertia of the
second-order motion and the axial eigenstrain it causes are left out: issue 14, item 2).

Derivation. Take a link of length L in its nominal (rigid-body) frame, x along the nominal chord
from its first joint, with the linear FE deflections u(x) (axial) and v(x) (transverse) that
``u^L = T^T U`` gives (:meth:`core.assembly.FlexibleLinkage.gather`: interior nodes in the link
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

(c coupler A->B, l lever O4->B, k crank O2->A). The issue's form ``[e_c; e_l] dB = -[delta_c;
delta_l]`` is (3) with the rotation term left out; with rigid bearings B's linear motion is
2-5 um, so the term is 1e-11 m there, but with bearing springs it is not negligible in
principle. test/test_second_order.py checks (3) against the exact intersection of two circles.
With bearing springs the frame is statically determinate (rigid crank pin, two bars), so the
second-order shortening changes no spring force and (3) holds with the members' end nodes.

The coupler's material point x then moves by ::

    dP(x) = dA - S_c(x) e_c + (x / L) (n_c . (dB - dA)) n_c                                  (4)

(the axial term of (1) and the rigid rotation that brings the chord to dB); x = L / 2 is the
published coupler mid-point. The lever tip is dB.

Reduced basis (the estimator). With a constant basis V (U = V q, :mod:`core.reduced`) only the
end-node translation rows of T^T rotate with the link angle theta_L, ``T^T = T0 + cos T_c +
sin T_s``, so ``S = q^T A(theta_L) q`` with ``A = A0 + cos A1 + sin A2 + cos 2 A3 + sin 2 A4``
(five constant r x r matrices per link, :func:`harmonic_matrices`), and every output is
``sum_j kappa_j(theta) S_j`` with the scalar coefficients of (3)-(4)
(:func:`output_coefficients`). The cheapest streaming form is factored: the link's transverse
DOFs ``z = Z(theta_L) q`` (2 e + 4 rows of V per link: interior v and phi, end X, Y and phi),
then ``S = 1/2 z^T G_v z`` with the banded G (:func:`step_cost`).
"""

import dataclasses

import numpy as np

from ...names import OUTPUT_NAMES
from . import beam
from .link import transverse_slopes
from ..kinematics import solve_kinematics

# Sums S of :func:`link_bending_integrals`, in order: crank, coupler, lever (S(L) each), and the
# coupler's S(L/2) for the mid-point.
FORMS = ('crank', 'coupler', 'lever', 'coupler_half')
# Output channels (as core.assembly.OUTPUT_NAMES).
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
    Eq. (1): S = 1/2 int v'^2 dx = 1/2 u^T G u, the axial shortening of a link's end relative to
    its first end in the nominal link frame (chord rotation included).

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
    Eq. (2): delta = 1/2 int (v' - c)^2 dx = 1/2 u^T G u - (v(L) - v(0))^2 / (2 L), c = (v(L) -
    v(0)) / L: the chord shortening of the bent link, its rigid rotation removed.

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


# ---------------------------------------------------------------------------------------
# Full order: from the nodal vector U of core.assembly / core.simulate


@dataclasses.dataclass(frozen=True)
class LinkForms:
    """
    Per-link G matrices of a :class:`core.assembly.FlexibleLinkage`.

    Attributes
    ----------
    full : dict of int to ndarray
        G over the whole link, per modelled link.
    coupler_half : ndarray
        G over [0, L/2] of the coupler.
    lengths : dict of int to float
        Link lengths [m].

    """

    full: dict
    coupler_half: np.ndarray
    lengths: dict


def link_forms(linkage):
    """G of every modelled link and the coupler's half (:func:`unit_geometric_stiffness`)."""
    full, lengths = {}, {}
    for link in linkage.links:
        mats = linkage.link_matrices[link]
        full[link] = unit_geometric_stiffness(mats.element_length, mats.elements)
        lengths[link] = linkage.mechanism.links[link].length
    mats = linkage.link_matrices[1]
    half = unit_geometric_stiffness(mats.element_length, mats.elements, 0.5 * lengths[1])
    return LinkForms(full=full, coupler_half=half, lengths=lengths)


def link_local(linkage, displacement, crank_angle):
    """
    Link-frame nodal vectors u^L = T^T U of every modelled link.

    Parameters
    ----------
    linkage : FlexibleLinkage
    displacement : ndarray, shape (N, n)
        System vectors U (e.g. ``PeriodicResponse.displacement``).
    crank_angle : ndarray, shape (N,)

    Returns
    -------
    dict of int to ndarray, shape (N, 3 (e + 1))

    """
    theta = np.atleast_1d(np.asarray(crank_angle, dtype=float))
    angle = solve_kinematics(linkage.mechanism, theta).angle
    u = np.atleast_2d(displacement)
    return {link: np.einsum('kan,kn->ka', linkage.gather(link, angle[link]), u)
            for link in linkage.links}


def bending_sums(linkage, displacement, crank_angle, forms=None):
    """
    S of every form in :data:`FORMS` (zero for a rigid crank) and delta of every link.

    Returns
    -------
    sums : ndarray, shape (N, 4)
        S_crank, S_coupler, S_lever, S_coupler(L/2) [m] (Eq. 1).
    chord : ndarray, shape (N, 3)
        delta per link (Eq. 2; zero for a rigid crank) [m].

    """
    forms = forms or link_forms(linkage)
    local = link_local(linkage, displacement, crank_angle)
    count = next(iter(local.values())).shape[0]
    sums, chord = np.zeros((count, len(FORMS))), np.zeros((count, 3))
    for link, values in local.items():
        sums[:, link] = bending_integral(values, forms.full[link])
        chord[:, link] = chord_shortening(values, forms.full[link], forms.lengths[link])
    sums[:, 3] = bending_integral(local[1], forms.coupler_half)
    return sums, chord


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


def second_order_outputs(linkage, displacement, crank_angle, forms=None):
    """
    Second-order parts of the published outputs from linear nodal vectors (Eqs. 1-4).

    Parameters
    ----------
    linkage : FlexibleLinkage
    displacement : ndarray, shape (N, n)
        Linear system vectors U at the crank angles (static sag included when the model has
        gravity: the periodic response of a model with gravity carries it).
    crank_angle : ndarray, shape (N,)

    Returns
    -------
    dict
        'outputs' (N, 4) [m] in :data:`OUTPUT_NAMES` order, 'sums' (N, 4) S per
        :data:`FORMS`, 'chord' (N, 3) delta per link, 'd_a', 'd_b' complex (N,) [m].

    """
    theta = np.atleast_1d(np.asarray(crank_angle, dtype=float))
    sums, chord = bending_sums(linkage, displacement, theta, forms)
    if 0 not in linkage.links:
        sums[:, 0] = 0.0
    kappa = output_coefficients(linkage.mechanism, theta)
    outputs = np.einsum('kof,kf->ko', kappa, sums)
    unit = np.exp(1j * solve_kinematics(linkage.mechanism, theta).angle)
    d_a = -sums[:, 0] * unit[0]
    d_b = loop_closure_second_order(unit[1], unit[2], sums[:, 1], sums[:, 2], d_a)
    return {'outputs': outputs, 'sums': sums, 'chord': chord, 'd_a': d_a, 'd_b': d_b}


def corrected_response(linkage, response):
    """
    Linear outputs plus their second-order parts for a :class:`core.simulate.PeriodicResponse`.

    Parameters
    ----------
    linkage : FlexibleLinkage
        The model the response was computed with.
    response : PeriodicResponse
        From ``periodic_response(linkage, speed, method='full', ...)`` (or 'modal' with all
        modes; a truncated modal U lacks what the basis misses).

    Returns
    -------
    dict
        'crank_angle' (P,), 'linear' (P, 4), 'second' (P, 4), 'total' (P, 4) [m], and the
        :func:`second_order_outputs` details under 'detail'.

    """
    detail = second_order_outputs(linkage, response.displacement, response.crank_angle)
    return {'crank_angle': response.crank_angle, 'linear': response.outputs,
            'second': detail['outputs'], 'total': response.outputs + detail['outputs'],
            'detail': detail}


# ---------------------------------------------------------------------------------------
# Reduced basis: U = V q (core.reduced); quadratic forms in q with angle-dependent matrices


def gather_harmonics(linkage, link):
    """
    Constant pieces of a link's gather, T^T(theta_L) = T0 + cos(theta_L) T_c + sin(theta_L) T_s.

    Only the end-node translation rows rotate (u^L = R^T (X, Y) there), so three evaluations of
    :meth:`FlexibleLinkage.gather` (theta_L = 0, pi/2, pi) give the pieces exactly.

    Returns
    -------
    ndarray, shape (3, 3 (e + 1), n)
        T0, T_c, T_s.

    """
    g = linkage.gather(link, np.array([0.0, 0.5 * np.pi, np.pi]))
    t0 = 0.5 * (g[0] + g[2])
    # entries are 0 and +-1: rounding drops the 1e-16 of sin(pi) and cos(pi / 2)
    return np.round(np.stack([t0, 0.5 * (g[0] - g[2]), g[1] - t0]))


def harmonic_matrices(linkage, basis, link, gmatrix):
    """
    Eq. (1) on a constant basis: S = q^T A(theta_L) q with five constant r x r matrices,

        A = A0 + cos(th) A1 + sin(th) A2 + cos(2 th) A3 + sin(2 th) A4,   th = theta_L,

    from ``1/2 (B0 + c Bc + s Bs)^T G (B0 + c Bc + s Bs)``, B = T V, c^2 = (1 + cos 2 th) / 2,
    s^2 = (1 - cos 2 th) / 2, c s = sin(2 th) / 2.

    Parameters
    ----------
    linkage : FlexibleLinkage
    basis : ndarray, shape (n, r)
        V (U = V q).
    link : int
    gmatrix : ndarray
        G of the link or of part of it (:func:`unit_geometric_stiffness`).

    Returns
    -------
    ndarray, shape (5, r, r), symmetric each

    """
    b0, bc, bs = np.einsum('jan,nr->jar', gather_harmonics(linkage, link), basis)
    form = lambda x, y: 0.5 * (x.T @ gmatrix @ y + y.T @ gmatrix @ x)  # noqa: E731 (sym)
    return 0.5 * np.stack([form(b0, b0) + 0.5 * (form(bc, bc) + form(bs, bs)),
                           2.0 * form(b0, bc), 2.0 * form(b0, bs),
                           0.5 * (form(bc, bc) - form(bs, bs)), form(bc, bs)])


def form_matrices(linkage, basis, crank_angle, forms=None):
    """
    A_j(theta) of every form in :data:`FORMS` at crank angles: S_j = q^T A_j q.

    Returns
    -------
    ndarray, shape (N, 4, r, r)
        Zero for the crank when it is rigid.

    """
    theta = np.atleast_1d(np.asarray(crank_angle, dtype=float))
    forms = forms or link_forms(linkage)
    angle = solve_kinematics(linkage.mechanism, theta).angle
    out = np.zeros((theta.shape[0], len(FORMS), basis.shape[1], basis.shape[1]))
    pairs = [(link, link, forms.full[link]) for link in linkage.links]
    pairs.append((3, 1, forms.coupler_half))
    for slot, link, gmatrix in pairs:
        pieces = harmonic_matrices(linkage, basis, link, gmatrix)
        th = angle[link]
        weights = np.stack([np.ones_like(th), np.cos(th), np.sin(th), np.cos(2 * th),
                            np.sin(2 * th)], axis=1)
        out[:, slot] = np.einsum('kj,jab->kab', weights, pieces)
    return out


def quadratic_tables(linkage, basis, crank_angle, forms=None):
    """
    Second-order outputs as quadratic forms of the reduced state: out_o = q^T Q_o(theta) q.

    Q_o = sum_j kappa_oj(theta) A_j(theta) (:func:`output_coefficients`,
    :func:`form_matrices`). With gravity the static sag is part of q (the reduced model's load
    includes gravity), so no separate linear and constant terms arise; a basis that kept the
    sag U_s apart (U = U_s + V q) would add ``2 U_s^T T G T^T V q / 2`` and a constant.

    Parameters
    ----------
    linkage : FlexibleLinkage
        The full model the basis belongs to (core.reduction.model.fe_mechanism, the same options).
    basis : ndarray, shape (n, r)
    crank_angle : ndarray, shape (N,)
        E.g. the reduced model's grid, 2 pi k / N.

    Returns
    -------
    dict
        'Q' (N, 4, r, r) per :data:`OUTPUT_NAMES`, 'A' (N, 4, r, r) per :data:`FORMS`,
        'kappa' (N, 4, 4).

    """
    theta = np.atleast_1d(np.asarray(crank_angle, dtype=float))
    amat = form_matrices(linkage, basis, theta, forms)
    kappa = output_coefficients(linkage.mechanism, theta)
    return {'Q': np.einsum('kof,kfab->koab', kappa, amat), 'A': amat, 'kappa': kappa}


def reduced_second_order(tables, q):
    """
    Second-order outputs from reduced states with :func:`quadratic_tables` (same angles).

    Parameters
    ----------
    tables : dict
        From :func:`quadratic_tables` at N angles.
    q : ndarray, shape (N, r)

    Returns
    -------
    ndarray, shape (N, 4) [m]

    """
    return np.einsum('ka,koab,kb->ko', q, tables['Q'], q)



@dataclasses.dataclass(frozen=True)
class FactoredForms:
    """
    Streaming form of the second-order outputs on a constant basis (per sample: S_j, then kappa).

    For form j on link L: ``z = (Z0 + cos(th_L) Zc + sin(th_L) Zs) q`` holds the link-frame
    transverse DOFs (v, phi per node) and ``S_j = 1/2 z^T G_j z`` with the banded G restricted to
    them. A compiled step computes the distinct rows of ``V q`` the link reads (interior v and
    phi, end X, Y and phi) once, rotates the end translations, and applies the band of G.

    Attributes
    ----------
    links : tuple of int
        Link of each form in :data:`FORMS` order (-1: absent, e.g. a rigid crank).
    z : dict of int to ndarray, shape (3, 2 (e + 1), r)
        Z0, Zc, Zs per modelled link.
    g : tuple of ndarray or None
        G on the (v, phi) DOFs per form, shape (2 (e + 1), 2 (e + 1)).
    rows : dict of int to ndarray
        Distinct system DOFs (rows of V) each link reads.

    """

    links: tuple
    z: dict
    g: tuple
    rows: dict


def factored_forms(linkage, basis, forms=None):
    """Build :class:`FactoredForms` of a linkage and basis V (n, r)."""
    forms = forms or link_forms(linkage)
    z, rows = {}, {}
    g, links = [], []
    for slot, link in enumerate((0, 1, 2, 1)):
        if link not in linkage.links:
            g.append(None)
            links.append(-1)
            continue
        keep = np.sort(np.concatenate([np.arange(1, 3 * (linkage.link_matrices[link].elements
                                                           + 1), 3) + d for d in (0, 1)]))
        if link not in z:
            pieces = gather_harmonics(linkage, link)[:, keep, :]
            z[link] = np.einsum('jan,nr->jar', pieces, basis)
            rows[link] = np.flatnonzero(np.abs(pieces).sum(axis=(0, 1)))
        gmatrix = forms.coupler_half if slot == 3 else forms.full[link]
        g.append(gmatrix[np.ix_(keep, keep)])
        links.append(link)
    return FactoredForms(links=tuple(links), z=z, g=tuple(g), rows=rows)


def factored_second_order(factored, mechanism, crank_angle, q):
    """
    Second-order outputs from reduced states by the factored form (equal to
    :func:`reduced_second_order` to rounding).

    Parameters
    ----------
    factored : FactoredForms
    mechanism : Mechanism
    crank_angle : ndarray, shape (N,)
    q : ndarray, shape (N, r)

    Returns
    -------
    ndarray, shape (N, 4) [m]

    """
    theta = np.atleast_1d(np.asarray(crank_angle, dtype=float))
    angle = solve_kinematics(mechanism, theta).angle
    sums = np.zeros((theta.shape[0], len(FORMS)))
    local = {}
    for link, (z0, zc, zs) in factored.z.items():
        c, s = np.cos(angle[link])[:, None], np.sin(angle[link])[:, None]
        local[link] = q @ z0.T + c * (q @ zc.T) + s * (q @ zs.T)
    for slot, (link, gmatrix) in enumerate(zip(factored.links, factored.g)):
        if link >= 0:
            sums[:, slot] = bending_integral(local[link], gmatrix)
    return np.einsum('kof,kf->ko', output_coefficients(mechanism, theta), sums)


def step_cost(factored, size, spline_powers=4):
    """
    Multiply-adds per sample of the second-order outputs in a compiled step, two ways.

    'factored' (:class:`FactoredForms`): the distinct rows of V q each link reads (rows x r),
    two per rotated end node, the band of each G (its non-zeros) plus the dot product, the
    4 x 4 output combination, and cubic-spline tables of cos/sin of the link angles and of
    kappa (16 scalars) over the crank angle. 'tables' (:func:`quadratic_tables` interpolated
    like the reduced model, a cubic per cell): 4 symmetric r x r matrices, r (r + 1) / 2
    entries each, ``spline_powers`` multiply-adds per entry to interpolate plus one each for
    the form, and r for its final dot product.

    Parameters
    ----------
    factored : FactoredForms
    size : int
        Reduced size r (the basis the forms were built with has this many columns).

    Returns
    -------
    dict
        'factored', 'tables' (multiply-adds), and the factored parts.

    """
    r = int(size)
    rows = sum(len(v) for v in factored.rows.values()) * r
    rotate = 2 * sum(int(np.count_nonzero(np.abs(z[1]).sum(axis=1))) for z in factored.z.values())
    band = sum(int(np.count_nonzero(g)) + g.shape[0] for g in factored.g if g is not None)
    scalars = spline_powers * (2 * len(factored.z) + 16) + 16
    triangle = r * (r + 1) // 2
    tables = len(OUTPUT_NAMES) * (triangle * (spline_powers + 1) + r)
    return {'factored': rows + rotate + band + scalars, 'tables': tables,
            'parts': {'rows_of_Vq': rows, 'rotate_ends': rotate, 'bands': band,
                      'scalars': scalars}}


__all__ = ['FORMS', 'OUTPUT_NAMES', 'unit_geometric_stiffness', 'bending_integral',
           'chord_shortening', 'loop_closure_second_order', 'coupler_point_second_order',
           'LinkForms', 'link_forms', 'link_local', 'bending_sums', 'output_coefficients',
           'second_order_outputs', 'corrected_response', 'gather_harmonics',
           'harmonic_matrices', 'form_matrices', 'quadratic_tables', 'reduced_second_order',
           'FactoredForms', 'factored_forms', 'factored_second_order', 'step_cost']
