"""
The dynamic second-order pass in the streaming step (numpy prototype, issue 14 item 2).

The full-order reference (:mod:`core.fe.second_order_dynamic`) solves, after the linear pass,
one more periodic linear problem of the same model, ``M U2'' + C U2' + K U2 = F2(U1)``, loaded
by the second-order terms of the strain energy on the linear state, and outputs the linear
output operator of U1 + U2. Here the same runs sample by sample on the reduced model: a second
state z2 = (q2, q2') advanced by the SAME 2-stage Radau IIA step as the linear state (the same
M, C, K at the same stage times, so the stage system's LU factors of the linear step serve
both; only the right-hand side differs), loaded by ``f2 = V^T F2(V q)`` at the two stages
(:class:`core.reduction.dynamic_second_order_tables.DynamicLoad`). The stages' linear q comes
from the linear step's own stage values (:func:`stage_positions`).

Outputs. On a model of order 2 (``keep_quasi_static``) the record keeps the quasi-static
correction and adds the output operator on ``q2 - K_r^-1 f2_eigenstrain`` (the mode-
acceleration split: the basis cannot hold the chord shortening, which the quasi-static forms
give exactly; q2 adds the rest). On a model of order 1 the outputs are linear + O q2 (the
full-order pass's 'total'), which misses the lever tip by 68-92 % for that reason.

Two things the reduced state does not hold, measured against the full-order pass (391 rpm,
gravity, rigid crank and bearings, 8 elements per link; studies/dynamic_second_order_study.py):
the static axial stretch (the elastic axial force of V q alone is off by the rigid-body force
F_r, 25 N against 1.5 N at 4 elements per link: the reference is therefore the axial force of
the reduced static response K_r^-1 f_r at each stage), and, on the default basis (4 modes +
2 static, r = 6), the dynamic increment itself (coupler mid-point +3.5 / +5.4 % p2p, worse
than the quasi-static +3.4 / +4.7 %); 8 + 4 (r = 12) brings it to +0.6 / +1.0 %.
"""

import numpy as np
from scipy.linalg import lapack

from . import native
from .step import NumpyStep, STAGE1
from .streaming import StreamingEstimator
from .tables import step_tables
from ..integrators import RADAU_TABLEAUX
from ..numerics import TWO_PI

RADAU_A = np.asarray(RADAU_TABLEAUX[2][0], dtype=float)


def stage_positions(h, q, v, dq, dv):
    """
    Radau IIA stage-1 position of the linear state from the step's increment (dq, dv).

    With stage accelerations X_j, ``dq = h v + h^2 sum_j (A^2)_2j X_j`` and
    ``dv = h sum_j A_2j X_j``; solving for X gives ``Q_1 = q + c_1 h v + h^2 sum_j (A^2)_1j X_j``
    (the stage values the stage equations M X + C V + K Q = f were solved for).
    """
    a, a2 = RADAU_A, RADAU_A @ RADAU_A
    d2 = np.array([[h * h * a2[1, 0], h * h * a2[1, 1]], [h * a[1, 0], h * a[1, 1]]])
    x = np.linalg.solve(d2, np.vstack([dq - h * v, dv]))
    return q + STAGE1 * h * v + h * h * (a2[0, 0] * x[0] + a2[0, 1] * x[1])


class DynamicSecondOrderStep(NumpyStep):
    """
    :class:`NumpyStep` with the reduced dynamic second-order state z2 = (q2, v2).

    Parameters
    ----------
    model : ReducedModel
        The reduced model.
    tables : _StepTables
        Its step tables.
    load : DynamicLoad
        The model's dynamic second-order load tables.
    keep_quasi_static : bool
        Keep the quasi-static correction of an order-2 model's record (False: a model of order
        1 is expected, the outputs are linear(q) + O q2).
    static_axial : bool
        Take the elastic axial force against the reduced static response K_r^-1 f_r at each
        stage (True) or against the tabulated rigid-body force F_r (False: the basis misses
        the static axial stretch, so that is off by about F_r).

    """

    def __init__(self, model, tables, load, keep_quasi_static=False, static_axial=True):
        super().__init__(model, tables)
        self.static_axial = bool(static_axial)
        if tables.second is not None and not keep_quasi_static:
            raise ValueError('the dynamic pass replaces the quasi-static correction: '
                             'use a model of order 1')
        self.load = load
        self.keep_quasi_static = bool(keep_quasi_static)
        self.z2 = np.zeros(2 * model.size)
        # K_r^-1 f2 at the last sample: the part of q2 the quasi-static correction holds.
        self.static2 = np.zeros(model.size)

    def start(self, q0, v0, crank, record):
        """Set the linear state (q2 = 0) and write its record (see NumpyStep.start)."""
        self.z2[:] = 0.0
        self.static2[:] = 0.0
        super().start(q0, v0, crank, record)

    def advance(self, rows, states, records):
        """Advance both states through sample rows; records add the output operator on q2."""
        rows = rows.reshape(-1, native.ROW_SIZE)
        every = records.ndim == 2
        for n, row in enumerate(rows):
            one = records[n] if every else records
            super().advance(row, states[n:n + 1] if states.size else states,
                            one if every or n == len(rows) - 1 else np.empty_like(one))
            if every or n == len(rows) - 1:
                self.add_second(row[2], row[3], row[4], one)

    def add_second(self, angle, speed, accel, record):
        """Add the output operator on q2 at a crank state to a record's deflections."""
        r = self.tables.size
        weights, _, k = self.evaluate(angle, speed, accel)
        operator = np.dot(weights[:self.tables.out_rows], self.tables.out[k]).reshape(-1, r + 1)
        record[:operator.shape[0]] += operator[:, :r] @ (self.z2[:r] - self.static2)

    def _step(self, h, angle, speed, accel, advance):
        """One Radau IIA step of z and of z2 with one LU factorisation of the stage system."""
        tables = self.tables
        r = tables.size
        previous = self.previous.tolist()
        stage = ((previous[0] + STAGE1 * advance) % TWO_PI,
                 previous[1] + STAGE1 * (speed - previous[1]),
                 previous[2] + STAGE1 * (accel - previous[2]))
        parity = self._load_stages(h, angle, speed, accel, advance)
        inv = 1.0 / h
        g = np.dot(np.array((inv * inv, inv, 1.0, h, h * h)), tables.g_stack[parity])
        blocks = np.dot(g.reshape(8, 8), self._stored.reshape(8, r * r))
        system_t = blocks.reshape(2, 4, r, r).transpose(1, 3, 0, 2).reshape(4 * r, 2 * r)
        z, stored = self.z, self._stored
        loads = np.concatenate((stored[1 - parity, 3, :r], stored[parity, 3, :r]))
        lu, pivots, info = lapack.dgetrf(system_t[:2 * r].T)
        increment, info2 = lapack.dgetrs(lu, pivots, np.dot(z[:2 * r], system_t[2 * r:]) + loads)
        if info != 0 or info2 != 0 or not np.all(np.isfinite(increment)):
            raise ValueError('singular or non-finite Radau step')
        q, v = z[:r].copy(), z[r:2 * r].copy()
        z[:2 * r] += increment
        q1 = stage_positions(h, q, v, increment[:r], increment[r:])
        statics = [np.linalg.solve(stored[slot, 2].reshape(r, r), stored[slot, 3, :r])
                   if self.static_axial else None for slot in (1 - parity, parity)]
        sample_load = self.load.load(z[:r], angle, speed, accel, statics[1])
        loads2 = np.concatenate((self.load.load(q1, *stage, statics[0])[0], sample_load[0]))
        if self.keep_quasi_static:
            self.static2 = np.linalg.solve(stored[parity, 2].reshape(r, r), sample_load[1])
        increment2, info2 = lapack.dgetrs(lu, pivots, np.dot(self.z2, system_t[2 * r:]) + loads2)
        if info2 != 0 or not np.all(np.isfinite(increment2)):
            raise ValueError('non-finite second-order step')
        self.z2 += increment2


def steady_revolution(model, load, speed, samples=720, revolutions=10, keep_quasi_static=True):
    """
    Stream the dynamic step at constant crank speed: outputs over its last revolution.

    The linear state starts on the periodic orbit (shooting, as the estimator's warm start),
    q2 at rest; the pass's transient decays with the modal damping over ``revolutions``.

    Parameters
    ----------
    model : ReducedModel
        The reduced model.
    load : DynamicLoad
        The model's dynamic load tables.
    speed : float
        Crank speed [rad/s].
    samples, revolutions : int
        Samples per revolution (crank angles 2 pi k / samples) and revolutions streamed.
    keep_quasi_static : bool
        True (``model`` of order 2): outputs linear + quasi-static + O (q2 - K_r^-1
        f2_eigenstrain); False (order 1): linear + O q2.

    Returns
    -------
    angles : ndarray, shape (samples,)
        Crank angles of the last revolution, from 0 [rad].
    outputs : ndarray, shape (samples, 4)
        Lever tip and coupler mid-point deflections [m].

    """
    shared = step_tables(model)
    q0, v0 = StreamingEstimator(model, compiled=False,
                                step_tables=shared).periodic_state(0.0, speed)
    step = DynamicSecondOrderStep(model, shared, load, keep_quasi_static)
    record = np.zeros(native.RECORD_SIZE)
    step.start(q0, v0, (0.0, speed, 0.0), record)
    count = samples * revolutions
    angles = np.mod(TWO_PI * np.arange(1, count + 1) / samples, TWO_PI)
    rows = np.column_stack([np.full(count, TWO_PI / speed / samples), np.ones(count), angles,
                            np.full(count, speed), np.zeros(count),
                            np.full(count, TWO_PI / samples)])
    records = np.zeros((count, native.RECORD_SIZE))
    step.advance(rows, np.empty(0), records)
    order = np.roll(np.arange(samples), 1)     # the last row is angle 0
    return angles[-samples:][order], records[-samples:, :4][order]
