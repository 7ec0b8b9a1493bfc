"""
Build a reduced model from the full-order pieces on the grid: basis, projection, tables.

The steps of :func:`reduce_samples`: a constant basis V (:mod:`.basis`); the projected
system ``V^T X(theta) V`` with the damping fitted in w^2; the residual flexibility
``O (K^-1 - V K_r^-1 V^T) f`` the basis misses of the quasi-static response; the joint
reactions for the criteria; and the periodic cubic spline of everything, per grid cell and
monomial (:mod:`.cells`).
"""

import numpy as np

from .basis import build_basis, fit_in_w2
from .cells import CELL_POWERS, MONOMIALS, periodic_cell_coefficients
from .model import ReducedModel, TableLayout

# The affine pieces of stiffness, load and reactions: F = F_1 + a F_a + w^2 F_w2.
AFFINE_PIECES = ('1', 'a', 'w2')


def project_system(pieces, samples, basis, speed_max, damping_speeds):
    """
    Project mass, Coriolis, fitted damping, stiffness, load and outputs onto ``basis``.

    Parameters
    ----------
    pieces : dict
        Block name to {monomial: values on the grid}; filled in place.
    samples : FrozenSamples
        Full-order pieces on the grid.
    basis : ndarray, shape (n, r)
        Constant basis V.
    speed_max : float
        Largest |crank speed| of the damping fit [rad/s].
    damping_speeds : int
        Speeds in [0, speed_max] at which the projected damping is fitted in w^2.

    """
    count = samples.grid_size
    project = lambda x: np.einsum('ni,...nm,mj->...ij', basis, x, basis)  # noqa: E731
    pieces['M']['1'] = project(samples.mass)
    pieces['C']['w'] = project(samples.gyroscopic)
    speeds = np.linspace(0.0, speed_max, max(damping_speeds, 3))
    damping = np.array([[basis.T @ samples.damping(k, w) @ basis for k in range(count)]
                        for w in speeds])
    fitted = fit_in_w2(damping, speeds)
    pieces['C']['1'], pieces['C']['w2'], pieces['C']['w4'] = fitted
    for piece in AFFINE_PIECES:
        pieces['K'][piece] = project(samples.stiffness[piece])
        pieces['f'][piece] = samples.load[piece] @ basis
    if 'w' in samples.stiffness:
        # Stiffness damping's D_beta = w Kb1 (core/fe/stiffness_damping.py): monomial w.
        pieces['K']['w'] = project(samples.stiffness['w'])
    pieces['out']['1'] = samples.outputs @ basis


def residual_flexibility(samples, basis):
    """
    Output error of the basis on the quasi-static response, per load piece and grid angle.

    ``O (K^-1 - V K_r^-1 V^T) f_piece`` at w = a = 0.

    Parameters
    ----------
    samples : FrozenSamples
        Full-order pieces on the grid.
    basis : ndarray, shape (n, r)
        Constant basis V.

    Returns
    -------
    dict of str to ndarray, shape (N, outputs)
        Per piece '1', 'a', 'w2'.

    """
    count = samples.grid_size
    residual = np.zeros((3, count, samples.outputs.shape[1]))
    for k in range(count):
        stiffness = samples.stiffness['1'][k]
        reduced_k = basis.T @ stiffness @ basis
        for i, piece in enumerate(AFFINE_PIECES):
            load = samples.load[piece][k]
            full = np.linalg.solve(stiffness, load)
            kept = basis @ np.linalg.solve(reduced_k, basis.T @ load)
            residual[i, k] = samples.outputs[k] @ (full - kept)
    return {piece: residual[i] for i, piece in enumerate(AFFINE_PIECES)}


def reaction_tables(pieces, forces, count, joints):
    """
    Tabulate the joint reactions, their time derivative and the RMS-reaction moments.

    Parameters
    ----------
    pieces : dict
        Block name to {monomial: values on the grid}; 'force', 'force_dot', 'rms2' are set.
    forces : dict or None
        As :func:`reduce_samples` takes them.
    count : int
        Grid size N.
    joints : int
        Joints with criteria data.

    Returns
    -------
    ndarray, shape (joints, 3)
        The model's ``force_moments``.

    """
    zero_force = np.zeros((count, joints, 2))
    forces = forces or {}
    force = {piece: forces.get('force', {}).get(piece, zero_force) for piece in AFFINE_PIECES}
    rate = {piece: forces.get('force_rate', {}).get(piece, zero_force)
            for piece in AFFINE_PIECES}
    pieces['force'] = force
    pieces['force_dot'] = {'w': rate['1'], 'wa': rate['a'] + 2.0 * force['w2'],
                           'w3': rate['w2']}
    force_moments = np.stack([np.mean(np.sum(force['1'] ** 2, axis=-1), axis=0),
                              2.0 * np.mean(np.sum(force['1'] * force['w2'], axis=-1), axis=0),
                              np.mean(np.sum(force['w2'] ** 2, axis=-1), axis=0)], axis=1)
    constant = lambda values: np.broadcast_to(values, (count, joints))  # noqa: E731
    pieces['rms2'] = {'1': constant(force_moments[:, 0]), 'w2': constant(force_moments[:, 1]),
                      'w4': constant(force_moments[:, 2])}
    return force_moments


def cell_table(pieces, count, layout):
    """
    Spline every piece per grid cell into the flat table of a ReducedModel.

    Parameters
    ----------
    pieces : dict
        Block name to {monomial: values on the grid, shape (N, ...)}.
    count : int
        Grid size N.
    layout : TableLayout
        Column layout of the table.

    Returns
    -------
    ndarray, shape (N, len(MONOMIALS) * CELL_POWERS, layout.width)

    """
    table = np.zeros((count, len(MONOMIALS), CELL_POWERS, layout.width))
    for name, by_mono in pieces.items():
        for mono, values in by_mono.items():
            coef = periodic_cell_coefficients(values.reshape(count, -1))
            table[:, MONOMIALS.index(mono), :, layout.slices[name]] = coef
    return table.reshape(count, len(MONOMIALS) * CELL_POWERS, layout.width)


def shape_table(samples, basis):
    """
    Spline the link-shape operator (projected) and the rigid positions per grid cell.

    Parameters
    ----------
    samples : FrozenSamples
        Full-order pieces on the grid.
    basis : ndarray, shape (n, r)
        Constant basis V.

    Returns
    -------
    ndarray, shape (N, CELL_POWERS, links, points, 2, r + 1)

    """
    count = samples.grid_size
    operator = np.einsum('klpcn,nr->klpcr', samples.shape_operator, basis)
    shape_values = np.concatenate([operator, samples.shape_positions[..., None]], axis=-1)
    return periodic_cell_coefficients(shape_values.reshape(count, -1)).reshape(
        (count, CELL_POWERS) + shape_values.shape[1:])


def reduce_samples(samples, modes, static=0, speed_max=60.0, zeta=0.02, forces=None,
                   damping_speeds=4, basis_speeds=3, angle_stride=1, info=None):
    """
    Build the reduced model from full-order pieces on the grid.

    Parameters
    ----------
    samples : FrozenSamples
        Full-order pieces on a uniform periodic grid of N crank angles.
    modes : int
        Basis directions from frozen modes.
    static : int
        Basis directions from static load responses.
    speed_max : float
        Largest |crank speed| to serve [rad/s] (basis snapshots and damping fit span it).
    zeta : float
        Modal damping ratio (recorded; the damping itself comes from ``samples.damping``).
    forces : dict or None
        Rigid-body joint reactions for the criteria: keys 'force' and 'force_rate', each a
        dict {'1', 'a', 'w2'} of arrays (N, joints, 2): F = F_1 + a F_a + w^2 F_w2 [N] and
        its derivative in theta [N/rad]; None for zeros. The time derivative tabulated is
        ``dF/dt = w dF/dtheta + 2 w a F_w2`` (crank jerk taken as zero).
    damping_speeds : int
        Speeds in [0, speed_max] at which the projected damping is fitted in w^2 (>= 3).
    basis_speeds : int
        Speeds in [0, speed_max] at which basis snapshots are taken.
    angle_stride : int
        Grid stride for basis snapshots.
    info : dict or None
        Extra JSON-serialisable facts to keep with the model.

    Returns
    -------
    ReducedModel
        The tables, the basis and the diagnostics.

    """
    count = samples.grid_size
    basis, singular = build_basis(samples, modes, static,
                                  np.linspace(0.0, speed_max, basis_speeds), angle_stride)
    size = basis.shape[1]
    layout = TableLayout(size)
    pieces = {name: {} for name in layout.shapes}
    project_system(pieces, samples, basis, speed_max, damping_speeds)
    pieces['corr'].update(residual_flexibility(samples, basis))
    force_moments = reaction_tables(pieces, forces, count, layout.joints)
    table = cell_table(pieces, count, layout)
    details = {'modes': int(modes), 'static': int(static), 'grid_size': int(count),
               'full_dofs': int(samples.dofs),
               'pod_modes': singular['modes'][:2 * size].tolist(),
               'pod_static': singular['static'][:2 * size].tolist()}
    details.update(info or {})
    return ReducedModel(table=table, shape_table=shape_table(samples, basis), basis=basis,
                        force_moments=force_moments, speed_max=float(speed_max),
                        zeta=float(zeta), info=details)
