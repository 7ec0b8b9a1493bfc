"""
Tables of the validity indicator (:mod:`core.validity`) on a reduced model's basis.

The indicator of :func:`core.validity.nonlinearity_indicator` needs, per sample, the link-mean
elastic axial force N_e,l over the Euler load P_cr,l of each flexible link (Eq. 1 there). On the
reduced model (U = V q plus the residual flexibility the basis misses) it is affine in
(q, 1, a, w^2) with angle-dependent coefficients ::

    N_e,l / P_cr,l = [ A_l(th) V q + sum_p m_p ( A_l(th) R(th) f_p(th) - F_r,l^p(th) ) ] / P_cr,l

with p over the affine pieces '1', 'a', 'w2' (m_p = 1, a, w^2), A_l the link mean of the FE
element axial force EA (u2 - u1) / l_e per DOF (= EA (u_last - u_first) / L of the link's
axial node displacements), R = K^-1 - V K_r^-1 V^T the residual flexibility at w = a = 0 (as
the outputs' correction, :func:`.build.residual_flexibility`) and F_r,l^p the link mean of the
rigid-body axial force piece (:func:`core.validity.rigid_element_axial_forces`). Those r + 3
coefficients per link are splined per grid cell like every other table (:mod:`.cells`).

The reference modes (frozen frequency omega_j and strain-energy shares s_jl, revolution means,
:func:`core.validity.mode_reference`) depend on the speed only (through K_G): tabulated at
:data:`REFERENCE_SPEEDS` speeds, uniform in w^2 over [0, speed_max^2], interpolated linearly in
w^2.

Stored as plain arrays with the model (:data:`TABLE_NAMES`); the model cache key carries
:data:`NONLINEARITY_VERSION`.
"""

import numpy as np

from .build import residual_flexibility
from .cells import periodic_cell_coefficients
from .. import validity
from ..kinematics import solve_kinematics

# Bump when the tables change (it is part of the reduced model's cache key).
NONLINEARITY_VERSION = 1
# Speeds at which the reference modes are tabulated (uniform in w^2 from 0 to speed_max^2).
REFERENCE_SPEEDS = 9
# Array names in the model (prefixed so that they sit beside the model's own arrays).
TABLE_NAMES = ('nonlinearity_table', 'nonlinearity_speeds', 'nonlinearity_omega',
               'nonlinearity_share')


def axial_operator(linkage, crank_angle, links):
    """
    Link mean of the FE element axial forces per DOF, A_l(theta) [N per unit DOF].

    The mean over a link's e elements of EA (u_{i+1} - u_i) / l_e is EA (u_e - u_0) / L
    (:meth:`core.fe.linkage.FlexibleLinkage.element_axial_forces`, averaged).

    Parameters
    ----------
    linkage : FlexibleLinkage
        The FE model.
    crank_angle : ndarray, shape (N,)
        Crank angles [rad].
    links : tuple of int
        Links to tabulate.

    Returns
    -------
    ndarray, shape (N, len(links), n)

    """
    theta = np.atleast_1d(np.asarray(crank_angle, dtype=float))
    mechanism = linkage.mechanism
    angle = solve_kinematics(mechanism, theta).angle
    rows = []
    for link in links:
        spec = mechanism.links[link]
        gather = linkage.gather(link, angle[link])          # (N, 3 (e + 1), n)
        rows.append(mechanism.youngs_modulus * spec.area / spec.length
                    * (gather[:, -3] - gather[:, 0]))
    return np.stack(rows, axis=1)


def rigid_axial_pieces(linkage, crank_angle, links):
    """
    Link means of the rigid-body axial force per affine piece '1', 'a', 'w2' [N].

    F_r = F_1 + a F_a + w^2 F_w2 (gravity in F_1), from
    :func:`core.validity.rigid_element_axial_forces` at (w, a) = (0, 0), (0, 1), (1, 0).

    Returns
    -------
    dict of str to ndarray, shape (N, len(links))

    """
    def link_means(speed, accel):
        forces = validity.rigid_element_axial_forces(linkage, crank_angle, speed, accel)
        return np.stack([forces[link].mean(axis=1) for link in links], axis=1)

    still = link_means(0.0, 0.0)
    return {'1': still, 'a': link_means(0.0, 1.0) - still, 'w2': link_means(1.0, 0.0) - still}


def reference_table(linkage, speed_max, speeds=REFERENCE_SPEEDS):
    """
    Tabulate the reference modes at speeds in [0, speed_max] (the indicator links' shares).

    Returns
    -------
    speeds : ndarray, shape (S,)
        [rad/s].
    omega : ndarray, shape (S, modes)
        Revolution-mean frozen frequencies [rad/s].
    share : ndarray, shape (S, modes, len(INDICATOR_LINKS))
        Strain-energy shares s_jl of the links.

    """
    grid = float(speed_max) * np.sqrt(np.linspace(0.0, 1.0, speeds))
    refs = [validity.mode_reference(linkage, speed) for speed in grid]
    links = list(validity.INDICATOR_LINKS)
    return (grid, np.stack([ref['omega'] for ref in refs]),
            np.stack([ref['share'][:, links] for ref in refs]))


def nonlinearity_tables(linkage, samples, basis, speed_max):
    """
    Build the indicator's tables for a reduced model (see the module docstring).

    Parameters
    ----------
    linkage : FlexibleLinkage
        The FE model the samples come from.
    samples : FrozenSamples
        Full-order pieces on the model's grid.
    basis : ndarray, shape (n, r)
        The model's constant basis V.
    speed_max : float
        Largest |crank speed| of the model [rad/s].

    Returns
    -------
    dict of str to ndarray
        :data:`TABLE_NAMES`: 'nonlinearity_table' (N, CELL_POWERS, links, r + 3), spline
        coefficients of the rows [A V | c_1 | c_a | c_w2] / P_cr; 'nonlinearity_speeds' (S,),
        'nonlinearity_omega' (S, modes), 'nonlinearity_share' (S, modes, links).

    """
    links = validity.INDICATOR_LINKS
    count = samples.grid_size
    angles = 2.0 * np.pi * np.arange(count) / count
    operator = axial_operator(linkage, angles, links)
    rigid = rigid_axial_pieces(linkage, angles, links)
    residual = residual_flexibility(samples, basis, operator)
    loads = validity.buckling_loads(linkage.mechanism, links)
    scale = 1.0 / np.array([loads[link] for link in links])
    columns = [operator @ basis] + [(residual[piece] - rigid[piece])[..., None]
                                    for piece in ('1', 'a', 'w2')]
    values = np.concatenate(columns, axis=-1) * scale[None, :, None]
    table = periodic_cell_coefficients(values)
    speeds, omega, share = reference_table(linkage, speed_max)
    return dict(zip(TABLE_NAMES, (table, speeds, omega, share)))
