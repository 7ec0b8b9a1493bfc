"""
Tables of the validity indicator (:mod:`core.validity`) on a reduced model's basis.

The indicator of :func:`core.validity.nonlinearity_indicator` needs, per sample, the link-mean
elastic axial force N_e,l over the Euler load P_cr,l of each flexible link (Eq. 1 there):
N_e,l = A_l U - F_r,l, with A_l the link mean of the FE element axial force EA (u2 - u1) / l_e
per DOF (= EA (u_last - u_first) / L, :func:`axial_operator`) and F_r,l the link mean of the
rigid-body axial force, affine in the pieces p = '1', 'a', 'w2' (:func:`rigid_axial_pieces`).

The basis V holds the bending response, not the axial stretch that carries N_e: A V q alone is
wrong by 20-200 %. The mode-acceleration form adds what V misses of the full-order equation of
motion (:mod:`.model`), U = V q + R r, with R = K_0^-1 - V K_r0^-1 V^T (R K_0 V = 0) and the
residual force r = f - M V q'' - w G V q' - (a K_a + w^2 K_w2) V q (modal damping left out);
q'' = M_r^-1 (f_r - C_r q' - K_r q) from the reduced equation. With H = A R M V M_r^-1 ::

    A U = (A V + H K_r0) q + a (H K_ra - A R K_a V) q + w^2 (H K_rw2 - A R K_w2 V) q
          + (H C_r,1 + w (H G_r - A R G V) + w^2 H C_r,w2 + w^4 H C_r,w4) q'
          + sum_p m_p (A R f_p - H f_r,p)                                                (1)

(m_p = 1, a, w^2; C_r = w G_r + C_r,1 + w^2 C_r,w2 + w^4 C_r,w4 the model's own fit). Against
the full-order indicator of the same model's periodic response, rigid crank and bearings: 1 %
where the residual flexibility of the loads alone (R f) is 7-32 % off.

So N_e,l / P_cr,l is one row of 7 r + 3 coefficients per link (:data:`COLUMNS`: q times 1, a,
w^2; q' times 1, w, w^2, w^4; then 1, a, w^2), splined per grid cell like every other table
(:mod:`.cells`).

The reference modes (frozen frequency omega_j and strain-energy shares s_jl, revolution means,
:func:`core.validity.mode_reference`) depend on the speed only (through K_G): tabulated at
:data:`REFERENCE_SPEEDS` speeds, uniform in w^2 over [0, speed_max^2], interpolated linearly in
w^2.

Plain arrays (:data:`TABLE_NAMES`), cached beside the model under a key of their own that
carries :data:`NONLINEARITY_VERSION` (:func:`.mechanism_model.with_nonlinearity`).
"""

import numpy as np

from .cells import CELL_POWERS, MONOMIALS, periodic_cell_coefficients
from .. import validity
from ..kinematics import solve_kinematics

# Bump when the tables change (it is part of the tables' cache key).
NONLINEARITY_VERSION = 2
# Monomials of the q and q' columns of a row (Eq. 1), then the constant columns 1, a, w^2.
COLUMNS = {'q': ('1', 'a', 'w2'), 'v': ('1', 'w', 'w2', 'w4')}
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


def grid_values(model, name, monomial):
    """Values on the grid of a block's monomial piece: the t^0 coefficients of its cells."""
    layout = model.layout
    rows = model.table[:, MONOMIALS.index(monomial) * CELL_POWERS, layout.slices[name]]
    return rows.reshape((model.grid_size,) + layout.shapes[name])


def mode_acceleration_rows(samples, model, operator, rigid):
    """
    Rows of Eq. (1) per grid angle: the link-mean axial force per column of :data:`COLUMNS`.

    Parameters
    ----------
    samples : FrozenSamples
        Full-order pieces on the model's grid.
    model : ReducedModel
        The reduced model (its basis and its reduced matrices, read from its table).
    operator : ndarray, shape (N, links, n)
        :func:`axial_operator` on the grid.
    rigid : dict of str to ndarray, shape (N, links)
        :func:`rigid_axial_pieces` on the grid.

    Returns
    -------
    ndarray, shape (N, links, 7 r + 3)
        [N].

    """
    basis = model.basis
    reduced = {(name, mono): grid_values(model, name, mono) for name, monos in (
        ('M', ('1',)), ('K', ('1', 'a', 'w2')), ('C', ('1', 'w', 'w2', 'w4')),
        ('f', ('1', 'a', 'w2'))) for mono in monos}
    rows = []
    for k in range(samples.grid_size):
        stiffness, axial = samples.stiffness['1'][k], operator[k]
        # A R = A K_0^-1 - (A V) K_r0^-1 V^T
        a_r = (np.linalg.solve(stiffness.T, axial.T).T
               - (axial @ basis) @ np.linalg.solve(reduced['K', '1'][k], basis.T))
        h = np.linalg.solve(reduced['M', '1'][k].T, (a_r @ samples.mass[k] @ basis).T).T
        columns = [axial @ basis + h @ reduced['K', '1'][k],
                   h @ reduced['K', 'a'][k] - a_r @ samples.stiffness['a'][k] @ basis,
                   h @ reduced['K', 'w2'][k] - a_r @ samples.stiffness['w2'][k] @ basis,
                   h @ reduced['C', '1'][k],
                   h @ reduced['C', 'w'][k] - a_r @ samples.gyroscopic[k] @ basis,
                   h @ reduced['C', 'w2'][k], h @ reduced['C', 'w4'][k]]
        columns += [(a_r @ samples.load[p][k] - h @ reduced['f', p][k] - rigid[p][k])[:, None]
                    for p in ('1', 'a', 'w2')]
        rows.append(np.concatenate(columns, axis=1))
    return np.stack(rows)


def nonlinearity_tables(linkage, samples, model, speed_max):
    """
    Build the indicator's tables for a reduced model (see the module docstring).

    Parameters
    ----------
    linkage : FlexibleLinkage
        The FE model the samples come from.
    samples : FrozenSamples
        Full-order pieces on the model's grid.
    model : ReducedModel
        The reduced model (its basis and full table).
    speed_max : float
        Largest |crank speed| of the model [rad/s].

    Returns
    -------
    dict of str to ndarray
        :data:`TABLE_NAMES`: 'nonlinearity_table' (N, CELL_POWERS, links, 7 r + 3), spline
        coefficients of the rows of Eq. (1) over P_cr; 'nonlinearity_speeds' (S,),
        'nonlinearity_omega' (S, modes), 'nonlinearity_share' (S, modes, links).

    """
    links = validity.INDICATOR_LINKS
    angles = 2.0 * np.pi * np.arange(samples.grid_size) / samples.grid_size
    rows = mode_acceleration_rows(samples, model, axial_operator(linkage, angles, links),
                                  rigid_axial_pieces(linkage, angles, links))
    loads = validity.buckling_loads(linkage.mechanism, links)
    scale = 1.0 / np.array([loads[link] for link in links])
    table = periodic_cell_coefficients(rows * scale[None, :, None])
    speeds, omega, share = reference_table(linkage, speed_max)
    return dict(zip(TABLE_NAMES, (table, speeds, omega, share)))
