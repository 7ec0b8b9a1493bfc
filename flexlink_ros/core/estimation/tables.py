"""
The per-sample step's tables, built once per model from its reduced table.

Node tables (cubic Hermite data) for M, C and [K | f], power-form tables for the output
operator and the joint reactions, and the coefficient stacks G(h) of the 2-stage Radau IIA
step; :func:`system_blocks` and :func:`quasi_static_peak` read M, C, K and f back from them.
"""

import math

import numpy as np

from ..integrators import RADAU_TABLEAUX
from ..numerics import TWO_PI
from ..reduction.cells import CELL_POWERS, monomial_values, MONOMIALS
from ..reduction.model import cell_groups
from ..reduction.second_order_tables import SecondOrderForms
from ..reduction.soft_tables import SoftLift
from ...names import OUTPUT_NAMES

POWERS = (-2, -1, 0, 1, 2)   # G(h) is a Laurent polynomial in h
FIRST_MC = 1                 # M and C start at monomial 1
GROUPS_C = 4                 # C: monomials 1, w2, w, w4
GROUPS_KF = 3                # K, f: monomials a, 1, w2
GROUPS_KF_DAMPED = 4         # ... and w: stiffness damping's D_beta = w Kb1 in K
# Speeds 0 ... speed_max at which the quasi-static deflection is evaluated.
QUASI_STATIC_SPEEDS = 5


def hermite_basis(t):
    """Return the cubic Hermite basis h00, h10, h01, h11 at t in [0, 1] (floats or arrays)."""
    t2 = t * t
    t3 = t2 * t
    h01 = t2 * (3.0 - 2.0 * t)
    return 1.0 - h01, t - 2.0 * t2 + t3, h01, t3 - t2


def _check_layout(model, stages):
    """Refuse a model (or stage count) the step tables are not written for."""
    if stages != 2:
        raise ValueError('the streaming step is written for 2-stage Radau IIA')
    if MONOMIALS[:5] != ('a', '1', 'w2', 'w', 'w4'):
        raise ValueError('monomial order changed: update _StepTables')
    if CELL_POWERS != 4:
        raise ValueError('the step tables are written for cubic cells')
    for name, stop in (('M', 1 + GROUPS_C), ('C', 1 + GROUPS_C),
                       ('K', GROUPS_KF_DAMPED), ('f', GROUPS_KF)):
        if np.any(_block(model, name)[:, 4 * stop:] != 0.0):
            raise ValueError(f'{name} uses monomials beyond the first {stop}: '
                             'update _StepTables')


def _block(model, name, rows=None):
    """Block ``name`` of the model's table, rows ``rows``: (cells, rows, width)."""
    table = model.table
    n_cells, n_rows = table.shape[:2]
    rows = slice(0, n_rows) if rows is None else rows
    return model.layout.block(table[:, rows], name).reshape(n_cells, rows.stop - rows.start, -1)


def _rows_used(model, name, first=0):
    """Table rows of block ``name`` up to its last nonzero one (at least 1)."""
    used = np.flatnonzero(np.any(_block(model, name)[:, first:] != 0.0, axis=(0, 2)))
    return int(used[-1]) + 1 if used.size else 1


def _nodes(model, name, first_group, groups):
    """Node values and slopes (node, group * 2 + V/S, width) of cells' cubics."""
    n_cells = model.table.shape[0]
    cells = _block(model, name, slice(4 * first_group, 4 * (first_group + groups)))
    cells = cells.reshape(n_cells, groups, 4, -1)
    return cells[:, :, :2].reshape(n_cells, 2 * groups, -1)


def kf_groups(model):
    """
    Monomial groups of the [K | f] node table: 3 (a, 1, w2), or 4 with stiffness damping.

    A model built with stiffness-proportional damping (core/fe/stiffness_damping.py) has
    ``D_beta = w Kb1`` in K's monomial-w rows; without it those rows are zero and the table
    keeps its 3 groups (the same bytes and the same step as before).
    """
    return GROUPS_KF_DAMPED if _rows_used(model, 'K') > 4 * GROUPS_KF else GROUPS_KF


def build_node_tables(model):
    """Return (mass_groups, mass, damping, kf): the node tables of M, C and [K | f]."""
    mass_groups = -(-(_rows_used(model, 'M', 4 * FIRST_MC)) // 4)
    # M and C in float32: a sample reads 31 % fewer bytes (the table reads are about
    # a third of the step) and the outputs move by 2e-8 of their size; K and f stay in
    # float64 (float32 there moves them by 1e-3: the static directions are stiff).
    mass = np.ascontiguousarray(_nodes(model, 'M', FIRST_MC, mass_groups), dtype=np.float32)
    damping = np.ascontiguousarray(_nodes(model, 'C', FIRST_MC, GROUPS_C), dtype=np.float32)
    groups = kf_groups(model)
    kf = np.ascontiguousarray(np.concatenate(
        [_nodes(model, 'K', 0, groups), _nodes(model, 'f', 0, groups)], axis=2))
    return mass_groups, mass, damping, kf


def build_output_tables(model):
    """Return (out_rows, out, joint): the power-form output operator and joint tables."""
    r = model.size
    n_cells = model.table.shape[0]
    out_rows = max(_rows_used(model, 'out'), _rows_used(model, 'corr'))
    rows = slice(0, out_rows)
    outputs = len(OUTPUT_NAMES)
    out = np.zeros((n_cells, out_rows, outputs, r + 1))
    out[..., :r] = _block(model, 'out', rows).reshape(n_cells, out_rows, outputs, r)
    out[..., r] = _block(model, 'corr', rows)
    joint = np.ascontiguousarray(np.concatenate(
        [_block(model, name) for name in ('force', 'force_dot', 'rms2')], axis=2))
    return out_rows, out.reshape(n_cells, out_rows, -1), joint


def _step_matrix(a):
    """Coefficients of A D2^-1 (the block matrix on dz) per power of h: (powers, 2, 2, 3)."""
    a2 = a @ a
    npow = len(POWERS)
    zero = POWERS.index(0)
    big = np.zeros((npow, 2, 2, 3))            # block matrix on the stage values M, C, K
    for i in range(2):
        big[zero, i, i, 0] = 1.0
        for j in range(2):
            big[zero + 1, i, j, 1] = a[i, j]
            big[zero + 2, i, j, 2] = a2[i, j]
    det = a2[1, 0] * a[1, 1] - a2[1, 1] * a[1, 0]
    d_inv = np.zeros((npow, 2, 2))             # D2^-1
    d_inv[zero - 2, 0, 0] = a[1, 1] / det
    d_inv[zero - 1, 0, 1] = -a2[1, 1] / det
    d_inv[zero - 2, 1, 0] = -a[1, 0] / det
    d_inv[zero - 1, 1, 1] = a2[1, 0] / det
    matrix = np.zeros((npow, 2, 2, 3))         # A D2^-1
    for p1 in range(npow):
        for p2 in range(npow):
            p = p1 + p2 - zero
            if 0 <= p < npow:
                matrix[p] += np.einsum('ijm,jk->ikm', big[p1], d_inv[p2])
    return matrix


def build_step_coefficients(stages=2):
    """
    Return the coefficient stack G(h) per slot parity: (2, powers, 64).

    Rows [A D2^-1 | right-hand-side operator on (q, v)] with stage 1 in the other slot and
    stage 2 (the sample) in slot ``parity``.
    """
    a, c = RADAU_TABLEAUX[stages]
    npow = len(POWERS)
    zero = POWERS.index(0)
    matrix = _step_matrix(a)
    operator = np.zeros((npow, 2, 2, 3))       # on (q, v); f is added separately
    for i in range(2):
        operator[zero, i, 0, 2] = -1.0                     # -K q
        operator[zero, i, 1, 1] = -1.0                     # -C v
        operator[zero + 1, i, 1, 2] = -c[i]                # -c_i h K v
    operator[1:, :, 1, :] += matrix[:-1, :, 0, :]          # + h (A D2^-1)_{i0} on v
    rows = np.concatenate([matrix, operator], axis=2)      # (npow, 2, 4, 3)
    g_stack = np.zeros((2, npow, 2, 4, 2, 4))
    for parity in (0, 1):
        # Stage 1 in the other slot, stage 2 (the sample) in slot `parity`.
        for i, slot in ((0, 1 - parity), (1, parity)):
            g_stack[parity, :, i, :, slot, :3] = rows[:, i]
    return g_stack.reshape(2, npow, 64)


class _StepTables:
    """
    Tables and coefficient stacks of the per-sample step (built once per model).

    M, C and [K | f] are kept at the grid nodes as cubic Hermite data: per monomial the
    node's value V and slope S (d/dt, cell units) of the model's periodic cubic spline (see
    core/reduction/model.py), which is C1, so cell k's cubic is exactly
    ``h00(t) V_k + h10(t) S_k + h01(t) V_k+1 + h11(t) S_k+1``. A cell then reads two rows
    per monomial of its own and two of the next node, which the next cell reads again:
    streaming through the cells (a new cell's tables are not in the core's own caches at
    most sample rates) reads half the bytes of the per-cell power form, and the tables take
    half the memory.
    ``mass`` M (monomial 1), ``damping`` C (1, w2, w, w4) and ``kf`` [K | f] (a, 1, w2):
    node x (monomial, V/S) x width. ``out`` (the output operator [O | corr], outputs x
    (r + 1), leading rows used) and ``joint`` [reactions F (joints x 2), their time
    derivative (joints x 2), squared cycle-RMS reaction (joints)] stay per cell in power form
    (rows ``monomial * 4 + power``; small, read once per sample). With stiffness damping
    ``kf`` has a fourth group, w (``kf_groups``).
    ``second`` (a model of order 2) evaluates the second-order outputs the record adds to the
    deflections (:class:`~core.reduction.second_order_tables.SecondOrderForms`); ``second_packed``
    are its arrays as the compiled step takes them (None for order 1).
    Two samples' [M, C, K, F] (F an r x r block holding f in its first r entries) in
    alternating slots times a 8 x 8 coefficient matrix G(h) give, in one product, the
    Radau IIA block matrix and the right-hand-side operator on (q, v).

    The unknowns are the state increment dz = (dq, dv) rather than the stage accelerations X:
    with ``dz = (D2 (x) I) X + (h v, 0)`` and ``D2 = [[h^2 (aa)_21, h^2 (aa)_22],
    [h a_21, h a_22]]`` (invertible for Radau IIA), the matrix becomes ``A (D2^-1 (x) I)`` and
    the operator gains ``h`` times its first block column, so the solve returns dz directly.
    G(h) is a Laurent polynomial in h (powers -2..2).
    """

    POWERS = POWERS
    FIRST_MC = FIRST_MC
    GROUPS_C = GROUPS_C
    GROUPS_KF = GROUPS_KF

    def __init__(self, model, stages=2):
        _check_layout(model, stages)
        self.size, self.record_size = model.step_size, model.size
        self.lift = None
        if model.soft is None:
            self.mass_groups, self.mass, self.damping, self.kf = build_node_tables(model)
        else:
            self.lift = SoftLift(model.soft)
            self.mass_groups, self.mass, self.damping, self.kf = 1, *(
                model.soft[f'soft_{name}'] for name in ('mass', 'damping', 'kf'))
        self.kf_groups = self.kf.shape[1] // 2
        self.out_rows, self.out, self.joint = build_output_tables(model)
        self.g_stack = build_step_coefficients(stages)
        # The compiled step's convention: the sample in slot 0, stage 1 in slot 1.
        self.g0 = np.ascontiguousarray(self.g_stack[0])
        self._bounds, self._peaks = {}, {}
        self.second = self.second_packed = None
        if model.second_order is not None:
            self.second = SecondOrderForms(model.second_order)
            self.second_packed = self.second.packed()

    def deflection_bound(self, model, safety_factor):
        """
        Return ``safety_factor`` / (2 zeta) times :func:`quasi_static_peak` (computed once).

        Parameters
        ----------
        model : ReducedModel
            The model of these tables (its speed range and damping ratio key the cache).
        safety_factor : float
            Factor on the resonant amplification 1 / (2 zeta).

        """
        zeta = float(model.zeta)
        key = (model.speed_max, zeta)
        if key not in self._bounds:
            bound = math.inf
            if zeta > 0.0:
                bound = safety_factor / (2.0 * zeta) * self.quasi_static_peak(model)
            # No load at all (or a singular K somewhere): no bound rather than a zero one.
            self._bounds[key] = bound if math.isfinite(bound) and bound > 0.0 else math.inf
        return self._bounds[key]

    def know_quasi_static_peaks(self, speeds, peaks):
        """Take :func:`quasi_static_peak` values found before (a cache file) at ``speeds``."""
        for top, peak in zip(np.asarray(speeds, dtype=float).tolist(),
                             np.asarray(peaks, dtype=float).tolist()):
            self._peaks[top] = peak

    def quasi_static_peak(self, model, speed_max=None):
        """Return :func:`quasi_static_peak` of the model of these tables (once per speed)."""
        top = float(model.speed_max if speed_max is None else speed_max)
        if top not in self._peaks:
            self._peaks[top] = quasi_static_peak(model, self, top)
        return self._peaks[top]

    def record(self, weights, k, z, out):
        """
        Write a sample's record, RECORD_SIZE values, from the row weights at cell k and z.

        The numpy twin of the compiled step's record.

        Parameters
        ----------
        weights : ndarray
            Row weights of the power-form tables (monomial times t^p).
        k : int
            Grid cell.
        z : ndarray
            State [q, v, 1].
        out : ndarray
            The record, written in place.

        """
        r = self.record_size
        operator = np.dot(weights[:self.out_rows], self.out[k]).reshape(-1, r + 1)
        outputs = operator.shape[0]
        np.dot(operator[:, :r], z[:r], out=out[:outputs])
        out[:outputs] += operator[:, r]
        out[outputs:2 * outputs] = operator[:, r]
        np.dot(weights, self.joint[k], out=out[2 * outputs:])
        if self.second is not None:
            # Monomial 1's row weights are the powers of t (MONOMIALS[1] == '1').
            scalars = np.dot(weights[CELL_POWERS:2 * CELL_POWERS], self.second.scalars[k])[None]
            out[:outputs] += self.second.outputs(
                scalars, self.second.sums(scalars, z[None, :r]))[0]


def step_tables(model):
    """Build the per-sample step's tables of a model (to share between estimators: replay)."""
    return _StepTables(model)


def system_blocks(model, tables, theta, w, a):
    """
    Return M, C, K, f at crank angles ``theta`` (array), speed ``w``, acceleration ``a``.

    From the step tables (the rows each block uses), so nothing of the model's full table
    is needed (``model`` may have been released).

    Parameters
    ----------
    model : ReducedModel
        The model of ``tables`` (its grid and size).
    tables : _StepTables
        :func:`step_tables` of the model.
    theta : array_like
        Crank angles [rad].
    w : float
        Crank speed [rad/s].
    a : float
        Crank acceleration [rad/s^2].

    """
    r = tables.size
    theta = np.asarray(theta, dtype=float)
    cells, t = model.cell(theta)
    basis = np.stack(hermite_basis(t), axis=-1)
    monomials = np.stack(np.broadcast_arrays(*monomial_values(
        np.full(theta.size, float(w)), np.full(theta.size, float(a)))), axis=-1)
    # (angle, monomial, node k / k + 1, V / S)
    weights = (monomials[:, :, None] * basis[:, None, :]).reshape(theta.size, -1, 2, 2)
    mass = np.empty((theta.size, r * r))
    damping = np.empty((theta.size, r * r))
    kf = np.empty((theta.size, r * r + r))
    first, after = tables.FIRST_MC, tables.FIRST_MC + tables.mass_groups
    for k, group in cell_groups(cells):
        k1 = (k + 1) % model.grid_size
        for out, table, groups in ((mass, tables.mass, slice(first, after)),
                                   (damping, tables.damping,
                                    slice(first, first + tables.GROUPS_C)),
                                   (kf, tables.kf, slice(0, tables.kf_groups))):
            node = weights[group, groups]
            out[group] = (node[:, :, 0].reshape(group.size, -1) @ table[k]
                          + node[:, :, 1].reshape(group.size, -1) @ table[k1])
    shape = (theta.size, r, r)
    return (mass.reshape(shape), damping.reshape(shape), kf[:, :r * r].reshape(shape),
            kf[:, r * r:])


def quasi_static_peak(model, tables, speed_max=None):
    """
    Return the largest |deflection component| of the quasi-static response over the grid [m].

    K q = f at every grid node, at constant speeds 0 ... speed_max (QUASI_STATIC_SPEEDS
    of them) and zero acceleration: batched solves of the step tables. (At accel_limit
    the axial inertia loads take the geometric stiffness of the node's default model to
    buckling, K indefinite: no bound of anything. Acceleration loads are left to the
    estimator's safety factor.)

    Parameters
    ----------
    model : ReducedModel
        The model of ``tables``.
    tables : _StepTables
        :func:`step_tables` of the model.
    speed_max : float or None
        The top speed [rad/s] (default: the model's ``speed_max``).

    """
    r = tables.record_size
    theta = np.arange(model.grid_size) / (model.grid_size / TWO_PI)
    operator_rows = np.zeros(tables.out_rows)
    peak = 0.0
    top = float(model.speed_max if speed_max is None else speed_max)
    for w in np.linspace(0.0, top, QUASI_STATIC_SPEEDS).tolist():
        _, _, stiffness, load = system_blocks(model, tables, theta, w, 0.0)
        q = np.linalg.solve(stiffness, load[..., None])[..., 0]
        if tables.lift is not None:
            q = tables.lift.nodes(q, w)
        # Power 0 of each monomial (a, 1, w2, w, w4, wa, w3): the node's operator.
        monomials = (0.0, 1.0, w * w, w, w ** 4, 0.0, w ** 3)
        operator_rows[0::4] = monomials[:operator_rows[0::4].size]
        operator = np.einsum('k,nkj->nj', operator_rows, tables.out).reshape(
            theta.size, -1, r + 1)
        deflection = np.einsum('nor,nr->no', operator[..., :r], q) + operator[..., r]
        peak = max(peak, float(np.max(np.abs(deflection))))
    return peak
