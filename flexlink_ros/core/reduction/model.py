"""
Reduced model of the flexible linkage for streaming: one precompute for every speed.

The full-order frozen system of Cho, Park & Lee (1992), Eq. 22, at crank angle theta, speed w
and acceleration a is ::

    M(th) q'' + (w G(th) + C_d(th, w)) q' + (K_0(th) + a K_a(th) + w^2 K_w2(th)) q
        = f_0(th) + a f_a(th) + w^2 f_w2(th)

(G: Coriolis terms; K: elastic, geometric (Eq. A.4) and the rotating-frame terms; f: rigid-body
inertia and gravity loads; C_d: modal damping zeta on the frozen modes). Everything but C_d is
affine in (w, w^2, a), so its pieces are tabulated once over a periodic grid of crank angles.

Basis. One constant basis V (n x r) serves the whole cycle: the frozen modes at every grid
angle and at several speeds, stacked, mass-weighted and compressed by an SVD (proper orthogonal
decomposition), optionally augmented by the static responses to the load pieces. A constant V
makes the reduced matrices V^T X(theta) V smooth in theta (no mode ordering or sign flips where
the coupler and lever modes veer past each other near 391 rpm), adds no dPhi/dt terms, and lets
the modal state run through grid cells without jumps.

Residual flexibility. What V misses of the quasi-static response, ``O (K^-1 - V K_r^-1 V^T) f``
(O: output operator), is tabulated too; it is added to the outputs and its size is the
estimator's per-sample error indicator.

Damping. C_d(theta, w) of the full model is projected, ``V^T C_d V``, at several speeds and
fitted by a quadratic in w^2 (exact at w = 0 and at the fitted speeds).

Interpolation. Every tabulated quantity is a periodic cubic spline in theta; per grid cell it
is stored as the coefficients of ``t^p`` (t in [0, 1) across the cell) times each monomial of
:data:`MONOMIALS`, so one dot product of 4 x len(MONOMIALS) weights with one cell's table
gives every matrix, load and output operator at (theta, w, a); the streaming step splits
that product by block to read only the monomial rows each block uses.
"""

import dataclasses

import numpy as np
import scipy.linalg

from . import store
from ..integrators import RadauIIA, compose_affine, step_maps
from .. import dynamics
from ..fe import linkage as assembly
from ..fe import simulate
from ..options import DEFAULT_SIZES, MODEL_VERSION, ModelOptions
from ...names import JOINT_NAMES as JOINTS, OUTPUT_NAMES

# Monomials of (w, a) that multiply the tabulated pieces, in table-row order ('w4': damping
# fit; 'wa', 'w3': time derivative of the joint reactions).
# The order puts each matrix block's monomials next to each other (K: a, 1, w2; M: 1;
# C: 1, w2, w, w4), so the streaming step reads only the rows a block uses.
MONOMIALS = ('a', '1', 'w2', 'w', 'w4', 'wa', 'w3')
# Polynomial degree of the spline in each cell (cubic).
CELL_POWERS = 4
# Exponent of the (omega_1 / omega) weight of frozen-mode snapshots in the POD.
MODE_WEIGHT_POWER = 2.0
# Static snapshots per angle and speed: the load at that speed ('w') and the acceleration piece.
STATIC_PIECES = ('w', 'a')
# Output channels of the deflection operator, in order.
# Joints of the criteria data (see core/criteria.py).


def monomial_values(w, a):
    """
    Values of :data:`MONOMIALS` at speed ``w`` [rad/s] and acceleration ``a`` [rad/s^2].

    Returns
    -------
    tuple of float
        One value per monomial.

    """
    w2 = w * w
    return (a, 1.0, w2, w, w2 * w2, w * a, w2 * w)


def periodic_cell_coefficients(values):
    """
    Per-cell coefficients of the periodic cubic spline through samples on a uniform grid.

    Parameters
    ----------
    values : ndarray, shape (N, ...)
        Samples at theta_k = 2 pi k / N.

    Returns
    -------
    ndarray, shape (N, 4, ...)
        ``c[k, p]`` such that the spline on cell k is ``sum_p c[k, p] t^p``, t in [0, 1).

    """
    values = np.asarray(values, dtype=float)
    count = values.shape[0]
    closed = np.concatenate([values, values[:1]], axis=0)
    import scipy.interpolate   # precompute only: spares the node ~20 MB of resident size
    spline = scipy.interpolate.CubicSpline(np.arange(count + 1.0), closed, axis=0,
                                           bc_type='periodic')
    # spline.c[m, k] multiplies (x - k)^(3 - m); the cell width is 1 here.
    return np.moveaxis(spline.c[::-1], 0, 1).copy()


@dataclasses.dataclass(frozen=True)
class FrozenSamples:
    """
    Full-order affine pieces of the frozen system on a periodic crank-angle grid.

    Attributes
    ----------
    mass : ndarray, shape (N, n, n)
        M(theta).
    gyroscopic : ndarray, shape (N, n, n)
        G(theta): the velocity-proportional matrix is w G (Coriolis).
    stiffness : dict of str to ndarray, shape (N, n, n)
        Keys '1', 'a', 'w2': K_0, K_a, K_w2 (elastic + geometric + rotating-frame terms).
    load : dict of str to ndarray, shape (N, n)
        Keys '1', 'a', 'w2': f_0, f_a, f_w2.
    outputs : ndarray, shape (N, len(OUTPUT_NAMES), n)
        Ground-frame deflections of the output points per DOF.
    damping : callable
        ``damping(k, w) -> ndarray (n, n)``: modal damping matrix at grid angle k, speed w.
    shape_operator : ndarray, shape (N, links, points, 2, n)
        Ground-frame deflection of points along each link per DOF.
    shape_positions : ndarray, shape (N, links, points, 2)
        Rigid-body positions of those points [m].
    frozen : dict or None
        Keys '1', 'a', 'w2': symmetric stiffness pieces of the frozen eigenproblem (elastic +
        geometric, as core/modes.py); None to use the symmetric part of ``stiffness``.

    """

    mass: np.ndarray
    gyroscopic: np.ndarray
    stiffness: dict
    load: dict
    outputs: np.ndarray
    damping: object
    shape_operator: np.ndarray
    shape_positions: np.ndarray
    frozen: dict = None

    @property
    def grid_size(self):
        """Number of grid angles N."""
        return self.mass.shape[0]

    @property
    def dofs(self):
        """Full-order size n."""
        return self.mass.shape[1]

    def stiffness_at(self, k, w, a=0.0):
        """K(theta_k, w, a) of the full model, shape (n, n)."""
        pieces = self.stiffness
        return pieces['1'][k] + a * pieces['a'][k] + w * w * pieces['w2'][k]

    def frozen_at(self, k, w, a=0.0):
        """Stiffness of the frozen eigenproblem at (theta_k, w, a), shape (n, n)."""
        if self.frozen is None:
            stiffness = self.stiffness_at(k, w, a)
            return 0.5 * (stiffness + stiffness.T)
        pieces = self.frozen
        return pieces['1'][k] + a * pieces['a'][k] + w * w * pieces['w2'][k]

    def load_at(self, k, w, a=0.0):
        """f(theta_k, w, a) of the full model, shape (n,)."""
        return self.load['1'][k] + a * self.load['a'][k] + w * w * self.load['w2'][k]


def mass_weighted_pod(snapshots, mass_ref, count):
    """
    Leading mass-orthonormal directions of a set of snapshot vectors (POD by SVD).

    Parameters
    ----------
    snapshots : ndarray, shape (n, m)
        Columns to compress.
    mass_ref : ndarray, shape (n, n)
        Symmetric positive definite weight (the cycle-mean mass matrix).
    count : int
        Directions to keep.

    Returns
    -------
    basis : ndarray, shape (n, count)
        ``basis.T @ mass_ref @ basis = I``.
    singular_values : ndarray, shape (min(n, m),)
        Of the weighted snapshot matrix, for truncation reports.

    """
    factor = np.linalg.cholesky(mass_ref)          # M = L L^T
    weighted = factor.T @ snapshots
    left, singular, _ = np.linalg.svd(weighted, full_matrices=False)
    basis = scipy.linalg.solve_triangular(factor.T, left[:, :count], lower=False)
    return basis, singular


def frozen_modes(stiffness, mass, count):
    """
    Lowest ``count`` frozen modes, mass-normalised, and their circular frequencies [rad/s].

    Returns
    -------
    omega : ndarray, shape (count,)
    shapes : ndarray, shape (n, count)

    """
    sym_k = 0.5 * (stiffness + stiffness.T)
    eigval, eigvec = scipy.linalg.eigh(sym_k, mass, subset_by_index=[0, count - 1])
    return np.sqrt(np.maximum(eigval, 0.0)), eigvec


def build_basis(samples, modes, static, speeds, angle_stride=1):
    """
    Constant reduced basis from frozen modes and static load responses over the cycle.

    Parameters
    ----------
    samples : FrozenSamples
        Full-order pieces on the grid.
    modes : int
        Directions kept from the frozen-mode snapshots.
    static : int
        Further directions kept from the static responses to the load pieces (after removing
        what the modal directions already span); 0 for none.
    speeds : sequence of float
        Crank speeds [rad/s] at which modes and static responses are collected.
    angle_stride : int
        Use every ``angle_stride``-th grid angle.

    Returns
    -------
    basis : ndarray, shape (n, modes + static)
        Orthonormal in the cycle-mean mass matrix.
    singular_values : dict of str to ndarray
        'modes' and 'static' POD spectra (for truncation reports).

    """
    mass_ref = samples.mass.mean(axis=0)
    # Collect a few more frozen modes than kept, so the POD sees where they go.
    per_state = min(samples.dofs, modes + 2)
    mode_snaps, static_snaps = [], []
    for k in range(0, samples.grid_size, angle_stride):
        for w in speeds:
            omega, shapes = frozen_modes(samples.frozen_at(k, w), samples.mass[k], per_state)
            stiffness = samples.stiffness_at(k, w)
            # Weight by flexibility (omega_1 / omega)^2, a mode's share of a static response,
            # so the extra modes collected count less than the ones to keep.
            weight = (omega[0] / np.maximum(omega, omega[0])) ** MODE_WEIGHT_POWER
            mode_snaps.append(shapes * weight)
            if static:
                # Static responses to the load at this speed (magnitudes kept: the larger
                # responses matter more) and to the acceleration piece.
                for piece in STATIC_PIECES:
                    load = (samples.load_at(k, w) if piece == 'w' else samples.load['a'][k])
                    static_snaps.append(np.linalg.solve(stiffness, load)[:, None])
    modal_basis, modal_sv = mass_weighted_pod(np.hstack(mode_snaps), mass_ref, modes)
    singular = {'modes': modal_sv, 'static': np.zeros(0)}
    if not static:
        return modal_basis, singular
    snaps = np.hstack(static_snaps)
    norms = np.sqrt(np.einsum('ij,ik,kj->j', snaps, mass_ref, snaps))
    snaps = snaps / np.max(norms)
    # Remove the modal span (mass-orthogonal projection), then compress what is left.
    snaps = snaps - modal_basis @ (modal_basis.T @ (mass_ref @ snaps))
    static_basis, static_sv = mass_weighted_pod(snaps, mass_ref, static)
    singular['static'] = static_sv
    basis = np.hstack([modal_basis, static_basis])
    # Re-orthonormalise the union (round-off) in the mass metric.
    gram = basis.T @ mass_ref @ basis
    basis = basis @ np.linalg.inv(np.linalg.cholesky(gram)).T
    return basis, singular


def fit_in_w2(values_by_speed, speeds):
    """
    Least-squares fit ``X(w) = X0 + w^2 X2 + w^4 X4`` over given speeds.

    Parameters
    ----------
    values_by_speed : ndarray, shape (S, ...)
        X at each speed.
    speeds : ndarray, shape (S,)
        Speeds [rad/s]; at least 3 distinct |w|.

    Returns
    -------
    ndarray, shape (3, ...)
        X0, X2, X4.

    """
    speeds = np.asarray(speeds, dtype=float)
    design = np.stack([np.ones_like(speeds), speeds ** 2, speeds ** 4], axis=1)
    flat = values_by_speed.reshape(len(speeds), -1)
    coef, *_ = np.linalg.lstsq(design, flat, rcond=None)
    return coef.reshape((3,) + values_by_speed.shape[1:])


class TableLayout:
    """
    Column layout of a reduced model's table: named blocks of a flat row.

    Parameters
    ----------
    size : int
        Reduced size r.
    outputs : int
        Output channels (len(OUTPUT_NAMES)).
    joints : int
        Joints with criteria data (len(JOINTS)).

    """

    def __init__(self, size, outputs=len(OUTPUT_NAMES), joints=len(JOINTS)):
        self.size, self.outputs, self.joints = size, outputs, joints
        shapes = (('M', (size, size)), ('C', (size, size)), ('K', (size, size)),
                  ('f', (size,)), ('out', (outputs, size)), ('corr', (outputs,)),
                  ('force', (joints, 2)), ('force_dot', (joints, 2)), ('rms2', (joints,)))
        self.shapes = dict(shapes)
        self.slices = {}
        start = 0
        for name, shape in shapes:
            width = int(np.prod(shape))
            self.slices[name] = slice(start, start + width)
            start += width
        self.width = start

    def block(self, row, name):
        """View of block ``name`` in a flat row (or rows, leading axes kept)."""
        part = row[..., self.slices[name]]
        return part.reshape(part.shape[:-1] + self.shapes[name])


def cell_groups(cells):
    """(cell, indices of the angles in it) for each grid cell present in ``cells``."""
    order = np.argsort(cells, kind='stable')
    for group in np.split(order, np.flatnonzero(np.diff(cells[order])) + 1):
        if group.size:
            yield int(cells[group[0]]), group


@dataclasses.dataclass(frozen=True)
class ReducedModel:
    """
    Precomputed reduced model: tables over a periodic crank-angle grid.

    Attributes
    ----------
    table : ndarray, shape (N, len(MONOMIALS) * CELL_POWERS, L)
        Per cell, the spline coefficients of every block (see :class:`TableLayout`), row
        ``m * CELL_POWERS + p`` multiplying monomial m times ``t^p``.
    shape_table : ndarray, shape (N, CELL_POWERS, links, points, 2, r + 1)
        Per cell, spline coefficients of rigid positions (last column) and the ground-frame
        deflection operator of points along each link.
    basis : ndarray, shape (n, r)
        Constant basis V (full-order DOFs per reduced coordinate).
    force_moments : ndarray, shape (joints, 3)
        Cycle means of |F_0|^2, 2 F_0.F_w2 and |F_w2|^2 per joint, so that the RMS reaction
        at speed w is sqrt(m0 + m1 w^2 + m2 w^4) (for the near-zero flag; also tabulated as
        block 'rms2').
    speed_max : float
        Largest |crank speed| the basis and damping fit were built for [rad/s].
    zeta : float
        Modal damping ratio.
    info : dict
        Options and diagnostics (JSON-serialisable).

    """

    table: np.ndarray
    shape_table: np.ndarray
    basis: np.ndarray
    force_moments: np.ndarray
    speed_max: float
    zeta: float
    info: dict = dataclasses.field(default_factory=dict)

    @property
    def grid_size(self):
        """Number of grid cells N."""
        return self.table.shape[0]

    @property
    def size(self):
        """Reduced size r."""
        return self.basis.shape[1]

    @property
    def layout(self):
        """TableLayout of ``table``."""
        return TableLayout(self.size)

    @property
    def nbytes(self):
        """Memory of the arrays [bytes]."""
        return (self.table.nbytes + self.shape_table.nbytes + self.basis.nbytes
                + self.force_moments.nbytes)

    def to_arrays(self):
        """Arrays and metadata for :func:`core.cache.save_cache`."""
        arrays = {'table': self.table, 'shape_table': self.shape_table, 'basis': self.basis,
                  'force_moments': self.force_moments}
        meta = {'speed_max': self.speed_max, 'zeta': self.zeta, 'info': self.info}
        return arrays, meta

    @classmethod
    def from_arrays(cls, arrays, meta):
        """Inverse of :meth:`to_arrays`."""
        return cls(table=arrays['table'], shape_table=arrays['shape_table'],
                   basis=arrays['basis'], force_moments=arrays['force_moments'],
                   speed_max=float(meta['speed_max']), zeta=float(meta['zeta']),
                   info=dict(meta.get('info', {})))

    def cell(self, theta):
        """Cell index and position t in [0, 1) of crank angles (any range); vectorised."""
        x = np.mod(np.asarray(theta, dtype=float), 2.0 * np.pi) * (self.grid_size / (2.0 * np.pi))
        k = np.minimum(np.floor(x).astype(int), self.grid_size - 1)
        return k, x - k

    def weights(self, t, w, a):
        """
        Row weights monomial * t^p, shape (..., len(MONOMIALS) * CELL_POWERS).

        Parameters
        ----------
        t, w, a : float or ndarray
            Cell position, speed [rad/s], acceleration [rad/s^2] (broadcast together).

        """
        t, w, a = np.broadcast_arrays(*(np.asarray(v, dtype=float) for v in (t, w, a)))
        powers = np.stack([t ** p for p in range(CELL_POWERS)], axis=-1)
        monos = np.stack(np.broadcast_arrays(*monomial_values(w, a)), axis=-1)
        return (monos[..., :, None] * powers[..., None, :]).reshape(t.shape + (-1,))

    def evaluate(self, theta, w, a=0.0):
        """
        Every tabulated block at crank angles ``theta``, speeds ``w``, accelerations ``a``.

        Parameters
        ----------
        theta, w, a : float or ndarray, shape (m,)
            Crank angle [rad], speed [rad/s], acceleration [rad/s^2].

        Returns
        -------
        ndarray, shape (m, L)
            Flat rows; read blocks with ``layout.block(rows, name)``.

        """
        theta, w, a = np.broadcast_arrays(*(np.atleast_1d(np.asarray(v, dtype=float))
                                            for v in (theta, w, a)))
        theta, w, a = (v.ravel() for v in (theta, w, a))
        cells, t = self.cell(theta)
        weights = self.weights(t, w, a)
        rows = np.empty((theta.size, self.table.shape[2]))
        # One matrix product per grid cell (no gathered copy of the table per angle).
        for k, group in cell_groups(cells):
            rows[group] = weights[group] @ self.table[k]
        return rows

    def shapes(self, theta, q):
        """
        Rigid positions and elastic deflections of points along each link.

        Parameters
        ----------
        theta : float
            Crank angle [rad].
        q : ndarray, shape (r,)
            Reduced coordinates.

        Returns
        -------
        positions, deflections : ndarray, shape (links, points, 2)
            Ground frame [m].

        """
        k, t = self.cell(theta)
        coef = self.shape_table[int(k)]
        values = np.tensordot(float(t) ** np.arange(CELL_POWERS), coef, axes=1)
        return values[..., -1], values[..., :-1] @ q


def reduce_samples(samples, modes, static=0, speed_max=60.0, zeta=0.02, forces=None,
                   damping_speeds=4, basis_speeds=3, angle_stride=1, info=None):
    """
    Build the reduced model from full-order pieces on the grid.

    Parameters
    ----------
    samples : FrozenSamples
        Full-order pieces on a uniform periodic grid of N crank angles.
    modes, static : int
        Basis directions from frozen modes and from static load responses.
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

    """
    count = samples.grid_size
    basis, singular = build_basis(samples, modes, static,
                                  np.linspace(0.0, speed_max, basis_speeds), angle_stride)
    size = basis.shape[1]
    layout = TableLayout(size)
    project = lambda x: np.einsum('ni,...nm,mj->...ij', basis, x, basis)  # noqa: E731
    pieces = {name: {} for name in layout.shapes}
    pieces['M']['1'] = project(samples.mass)
    pieces['C']['w'] = project(samples.gyroscopic)
    speeds = np.linspace(0.0, speed_max, max(damping_speeds, 3))
    damping = np.array([[basis.T @ samples.damping(k, w) @ basis for k in range(count)]
                        for w in speeds])
    fitted = fit_in_w2(damping, speeds)
    pieces['C']['1'], pieces['C']['w2'], pieces['C']['w4'] = fitted
    for piece in ('1', 'a', 'w2'):
        pieces['K'][piece] = project(samples.stiffness[piece])
        pieces['f'][piece] = samples.load[piece] @ basis
    pieces['out']['1'] = samples.outputs @ basis
    # Residual flexibility at w = a = 0: O (K^-1 - V K_r^-1 V^T) f_piece.
    residual = np.zeros((3, count, samples.outputs.shape[1]))
    for k in range(count):
        stiffness = samples.stiffness['1'][k]
        reduced_k = basis.T @ stiffness @ basis
        for i, piece in enumerate(('1', 'a', 'w2')):
            load = samples.load[piece][k]
            full = np.linalg.solve(stiffness, load)
            kept = basis @ np.linalg.solve(reduced_k, basis.T @ load)
            residual[i, k] = samples.outputs[k] @ (full - kept)
    for i, piece in enumerate(('1', 'a', 'w2')):
        pieces['corr'][piece] = residual[i]
    joints = layout.joints
    zero_force = np.zeros((count, joints, 2))
    forces = forces or {}
    force = {piece: forces.get('force', {}).get(piece, zero_force) for piece in ('1', 'a', 'w2')}
    rate = {piece: forces.get('force_rate', {}).get(piece, zero_force)
            for piece in ('1', 'a', 'w2')}
    pieces['force'] = force
    pieces['force_dot'] = {'w': rate['1'], 'wa': rate['a'] + 2.0 * force['w2'],
                           'w3': rate['w2']}
    force_moments = np.stack([np.mean(np.sum(force['1'] ** 2, axis=-1), axis=0),
                              2.0 * np.mean(np.sum(force['1'] * force['w2'], axis=-1), axis=0),
                              np.mean(np.sum(force['w2'] ** 2, axis=-1), axis=0)], axis=1)
    constant = lambda values: np.broadcast_to(values, (count, joints))  # noqa: E731
    pieces['rms2'] = {'1': constant(force_moments[:, 0]), 'w2': constant(force_moments[:, 1]),
                      'w4': constant(force_moments[:, 2])}

    table = np.zeros((count, len(MONOMIALS), CELL_POWERS, layout.width))
    for name, by_mono in pieces.items():
        for mono, values in by_mono.items():
            coef = periodic_cell_coefficients(values.reshape(count, -1))
            table[:, MONOMIALS.index(mono), :, layout.slices[name]] = coef
    table = table.reshape(count, len(MONOMIALS) * CELL_POWERS, layout.width)

    operator = np.einsum('klpcn,nr->klpcr', samples.shape_operator, basis)
    shape_values = np.concatenate([operator, samples.shape_positions[..., None]], axis=-1)
    shape_table = periodic_cell_coefficients(shape_values.reshape(count, -1)).reshape(
        (count, CELL_POWERS) + shape_values.shape[1:])

    details = {'modes': int(modes), 'static': int(static), 'grid_size': int(count),
               'full_dofs': int(samples.dofs),
               'pod_modes': singular['modes'][:2 * size].tolist(),
               'pod_static': singular['static'][:2 * size].tolist()}
    details.update(info or {})
    return ReducedModel(table=table, shape_table=shape_table, basis=basis,
                        force_moments=force_moments, speed_max=float(speed_max),
                        zeta=float(zeta), info=details)


def system_blocks(model, rows):
    """M, C, K, f blocks of evaluated rows: shapes (m, r, r) x 3 and (m, r)."""
    layout = model.layout
    return tuple(layout.block(rows, name) for name in ('M', 'C', 'K', 'f'))


def output_values(model, rows, q):
    """
    Output deflections (with the residual correction) from evaluated rows and coordinates.

    Parameters
    ----------
    model : ReducedModel
    rows : ndarray, shape (m, L)
    q : ndarray, shape (m, r)

    Returns
    -------
    ndarray, shape (m, len(OUTPUT_NAMES))

    """
    layout = model.layout
    return (np.einsum('mor,mr->mo', layout.block(rows, 'out'), q)
            + layout.block(rows, 'corr'))


# Steps per chunk of periodic_response (bounds its peak memory).
PERIODIC_CHUNK = 60


def periodic_response(model, speed, start_angle=0.0, steps=720, stages=2, blocks=None):
    """
    Periodic steady state of the reduced model at constant crank speed (shooting).

    The one-revolution map of the Radau IIA discretisation is affine in the initial state,
    ``z_T = P z_0 + g``; it is the product of the steps' affine maps (all solved at once),
    and ``z_0 = (I - P)^-1 g`` is the periodic state. At zero speed the static state K^-1 f
    is returned.

    Parameters
    ----------
    model : ReducedModel
    speed : float
        Crank speed [rad/s] (either sign).
    start_angle : float
        Crank angle of the first state [rad].
    steps : int
        Time steps per revolution.
    stages : int
        Radau IIA stages.
    blocks : callable or None
        ``blocks(theta, w, a)`` -> M, C, K, f at crank angles ``theta`` (arrays of shapes
        (m, r, r) x 3 and (m, r)); None: from ``model.evaluate``.

    Returns
    -------
    angles : ndarray, shape (steps + 1,)
        Unwrapped crank angles [rad] from ``start_angle``.
    q, v : ndarray, shape (steps + 1, r)
        Reduced coordinates and velocities.

    """
    size = model.size
    if blocks is None:
        blocks = lambda theta, w, a: system_blocks(model, model.evaluate(theta, w, a))  # noqa
    if speed == 0.0:
        _, _, stiffness, load = blocks(np.atleast_1d(float(start_angle)), 0.0, 0.0)
        q = np.linalg.solve(stiffness[0], load[0])
        return (np.full(steps + 1, float(start_angle)), np.tile(q, (steps + 1, 1)),
                np.zeros((steps + 1, size)))
    method = RadauIIA(stages)
    period = 2.0 * np.pi / abs(speed)
    h = period / steps
    stage_times = (np.arange(steps)[:, None] + method.c[None, :]) * h
    maps = np.empty((steps, 2 * size, 2 * size + 1))
    # In chunks: the table rows of a whole revolution at once would add tens of MB to the
    # peak (and, through malloc's heap, to the node's resident size for good).
    for first in range(0, steps, PERIODIC_CHUNK):
        chunk = slice(first, min(first + PERIODIC_CHUNK, steps))
        count = chunk.stop - chunk.start
        mass, damping, stiffness, load = (
            b.reshape((count, stages) + b.shape[1:])
            for b in blocks(start_angle + speed * stage_times[chunk].ravel(), speed, 0.0))
        maps[chunk] = step_maps(method, np.full(count, h), mass, damping, stiffness, load)
    total = np.concatenate([np.eye(2 * size), np.zeros((2 * size, 1))], axis=1)
    for step in maps:
        total = step[:, :2 * size] @ total
        total[:, -1] += step[:, -1]
    start = np.linalg.solve(np.eye(2 * size) - total[:, :-1], total[:, -1])
    states = compose_affine(maps, start)
    q_all, v_all = states[:, :size], states[:, size:]
    angles = start_angle + speed * h * np.arange(steps + 1)
    return angles, q_all, v_all


# ---------------------------------------------------------------------------------------
# Models of a mechanism: options, cache, and the full-order pieces from core/assembly.py

# Bump when the precompute changes what it stores; older cache files are then rebuilt.
# Points per beam element where link shapes are tabulated (3 elements: 10 points per link).
SHAPE_POINTS_PER_ELEMENT = 3
# Grid points and steps per revolution of the full-order reference.
REFERENCE_GRID = 256
REFERENCE_STEPS = 1440
REFERENCE_POINT_STRIDE = 4
_REFERENCE_CACHE = {}


def model_key(mechanism, options):
    """Cache key of a mechanism's reduced model (hex)."""
    # {'criteria': True} keeps the keys of models cached when the reactions were optional.
    return store.cache_key('reduced-model', MODEL_VERSION, mechanism.key(),
                           options.cache_fields(), {'criteria': True})


def model_for_mechanism(mechanism, options=None, cache_dir=None, use_cache=True):
    """
    The reduced model of a mechanism: from a verified cache file, or built (and cached).

    Parameters
    ----------
    mechanism : Mechanism
    options : ModelOptions or None
    cache_dir : str, Path or None
        Cache directory (None: core.store.default_cache_dir()).
    use_cache : bool
        False builds without reading or writing a cache.

    Returns
    -------
    ReducedModel

    """
    options = options or ModelOptions()
    key = model_key(mechanism, options)
    path = None
    if use_cache:
        directory = store.default_cache_dir() if cache_dir in (None, '') else cache_dir
        path = f'{directory}/{mechanism.name}-{key[:16]}.npz'

    def build():
        return build_model(mechanism, options).to_arrays()

    arrays, meta, _ = store.load_or_build(path, key, build)
    return ReducedModel.from_arrays(arrays, meta)


def build_model(mechanism, options):
    """Precompute the reduced model of a mechanism (full-order pieces from core/assembly.py)."""
    samples = frozen_samples_for(mechanism, options)
    angles = 2.0 * np.pi * np.arange(options.grid_size) / options.grid_size
    forces, criteria_source = reaction_pieces(mechanism, angles)
    return reduce_samples(samples, options.modes, options.static, options.speed_max,
                          mechanism.damping_ratio, forces=forces,
                          info={'options': options.cache_fields(),
                                'mechanism': mechanism.name, 'criteria': criteria_source})


def fe_mechanism(mechanism, options):
    """The mechanism with the element count of ``options`` (if set)."""
    if options.elements_per_link is None:
        return mechanism
    return dataclasses.replace(mechanism, elements_per_link=int(options.elements_per_link))


def modal_damping_matrix(mass, stiffness, zeta):
    """
    ``C_d = M Phi diag(2 zeta omega) Phi^T M`` over all frozen modes (as core/modes.py).

    Parameters
    ----------
    mass, stiffness : ndarray, shape (n, n)
        Mass and symmetric frozen stiffness.
    zeta : float
        Damping ratio of every mode.

    Returns
    -------
    ndarray, shape (n, n)

    """
    eigenvalues, shapes = scipy.linalg.eigh(stiffness, mass)
    left = mass @ shapes
    return (left * (2.0 * zeta * np.sqrt(np.maximum(eigenvalues, 0.0)))) @ left.T


def frozen_samples_for(mechanism, options, points_per_element=SHAPE_POINTS_PER_ELEMENT):
    """
    Full-order affine pieces of the flexible model (core/assembly.py) on the crank-angle grid.

    The frozen eigenproblem and the modal damping use ``K + K_G(w, a)`` as core/modes.py does
    (no centrifugal term); the equations of motion add the rotating-frame terms K_c.

    """
    mechanism = fe_mechanism(mechanism, options)
    linkage = assembly.FlexibleLinkage(mechanism, options)
    angles = 2.0 * np.pi * np.arange(options.grid_size) / options.grid_size
    system = linkage.assemble(angles)
    frozen = {'1': system.stiffness + system.geometric['1'], 'a': system.geometric['a'],
              'w2': system.geometric['w2']}
    stiffness = {'1': frozen['1'], 'a': system.coupling['a'] + system.geometric['a'],
                 'w2': system.coupling['w2'] + system.geometric['w2']}
    positions, operator = linkage.shape_operator(angles, points_per_element)
    zeta = mechanism.damping_ratio

    def damping(k, w):
        stiff = frozen['1'][k] + w * w * frozen['w2'][k]
        return modal_damping_matrix(system.mass[k], stiff, zeta)

    return FrozenSamples(mass=system.mass, gyroscopic=system.gyroscopic, stiffness=stiffness,
                         load=dict(system.load), outputs=linkage.output_operator(angles),
                         damping=damping, shape_operator=operator, shape_positions=positions,
                         frozen=frozen)


def reaction_pieces(mechanism, angles):
    """
    Rigid-body joint reactions F = F_1 + a F_a + w^2 F_w2 and dF/dtheta on the grid.

    From core/dynamics.py (Newton-Euler, reactions across each bearing with the mechanism's
    joint-mass split; spring and gravity in F_1).

    Returns
    -------
    forces : dict
        As :func:`reduce_samples` takes them.
    source : str
        Where the reactions come from.

    """
    pieces = dynamics.reaction_pieces(mechanism, angles)
    forces = {'force': pieces['force'], 'force_rate': pieces['force_rate']}
    return forces, 'rigid-body Newton-Euler reactions (core/dynamics.py)'


def reference_response(mechanism, options, speed, angles, steps=REFERENCE_STEPS):
    """
    Full-order periodic response at constant crank speed, at given crank angles.

    The reference is core/simulate.py's full-order shooting (every FE DOF, coefficient
    matrices assembled at every Radau stage) with ``steps`` steps and one output per
    REFERENCE_POINT_STRIDE steps, interpolated to ``angles`` by a periodic cubic spline.
    Where core/simulate.py is not in the checkout, the same equations are solved here without
    reduction (identity basis, tables on a REFERENCE_GRID-point grid): the two agree to
    4e-5 (flexible bearings) and 1e-6 (rigid) relative RMS at 269 and 391 rpm.

    Parameters
    ----------
    mechanism : Mechanism
    options : ModelOptions
        Only the physical options (elements, rigid crank, bearings, geometric stiffness).
    speed : float
        Crank speed [rad/s], non-zero.
    angles : ndarray, shape (m,)
        Crank angles [rad].
    steps : int
        Steps per revolution.

    Returns
    -------
    dict
        'lever_tip', 'coupler_mid': ndarray (m, 2) [m]; 'source': str.

    """
    key = (mechanism.key(), dataclasses.astuple(options), float(speed), steps)
    if key not in _REFERENCE_CACHE:
        _REFERENCE_CACHE.clear()
        _REFERENCE_CACHE[key] = _reference_revolution(mechanism, options, speed, steps)
    outputs, source = _REFERENCE_CACHE[key]
    points = outputs.shape[0]
    coef = periodic_cell_coefficients(outputs)
    phase = np.mod(np.asarray(angles, dtype=float) * np.sign(speed), 2.0 * np.pi) \
        / (2.0 * np.pi) * points
    k = np.minimum(np.floor(phase).astype(int), points - 1)
    t = phase - k
    values = np.einsum('mp,mpc->mc', t[:, None] ** np.arange(CELL_POWERS), coef[k])
    return {'lever_tip': values[:, :2], 'coupler_mid': values[:, 2:], 'source': source}


def _reference_revolution(mechanism, options, speed, steps):
    """Outputs (points, 4) over one revolution from crank angle 0, and their source."""
    linkage = assembly.FlexibleLinkage(fe_mechanism(mechanism, options), options)
    result = simulate.periodic_response(linkage, speed, method='full', steps=steps,
                                        points=steps // REFERENCE_POINT_STRIDE)
    return result.outputs, 'core.simulate full order'


def unreduced_revolution(mechanism, options, speed, steps=REFERENCE_STEPS):
    """
    Outputs (points, 4) over one revolution from the unreduced tables, and their source.

    The tables of :func:`reduce_samples` with every DOF kept, integrated as the reduced model
    is: a check of the tables and the integrator against core.simulate's full order.
    """
    full_options = dataclasses.replace(options, grid_size=REFERENCE_GRID, modes=1, static=0)
    samples = frozen_samples_for(mechanism, full_options)
    model = reduce_samples(samples, samples.dofs, 0, max(abs(speed), options.speed_max),
                           mechanism.damping_ratio)
    grid, q, _ = periodic_response(model, speed, start_angle=0.0, steps=steps)
    outputs = output_values(model, model.evaluate(grid, speed, 0.0), q)[:-1]
    return outputs[::REFERENCE_POINT_STRIDE], 'unreduced tables'
