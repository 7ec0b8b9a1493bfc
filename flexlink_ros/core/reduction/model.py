"""
Reduced model of the flexible linkage for streaming: one precompute for every speed.

The full-order frozen system of Cho, Park & Lee (1992), Eq. 22, at crank angle theta, speed w
and acceleration a is ::

    M(th) q'' + (w G(th) + C_d(th, w)) q' + (K_0(th) + a K_a(th) + w^2 K_w2(th)) q
        = f_0(th) + a f_a(th) + w^2 f_w2(th)

(G: Coriolis terms; K: elastic, geometric (Eq. A.4) and the rotating-frame terms; f: rigid-body
inertia and gravity loads; C_d: modal damping zeta on the frozen modes). Everything but C_d is
affine in (w, w^2, a), so its pieces are tabulated once over a periodic grid of crank angles.

Basis (:mod:`.basis`). One constant basis V (n x r) serves the whole cycle. A constant V
makes the reduced matrices V^T X(theta) V smooth in theta (no mode ordering or sign flips where
the coupler and lever modes veer past each other near 391 rpm), adds no dPhi/dt terms, and lets
the modal state run through grid cells without jumps.

Residual flexibility. What V misses of the quasi-static response, ``O (K^-1 - V K_r^-1 V^T) f``
(O: output operator), is tabulated too (:mod:`.build`); it is added to the outputs and its size
is the estimator's per-sample error indicator.

Damping. C_d(theta, w) of the full model is projected, ``V^T C_d V``, at several speeds and
fitted by a quadratic in w^2 (exact at w = 0 and at the fitted speeds).

Interpolation (:mod:`.cells`). Every tabulated quantity is a periodic cubic spline in theta;
per grid cell it is stored as the coefficients of ``t^p`` (t in [0, 1) across the cell) times
each monomial of :data:`MONOMIALS`, so one dot product of 4 x len(MONOMIALS) weights with one
cell's table gives every matrix, load and output operator at (theta, w, a); the streaming step
splits that product by block to read only the monomial rows each block uses.

This module holds the model itself (:class:`ReducedModel`, its table layout and readers);
:mod:`.build` makes one from full-order samples, :mod:`.mechanism_model` for a mechanism (cached in
:mod:`.store`), :mod:`.periodic` gives its periodic response, :mod:`.reference` the full-order
reference it is checked against.
"""

import dataclasses

import numpy as np

from .cells import CELL_POWERS, monomial_values
from ...names import JOINT_NAMES, OUTPUT_NAMES


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
        Joints with criteria data (len(JOINT_NAMES)).

    """

    def __init__(self, size, outputs=len(OUTPUT_NAMES), joints=len(JOINT_NAMES)):
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
    nonlinearity : dict of str to ndarray, or None
        Tables of the validity indicator (:mod:`.nonlinearity_tables`); None for a model
        built without them.
    second_order : dict of str to ndarray or None
        Tables of the second-order outputs (:mod:`.second_order_tables`, names ``second_*``)
        of a model of order 2; None: the linear outputs only (order 1).
    soft : dict of str to ndarray or None
        The step's tables on the soft basis (:mod:`.soft_tables`, names ``soft_*``): the
        estimator steps p coordinates and lifts them to the r of this model; None: it steps
        all r.
    dynamic_second_order : dict of str to ndarray or None
        Tables of the dynamic second-order pass (:mod:`.second_order_dynamic_tables`, names
        ``dynamic_*``) of a model built with ``second_order='dynamic'``; None otherwise.

    """

    table: np.ndarray
    shape_table: np.ndarray
    basis: np.ndarray
    force_moments: np.ndarray
    speed_max: float
    zeta: float
    info: dict = dataclasses.field(default_factory=dict)
    nonlinearity: dict = None
    second_order: object = None
    soft: object = None
    dynamic_second_order: object = None

    @property
    def grid_size(self):
        """Return the number of grid cells N."""
        return self.table.shape[0]

    @property
    def size(self):
        """Return the reduced size r."""
        return self.basis.shape[1]

    @property
    def step_size(self):
        """Return the coordinates the estimator steps: p with the soft basis, else r."""
        if self.soft is None:
            return self.size
        return self.soft['soft_phi'].shape[2] // self.size

    @property
    def layout(self):
        """Return the column layout of ``table``."""
        return TableLayout(self.size)

    @property
    def nbytes(self):
        """Return the memory of the arrays [bytes]."""
        second = sum(a.nbytes for a in ({**(self.second_order or {}),
                                         **(self.dynamic_second_order or {}),
                                         **(self.soft or {})}).values())
        return (self.table.nbytes + self.shape_table.nbytes + self.basis.nbytes
                + self.force_moments.nbytes + second
                + sum(a.nbytes for a in (self.nonlinearity or {}).values()))

    def to_arrays(self):
        """Arrays and metadata for :func:`core.reduction.store.save_cache`."""
        arrays = {'table': self.table, 'shape_table': self.shape_table, 'basis': self.basis,
                  'force_moments': self.force_moments, **(self.nonlinearity or {}),
                  **(self.second_order or {}), **(self.dynamic_second_order or {})}
        meta = {'speed_max': self.speed_max, 'zeta': self.zeta, 'info': self.info}
        return arrays, meta

    @classmethod
    def from_arrays(cls, arrays, meta):
        """Inverse of :meth:`to_arrays`."""
        second = {name: array for name, array in arrays.items() if name.startswith('second_')}
        return cls(table=arrays['table'], shape_table=arrays['shape_table'],
                   basis=arrays['basis'], force_moments=arrays['force_moments'],
                   speed_max=float(meta['speed_max']), zeta=float(meta['zeta']),
                   info=dict(meta.get('info', {})), second_order=second or None,
                   dynamic_second_order={name: array for name, array in arrays.items()
                                         if name.startswith('dynamic_')} or None,
                   nonlinearity={name: array for name, array in arrays.items()
                                 if name.startswith('nonlinearity_')} or None)

    @property
    def order(self):
        """Return 2 when the model carries the second-order tables, else 1."""
        return 1 if self.second_order is None else 2

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
        # np.tensordot's own product (the same doubles) without its axis bookkeeping
        powers = (float(t) ** np.arange(CELL_POWERS)).reshape(1, CELL_POWERS)
        values = np.dot(powers, coef.reshape(CELL_POWERS, -1)).reshape(coef.shape[1:])
        return values[..., -1], values[..., :-1] @ q


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
        The model the rows were evaluated from.
    rows : ndarray, shape (m, L)
        Rows of ``model.evaluate``.
    q : ndarray, shape (m, r)
        Reduced coordinates at the same samples.

    Returns
    -------
    ndarray, shape (m, len(OUTPUT_NAMES))
        Ground-frame deflections of the output points [m].

    """
    layout = model.layout
    return (np.einsum('mor,mr->mo', layout.block(rows, 'out'), q)
            + layout.block(rows, 'corr'))
