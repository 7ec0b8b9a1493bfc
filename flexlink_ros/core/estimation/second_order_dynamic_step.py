"""
The dynamic second-order pass in the streaming step (``second_order='dynamic'``).

The full-order reference (:mod:`core.fe.second_order_dynamic`) solves, after the linear pass,
one more periodic linear problem of the same model, ``M U2'' + C U2' + K U2 = F2(U1)``, loaded
by the second-order terms of the strain energy on the linear state, and outputs the linear
output operator of U1 + U2. Here the same runs sample by sample on the reduced model: a second
state z2 = (q2, q2') advanced by the SAME 2-stage Radau IIA step as the linear state (the same
M, C, K at the same stage times, so the stage system's LU factors of the linear step serve
both; only the right-hand side differs), loaded by ``f2 = V^T F2(V q)`` at the two stages
(:class:`.second_order_dynamic_kernel.DynamicPassKernel`, compiled where built). The stages'
linear q comes from the linear step's own stage values (:func:`stage_positions`).

Outputs. The model is of order 2: the record keeps the quasi-static correction and adds the
output operator on ``q2 - K_r^-1 f2_eigenstrain`` (the mode-acceleration split: the basis
cannot hold the chord shortening, which the quasi-static forms give exactly; q2 adds the
rest). Only the record's deflections (lever tip, coupler mid-point) get the increment; the
link shapes keep the quasi-static correction.

Two things the reduced state does not hold, measured against the full-order pass (391 rpm,
gravity, rigid crank and bearings, 8 elements per link;
docs/studies/dynamic_second_order_study.py):
the static axial stretch (the elastic axial force of V q alone is off by the rigid-body force
F_r, 25 N against 1.5 N at 4 elements per link: the reference is therefore the axial force of
the reduced static response K_r^-1 f_r at each stage), and, on the default basis (4 modes +
2 static, r = 6), the dynamic increment itself (coupler mid-point +3.5 / +5.4 % p2p, worse
than the quasi-static +3.4 / +4.7 %); 8 + 4 (r = 12, :data:`core.options.DYNAMIC_SIZES`)
brings it to +0.6 / +1.0 %.
"""

import numpy as np
import scipy   # scipy.linalg loads on first use: the compiled step never needs it

from . import native
from .second_order_dynamic_kernel import dynamic_pass_compiled_available, DynamicPassKernel, impl
from .step import CompiledStep, NumpyStep, STAGE1
from .tables import step_tables, system_blocks
from .warm_start import WarmStart
from ..integrators import RADAU_TABLEAUX
from ..numerics import TWO_PI

RADAU_A = np.asarray(RADAU_TABLEAUX[2][0], dtype=float)


def stage_weights(a=RADAU_A):
    """
    Return (g1, g2): ``Q_1 = q + c_1 h v + g1 (dq - h v) + g2 h dv`` for any step h.

    With stage accelerations X_j, ``dq = h v + h^2 sum_j (A^2)_2j X_j`` and
    ``dv = h sum_j A_2j X_j``; solving for X gives ``Q_1 = q + c_1 h v + h^2 sum_j
    (A^2)_1j X_j`` (the stage values the stage equations M X + C V + K Q = f were solved
    for), whose weights on (dq - h v) and h dv do not depend on h.
    """
    a2 = a @ a
    weights = np.linalg.solve(np.array([[a2[1, 0], a[1, 0]], [a2[1, 1], a[1, 1]]]),
                              a2[0, :2])
    return float(weights[0]), float(weights[1])


STAGE_WEIGHTS = stage_weights()
ONE_ROW = np.zeros(1, dtype=int)      # the last step of a single row without sub-steps


def stage_positions(h, q, v, dq, dv):
    """Radau IIA stage-1 position of the linear state from the step's increment (dq, dv)."""
    g1, g2 = STAGE_WEIGHTS
    return q + (STAGE1 - g1) * h * v + g1 * dq + g2 * h * dv


class _DynamicPassState:
    """
    The dynamic pass's state beside a linear step's: z2 = (q2, v2) and K_r^-1 f2_eigenstrain.

    Shared by the numpy and the compiled step (listed first among their bases): both refuse a
    model without the quasi-static correction and start the pass at rest with the linear state.
    """

    def _init_pass_state(self, model, tables):
        """Refuse a model of order 1; allocate z2 and the quasi-static part of q2."""
        if tables.second is None:
            raise ValueError('the dynamic pass adds to the quasi-static correction: '
                             'use a model of order 2')
        self.z2 = np.zeros(2 * model.size)
        # K_r^-1 f2_eigenstrain at the last sample: the part of q2 the quasi-static
        # correction holds.
        self.static2 = np.zeros(model.size)

    def start(self, q0, v0, crank, record):
        """Set the linear state (q2 = 0) and write its record (see NumpyStep.start)."""
        self.z2[:] = 0.0
        self.static2[:] = 0.0
        super().start(q0, v0, crank, record)


class DynamicSecondOrderStep(_DynamicPassState, NumpyStep):
    """
    :class:`NumpyStep` with the reduced dynamic second-order state z2 = (q2, v2).

    Parameters
    ----------
    model : ReducedModel
        The reduced model, of order 2.
    tables : _StepTables
        Its step tables.
    kernel : callable
        ``kernel(stored, slots, states, angles)`` -> (3, r): the pass's loads of a step
        (:class:`.second_order_dynamic_kernel.DynamicPassKernel`).

    """

    def __init__(self, model, tables, kernel):
        super().__init__(model, tables)
        self._init_pass_state(model, tables)
        self.kernel = kernel
        self._points = np.zeros((2, model.size))     # the linear q at stage 1 and the sample

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
        stage_angle = (self.previous[0] + STAGE1 * advance) % TWO_PI
        parity = self.load_stages(h, angle, speed, accel, advance)
        inv = 1.0 / h
        g = np.dot(np.array((inv * inv, inv, 1.0, h, h * h)), tables.g_stack[parity])
        blocks = np.dot(g.reshape(8, 8), self.stored.reshape(8, r * r))
        system_t = blocks.reshape(2, 4, r, r).transpose(1, 3, 0, 2).reshape(4 * r, 2 * r)
        z, stored = self.z, self.stored
        loads = np.concatenate((stored[1 - parity, 3, :r], stored[parity, 3, :r]))
        lapack = scipy.linalg.lapack
        lu, pivots, info = lapack.dgetrf(system_t[:2 * r].T)
        increment, info2 = lapack.dgetrs(lu, pivots, np.dot(z[:2 * r], system_t[2 * r:]) + loads)
        if info != 0 or info2 != 0 or not np.all(np.isfinite(increment)):
            raise ValueError('singular or non-finite Radau step')
        self._points[0] = stage_positions(h, z[:r], z[r:2 * r], increment[:r], increment[r:])
        z[:2 * r] += increment
        self._points[1] = z[:r]
        second = self.kernel(stored, (1 - parity, parity), self._points, (stage_angle, angle))
        self.static2[:] = second[2]
        increment2, info2 = lapack.dgetrs(lu, pivots, np.dot(self.z2, system_t[2 * r:])
                                          + second[:2].ravel())
        if info2 != 0 or not np.all(np.isfinite(increment2)):
            raise ValueError('non-finite second-order step')
        self.z2 += increment2


class CompiledDynamicStep(_DynamicPassState, CompiledStep):
    """
    :class:`CompiledStep` (the linear state and its records) with z2 advanced in C.

    The linear step is the package's compiled one, unchanged; after it, per step,
    ``_second_order_dynamic.advance`` repeats :meth:`DynamicSecondOrderStep._step`'s
    arithmetic for z2 (M, C, [K | f] at the two stages from the same node tables, the same
    G(h) block system, the loads of :class:`.second_order_dynamic_kernel.DynamicPassKernel`) and
    the records' deflections add the output operator on q2 - K_r^-1 f2_eigenstrain. Rows
    with sub-steps are split here first (as :meth:`NumpyStep._sub_steps` does), so that z2
    sees every linear sub-step.

    Parameters
    ----------
    model : ReducedModel
        The reduced model, of order 2, with its dynamic tables.
    tables : _StepTables
        Its step tables.

    """

    def __init__(self, model, tables):
        super().__init__(model, tables)
        self._init_pass_state(model, tables)
        self.kernel = DynamicPassKernel(model.dynamic_second_order)
        if not self.kernel.compiled:
            raise RuntimeError('the compiled pass (_second_order_dynamic.c) is not built')
        t = tables
        self._step_context = np.array([
            t.size, model.grid_size, self.cells_per_radian, t.mass_groups, t.kf_groups,
            t.out_rows, STAGE1, *STAGE_WEIGHTS, t.FIRST_MC, t.GROUPS_C], dtype=float)
        self._out = np.ascontiguousarray(t.out)
        # the linear state and crank state before a call's rows; one row's buffers
        self._z_start, self._previous = np.zeros(2 * model.size), np.zeros(3)
        self._one_state, self._one_increment = np.zeros((1, 2 * model.size)), np.zeros((1, 4))

    def advance(self, rows, states, records):
        """Advance the linear state (compiled step), then z2 through the same steps."""
        rows = rows.reshape(-1, native.ROW_SIZE)
        r = self.tables.size
        self._z_start[:] = self.z[:2 * r]
        self._previous[:] = self.previous
        steps, last = split_sub_steps(rows, self._previous)
        every = records.ndim == 2
        if steps.shape[0] == 1:
            step_states, increments = self._one_state, self._one_increment
        else:
            step_states = np.empty((steps.shape[0], 2 * r))
            increments = np.empty((steps.shape[0], 4))
        step_records = records
        if steps is not rows and every:
            step_records = np.empty((steps.shape[0], native.RECORD_SIZE))
        super().advance(steps, step_states, step_records)
        if step_records is not records:
            records[:] = step_records[last]
        k, t = self.kernel, self.tables
        impl.advance(k.context, k.load.pieces, k.load.arrays['dynamic_unit'], k.load.scalars,
                     self._step_context, t.mass, t.damping, t.kf, t.g0, self._out, steps,
                     self._z_start, self._previous, step_states, self.z2, self.static2,
                     increments)
        if every:
            records[:, :4] += increments[last]
        else:
            records[:4] += increments[-1]
        if states.size:
            states[:] = step_states[last, :states.shape[1]]


def split_sub_steps(rows, previous):
    """
    Return (steps, last): rows with sub-steps split into single steps, and each row's last.

    As :meth:`NumpyStep._sub_steps` takes them: ``count`` equal steps over h, the crank state
    linear between the samples. ``rows`` itself when no row has sub-steps.
    """
    if rows.shape[0] == 1 and rows[0, 1] <= 1.0:
        return rows, ONE_ROW
    counts = rows[:, 1].astype(int)
    if np.all(counts <= 1):
        return rows, np.arange(rows.shape[0])
    steps = []
    angle0, speed0, accel0 = previous.tolist()
    for (h, count, angle, speed, accel, advance) in rows.tolist():
        count = max(int(count), 1)
        for i in range(1, count):
            f = i / count
            steps.append((h / count, 1.0, (angle0 + advance * f) % TWO_PI,
                          speed0 + f * (speed - speed0), accel0 + f * (accel - accel0),
                          advance / count))
        steps.append((h / count, 1.0, angle, speed, accel, advance / count))
        angle0, speed0, accel0 = angle, speed, accel
    return np.array(steps), np.cumsum(np.maximum(counts, 1)) - 1


def step_for_model(model, tables, compiled):
    """
    Return the streaming step of a model: with the dynamic pass if it has its tables.

    The compiled step (:class:`CompiledStep`) where ``compiled``, else :class:`NumpyStep`;
    a model built with ``second_order='dynamic'`` gets :class:`CompiledDynamicStep` where
    ``compiled`` and both extensions are built, else :class:`DynamicSecondOrderStep` (numpy,
    its twin).
    """
    if model.dynamic_second_order is not None:
        if compiled and dynamic_pass_compiled_available():
            return CompiledDynamicStep(model, tables)
        return DynamicSecondOrderStep(model, tables,
                                      DynamicPassKernel(model.dynamic_second_order, compiled))
    return (CompiledStep if compiled else NumpyStep)(model, tables)


def steady_revolution(model, kernel, speed, samples=720, revolutions=10):
    """
    Stream the dynamic step at constant crank speed: outputs over its last revolution.

    The linear state starts on the periodic orbit (shooting, as the estimator's warm start),
    q2 at rest; the pass's transient decays with the modal damping over ``revolutions``.

    Parameters
    ----------
    model : ReducedModel
        The reduced model.
    kernel : callable
        The pass's loads (:class:`DynamicSecondOrderStep`).
    speed : float
        Crank speed [rad/s].
    samples, revolutions : int
        Samples per revolution (crank angles 2 pi k / samples) and revolutions streamed.

    Returns
    -------
    angles : ndarray, shape (samples,)
        Crank angles of the last revolution, from 0 [rad].
    outputs : ndarray, shape (samples, 4)
        Lever tip and coupler mid-point deflections [m].

    """
    shared = step_tables(model)
    q0, v0 = WarmStart().periodic_state(
        model, lambda theta, w, a: system_blocks(model, shared, theta, w, a), 0.0, speed)
    step = DynamicSecondOrderStep(model, shared, kernel)
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
