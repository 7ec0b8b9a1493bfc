"""
Second-order (quasi-static) motion of the flexible four-bar from its linear KED state.

The linear kineto-elastodynamic model of Cho, Park & Lee (1992) (:mod:`core.fe.linkage`,
:mod:`core.fe.simulate`) keeps each link's axial and transverse deflections to first order. A bent
link is also shorter along its chord, by an amount quadratic in its bending; with rigid bearings
joint B moves mainly by that shortening of the coupler and the lever (the linear lever tip is
89-100 % low against a geometrically exact peer, :mod:`studies.peer_exudyn`). This module adds
that motion, computed from the linear state, without any further dynamics (the inertia of the
second-order motion and the axial eigenstrain it causes are left out here:
:mod:`.second_order_dynamic` adds them).

Here the second-order outputs are evaluated from full-order nodal vectors U; the geometry
(Eqs. 1-4) is in :mod:`core.fe.second_order_geometry`, the reduced-basis forms in
:mod:`core.fe.second_order_reduced`.
"""

import dataclasses

import numpy as np

from .second_order_geometry import (bending_integral, chord_shortening, FORMS,
                                    loop_closure_second_order, output_coefficients,
                                    unit_geometric_stiffness)
from ..kinematics import solve_kinematics


@dataclasses.dataclass(frozen=True)
class LinkForms:
    """
    Per-link G matrices of a :class:`core.fe.linkage.FlexibleLinkage`.

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
        The FE model (:class:`core.fe.linkage.FlexibleLinkage`).
    displacement : ndarray, shape (N, n)
        System vectors U (e.g. ``PeriodicResponse.displacement``).
    crank_angle : ndarray, shape (N,)
        Crank angles [rad].

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


def second_order_outputs(linkage, displacement, crank_angle, forms=None):
    """
    Second-order parts of the published outputs from linear nodal vectors (Eqs. 1-4).

    Parameters
    ----------
    linkage : FlexibleLinkage
        The FE model (:class:`core.fe.linkage.FlexibleLinkage`).
    displacement : ndarray, shape (N, n)
        Linear system vectors U at the crank angles (static sag included when the model has
        gravity: the periodic response of a model with gravity carries it).
    crank_angle : ndarray, shape (N,)
        Crank angles [rad].
    forms : LinkForms or None
        G matrices from :func:`link_forms` (built when None).

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
    Linear outputs plus their second-order parts for a :class:`core.fe.simulate.PeriodicResponse`.

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
