"""
Second-order outputs on a reduced basis U = V q evaluated three ways: the study's alternatives.

With a constant basis V only the end-node translation rows of T^T rotate with the link angle
theta_L, ``T^T = T0 + cos T_c + sin T_s`` (:func:`core.fe.second_order_reduced.gather_harmonics`),
so ``S = q^T A(theta_L) q`` with ``A = A0 + cos A1 + sin A2 + cos 2 A3 + sin 2 A4`` (five
constant r x r matrices per link, :func:`harmonic_matrices`), and every output is
``sum_j kappa_j(theta) S_j`` with the scalar coefficients of (3)-(4)
(:func:`core.fe.second_order_geometry.output_coefficients`). Tabulated per angle
(:func:`quadratic_tables`, :func:`reduced_second_order`) or factored (the link's transverse
slopes first, :class:`FactoredForms`, :func:`factored_second_order`); :func:`step_cost` counts
both. ``docs/studies/second_order_study.py`` and ``benchmarks/second_order_bench.py`` use them;
the estimator streams the tables of :mod:`core.reduction.second_order_tables`.
"""

import dataclasses

from flexlink_ros.core.fe.second_order_full import link_forms
from flexlink_ros.core.fe.second_order_geometry import bending_integral, FORMS, \
    output_coefficients
from flexlink_ros.core.fe.second_order_reduced import gather_harmonics
from flexlink_ros.core.kinematics import solve_kinematics
from flexlink_ros.names import OUTPUT_NAMES
import numpy as np


def harmonic_matrices(linkage, basis, link, gmatrix):
    """
    Eq. (1) on a constant basis: S = q^T A(theta_L) q with five constant r x r matrices.

    ::

        A = A0 + cos(th) A1 + sin(th) A2 + cos(2 th) A3 + sin(2 th) A4,   th = theta_L,

    from ``1/2 (B0 + c Bc + s Bs)^T G (B0 + c Bc + s Bs)``, B = T V, c^2 = (1 + cos 2 th) / 2,
    s^2 = (1 - cos 2 th) / 2, c s = sin(2 th) / 2.

    Parameters
    ----------
    linkage : FlexibleLinkage
        The FE model (:class:`core.fe.linkage.FlexibleLinkage`).
    basis : ndarray, shape (n, r)
        V (U = V q).
    link : int
        Link index (0 crank, 1 coupler, 2 lever).
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
        The full model the basis belongs to (same options:
        core.reduction.mechanism_model.fe_mechanism).
    basis : ndarray, shape (n, r)
        Reduced basis V (U = V q).
    crank_angle : ndarray, shape (N,)
        E.g. the reduced model's grid, 2 pi k / N.
    forms : LinkForms or None
        G matrices from :func:`link_forms` (built when None).

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
        Reduced states, one row per crank angle.

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
        nodes = linkage.link_matrices[link].elements + 1
        keep = np.sort(np.concatenate([np.arange(1, 3 * nodes, 3) + d for d in (0, 1)]))
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
    Second-order outputs from reduced states by the factored form.

    Equal to :func:`reduced_second_order` to rounding.

    Parameters
    ----------
    factored : FactoredForms
        From :func:`factored_forms`.
    mechanism : Mechanism
        The mechanism (link angles from its kinematics).
    crank_angle : ndarray, shape (N,)
        Crank angles [rad].
    q : ndarray, shape (N, r)
        Reduced states, one row per crank angle.

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
        From :func:`factored_forms`.
    size : int
        Reduced size r (the basis the forms were built with has this many columns).
    spline_powers : int
        Multiply-adds per interpolated table entry (4 for a cubic).

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
