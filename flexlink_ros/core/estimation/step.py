"""
The per-sample Radau IIA step of the reduced model, in numpy or compiled, and its criteria.

Everything the step needs at the new sample (M, C, K, f, output operator, residual
correction, joint reactions) is one dot product of 4 x 7 weights with one grid cell of the
step tables (tables.py), and the first Radau stage (at 1/3 of the step, crank state
interpolated between the samples) is a second such product. (Interpolating the stage-1
matrices linearly in time instead saves that product but, with flexible bearings near
resonance, shifted the response by up to 40 %: the ground-frame stiffness of the rotating
links is not linear over a step.) The two stages' block matrix and right-hand-side operator
come out of one small matrix product with coefficients that depend only on the step h.

:class:`CompiledStep` runs the same step in C (_radau_step.c): one call per sample (or per
chunk of rows) instead of about thirty numpy calls, the same arithmetic to rounding.
"""

import math

import numpy as np
import scipy   # scipy.linalg loads on first use: the compiled step never needs it

from . import native
from .tables import hermite_basis
from ..integrators import RADAU_TABLEAUX
from ..numerics import TWO_PI
from ..reduction.cells import CELL_POWERS, MONOMIALS
from ...names import OUTPUT_NAMES

# Steps longer than this are split into equal sub-steps, the crank state interpolated linearly
# between the samples: one Radau step across a gap loses the state of the fast modes (at
# 391 rpm, a 15 ms gap left an error of 28 % of the coupler's peak-to-peak for a revolution;
# 0.9 % with sub-steps) [ns].
MAX_SUBSTEP_NS = 2_000_000
# Node of the first Radau IIA stage (2 stages).
STAGE1 = float(RADAU_TABLEAUX[2][1][0])
# Reactions are clamped to this fraction of their cycle RMS in the criterion (finite at R = 0).
REACTION_FLOOR_FRACTION = 1e-6


def joint_criteria(values, near_zero_fraction):
    """
    Return R, gamma-dot, |gamma-dot / R| and near-zero flags per joint from table values.

    A reaction below REACTION_FLOOR_FRACTION of its cycle RMS is clamped to that floor
    (as core/criteria.py does), so the criterion stays finite; it is flagged near zero.
    The numpy twin of the compiled step's ``criteria``.

    Parameters
    ----------
    values : list of float
        The joint part of a record: reactions (joints x 2), their time derivative
        (joints x 2), squared cycle-RMS reactions (joints).
    near_zero_fraction : float
        A reaction below this fraction of its cycle RMS is near zero.

    """
    limit2 = near_zero_fraction * near_zero_fraction
    floor_fraction2 = REACTION_FLOOR_FRACTION * REACTION_FLOOR_FRACTION
    reactions, gamma_dots, ratios, near = [0.0] * 4, [0.0] * 4, [0.0] * 4, [False] * 4
    for j in range(4):
        fx, fy = values[2 * j], values[2 * j + 1]
        r2 = fx * fx + fy * fy
        rms2 = values[16 + j]
        near[j] = r2 < limit2 * rms2
        r2 = max(r2, floor_fraction2 * rms2)
        if r2 > 0.0:
            magnitude = math.sqrt(r2)
            gamma_dot = (fx * values[9 + 2 * j] - fy * values[8 + 2 * j]) / r2
            reactions[j], gamma_dots[j] = math.sqrt(fx * fx + fy * fy), gamma_dot
            ratios[j] = abs(gamma_dot) / magnitude
    return tuple(reactions), tuple(gamma_dots), tuple(ratios), tuple(near)


class NumpyStep:
    """
    The model's state z = [q, v, 1] and the numpy step that advances it through sample rows.

    Parameters
    ----------
    model : ReducedModel
        The reduced model (its size and grid).
    tables : _StepTables
        :func:`tables.step_tables` of the model.
    interpolate_stages : bool
        With the soft basis, stage 1's matrices by quadratic interpolation in time through
        the last two samples' and the new one's (one table evaluation per step); False
        evaluates them at the stage (as the 26-coordinate step always does: its stiff
        directions are not smooth enough in time for it). Checked against each other in
        test_step.

    """

    compiled = False

    def __init__(self, model, tables, interpolate_stages=True):
        if MONOMIALS != ('a', '1', 'w2', 'w', 'w4', 'wa', 'w3'):
            raise ValueError('monomial order changed: update NumpyStep.evaluate')
        r = tables.size
        self.tables = tables
        self.grid_size = model.grid_size
        self.cells_per_radian = model.grid_size / TWO_PI
        self.z = np.zeros(2 * r + 1)        # [q, v, 1] (soft basis: [eta, eta', 1])
        self.z[2 * r] = 1.0
        # The reduced model's [q, v, 1]: z itself, or lifted from the soft coordinates.
        self.lifted = self.z
        if tables.lift is not None:
            self.lifted = np.zeros(2 * tables.record_size + 1)
            self.lifted[-1] = 1.0
        # Stage 1 by interpolation in time (the soft basis): [count, h, X_n, X_n-1].
        self.history = None
        if tables.lift is not None and interpolate_stages:
            self.history = np.zeros(2 + 2 * (3 * r * r + r))
        self.previous = np.zeros(3)         # crank state (angle, speed, accel) of the last step
        # [M, C, K, F] of stage 1 and of the sample, in alternating slots (the dynamic pass
        # of second_order_dynamic_step.py reads them too).
        self.stored = np.zeros((2, 4, r * r))
        self._flat = self.stored.reshape(2, 4 * r * r)
        self._parity = 0
        self._weights = np.zeros(CELL_POWERS * len(MONOMIALS))
        self._hermite = np.zeros((2, 2 * len(MONOMIALS)))

    @property
    def state(self):
        """Return (q, q') of the reduced model at the newest sample (a view)."""
        return self.lifted[:-1]

    def _record(self, crank, record):
        """Write the record of the state at crank state (angle, speed, accel)."""
        weights, hermite, k = self.evaluate(*crank)
        if self.tables.lift is not None:
            self.tables.lift.state(weights, hermite, k, self.z, crank[1], self.lifted,
                                   self.cells_per_radian)
        self.tables.record(weights, k, self.lifted, record)

    def evaluate(self, angle, speed, accel):
        """
        Return the row weights, the Hermite weights and the cell at a crank state.

        Row weights of the power-form tables (monomial times t^p, in table-row order), the
        Hermite weights of the node tables ((2, monomials x 2): node k's monomial times h00,
        h10 and node k + 1's times h01, h11) and the cell k. The weights go to reused
        buffers: use them before the next call.

        Parameters
        ----------
        angle : float
            Crank angle in [0, 2 pi) [rad].
        speed : float
            Crank speed [rad/s].
        accel : float
            Crank acceleration [rad/s^2].

        """
        x = angle * self.cells_per_radian
        k = int(x)
        if k >= self.grid_size:
            k = self.grid_size - 1
        t = x - k
        t2 = t * t
        t3 = t2 * t
        h00, h10, h01, h11 = hermite_basis(t)
        w, a = speed, accel
        w2 = w * w
        # Order of MONOMIALS: a, 1, w2, w, w4, wa, w3.
        monomials = (a, 1.0, w2, w, w2 * w2, w * a, w2 * w)
        self._weights[:] = [m * p for m in monomials for p in (1.0, t, t2, t3)]
        self._hermite[0] = [m * p for m in monomials for p in (h00, h10)]
        self._hermite[1] = [m * p for m in monomials for p in (h01, h11)]
        return self._weights, self._hermite, k

    def start(self, q0, v0, crank, record):
        """
        Set the state to (q0, v0) at crank state ``crank`` and write its record.

        Parameters
        ----------
        q0, v0 : ndarray
            Modal coordinates and velocities.
        crank : tuple of float
            (angle, speed, accel) of the crank.
        record : ndarray
            RECORD_SIZE values, written in place.

        """
        r = q0.size
        self.z[:r] = q0
        self.z[r:2 * r] = v0
        if self.history is not None:
            self.history[0] = 0.0
        self._record(crank, record)
        self.previous[:] = crank

    def advance(self, rows, states, records):
        """
        Advance through sample rows (h, sub-steps, angle, speed, acceleration, advance).

        Parameters
        ----------
        rows : ndarray
            ROW_SIZE values per row.
        states : ndarray
            Empty, or rows x 2 r: z[:2 r] after each row.
        records : ndarray
            Rows x RECORD_SIZE, or one record (of the last row).

        """
        rows = rows.reshape(-1, native.ROW_SIZE).tolist()
        every = records.ndim == 2
        for n, (h, splits, angle, w, a, step) in enumerate(rows):
            self._sub_steps(h, int(splits), angle, w, a, step)
            if every or n == len(rows) - 1 or states.size:
                self._record((angle, w, a), records[n] if every else records)
            if states.size:
                states[n] = self.lifted[:states.shape[1]]

    def criteria(self, record, near_zero_fraction):
        """
        Return the joint criteria of a record (:func:`joint_criteria`).

        Parameters
        ----------
        record : ndarray
            RECORD_SIZE values.
        near_zero_fraction : float
            A reaction below this fraction of its cycle RMS is near zero.

        """
        return joint_criteria(record[2 * len(OUTPUT_NAMES):].tolist(),
                              near_zero_fraction)

    def _sub_steps(self, h, count, angle, speed, accel, advance):
        """
        Take ``count`` equal Radau IIA steps over ``h`` to the new sample (MAX_SUBSTEP_NS).

        Between the samples the crank state is linear: angle previous + f advance, speed and
        acceleration interpolated (the offline replay builds the same sub-step rows).
        """
        if count > 1:
            angle0, speed0, accel0 = self.previous.tolist()
            for i in range(1, count):
                f = i / count
                self._step(h / count, (angle0 + advance * f) % TWO_PI,
                           speed0 + f * (speed - speed0), accel0 + f * (accel - accel0),
                           advance / count)
            h, advance = h / count, advance / count
        self._step(h, angle, speed, accel, advance)

    def _combine_nodes(self, hermite, k, first_group, groups, table, out):
        """Hermite weights times the node rows of cell k (nodes k and k + 1) into ``out``."""
        rows = slice(2 * first_group, 2 * (first_group + groups))
        if k + 1 < self.grid_size:
            # Nodes k and k + 1 are adjacent: one product over both (a float32 table is
            # converted once).
            weights = np.concatenate((hermite[0, rows], hermite[1, rows]))
            np.dot(weights, table[k:k + 2].reshape(-1, table.shape[2]), out=out)
        else:
            np.dot(hermite[0, rows], table[k], out=out)
            out += np.dot(hermite[1, rows], table[0])

    def _load(self, slot, hermite, k):
        """Write M, C and [K, f] of the node tables at (Hermite weights, cell k) into a slot."""
        tables, r = self.tables, self.tables.size
        r2 = r * r
        flat = self._flat[slot]
        first = tables.FIRST_MC
        self._combine_nodes(hermite, k, first, tables.mass_groups, tables.mass, flat[:r2])
        self._combine_nodes(hermite, k, first, tables.GROUPS_C, tables.damping,
                            flat[r2:2 * r2])
        self._combine_nodes(hermite, k, 0, tables.kf_groups, tables.kf,
                            flat[2 * r2:3 * r2 + r])

    def _pack(self, slot):
        """Return a slot's [M, C, K | f] as one history entry."""
        r = self.tables.size
        return np.concatenate((self.stored[slot, :3].ravel(), self.stored[slot, 3, :r]))

    def _interpolate_stage(self, h, parity):
        """Stage 1 from the history and the sample's slot (_radau_step.c's load_stages)."""
        r, c1 = self.tables.size, STAGE1
        history, width = self.history, 3 * r * r + r
        last, before = history[2:2 + width], history[2 + width:]
        if history[0] >= 2.0:
            back, x = history[1], c1 * h
            weights = (x * (x - h) / (back * (back + h)), (x + back) * (h - x) / (back * h),
                       (x + back) * x / ((h + back) * h))
        else:
            weights = (0.0, 1.0 - c1, c1)
        sample = self._pack(parity)
        stage = weights[0] * before + weights[1] * last + weights[2] * sample
        self.stored[1 - parity, :3] = stage[:3 * r * r].reshape(3, r * r)
        self.stored[1 - parity, 3, :r] = stage[3 * r * r:]
        before[:] = last
        last[:] = sample
        history[1] = h
        history[0] = min(history[0] + 1.0, 2.0)

    def load_stages(self, h, angle, speed, accel, advance):
        """Load stage 1 (crank state interpolated to c_1 h) and the sample into the slots."""
        parity = 1 - self._parity
        self._parity = parity
        c1 = STAGE1
        previous = self.previous.tolist()
        if self.history is not None:
            if self.history[0] < 1.0:
                _, hermite, k = self.evaluate(*previous)
                self._load(parity, hermite, k)
                sample = self._pack(parity)
                self.history[2:2 + sample.size] = sample
                self.history[0] = 1.0
            _, hermite, k = self.evaluate(angle, speed, accel)
            self._load(parity, hermite, k)
            self._interpolate_stage(h, parity)
            self.previous[:] = (angle, speed, accel)
            return parity
        stage_angle = previous[0] + c1 * advance
        if stage_angle >= TWO_PI:
            stage_angle -= TWO_PI
        elif stage_angle < 0.0:
            stage_angle += TWO_PI
        _, hermite, k = self.evaluate(stage_angle, previous[1] + c1 * (speed - previous[1]),
                                      previous[2] + c1 * (accel - previous[2]))
        self._load(1 - parity, hermite, k)
        _, hermite, k = self.evaluate(angle, speed, accel)
        self._load(parity, hermite, k)
        self.previous[:] = (angle, speed, accel)
        return parity

    def _step(self, h, angle, speed, accel, advance):
        """One Radau IIA step to the new crank state (the numpy twin of _radau_step.c)."""
        tables = self.tables
        r = tables.size
        parity = self.load_stages(h, angle, speed, accel, advance)
        inv = 1.0 / h
        g = np.dot(np.array((inv * inv, inv, 1.0, h, h * h)), tables.g_stack[parity])
        blocks = np.dot(g.reshape(8, 8), self.stored.reshape(8, r * r))
        # Transposed system (column block, l, i, k): its first 2 r rows are the Fortran-order
        # block matrix LAPACK wants, the rest the transposed right-hand-side operator.
        system_t = blocks.reshape(2, 4, r, r).transpose(1, 3, 0, 2).reshape(4 * r, 2 * r)
        z = self.z
        stored = self.stored
        loads = np.concatenate((stored[1 - parity, 3, :r], stored[parity, 3, :r]))
        _, _, increment, info = scipy.linalg.lapack.dgesv(
            system_t[:2 * r].T, np.dot(z[:2 * r], system_t[2 * r:]) + loads,
            overwrite_a=1, overwrite_b=1)
        if info != 0 or not np.all(np.isfinite(increment)):
            raise ValueError('singular or non-finite Radau step')   # as the compiled step
        z[:2 * r] += increment


class CompiledStep(NumpyStep):
    """:class:`NumpyStep` with the step and the criteria compiled (_radau_step.c)."""

    compiled = True

    def __init__(self, model, tables, interpolate_stages=True):
        if native.impl is None:
            raise RuntimeError('the compiled step (core/estimation/_radau_step.c) is not built')
        super().__init__(model, tables, interpolate_stages)
        self._kernel = native.impl
        # The soft basis's lift as the kernel takes it: (phi, dphi, residual, lifted, history).
        self.lift_buffers = (None if tables.lift is None
                             else (*tables.lift.packed(), self.lifted, self.history))

    def advance(self, rows, states, records):
        """
        Advance through sample rows in one call of the compiled step.

        Parameters
        ----------
        rows : ndarray
            ROW_SIZE values per row.
        states : ndarray
            Empty, or rows x 2 r: z[:2 r] after each row.
        records : ndarray
            Rows x RECORD_SIZE, or one record (of the last row).

        """
        t = self.tables
        self._kernel.advance(t.mass, t.damping, t.kf, t.out, t.joint, t.g0,
                             self.cells_per_radian, STAGE1, self.z, self.previous, rows,
                             states, records, t.second_packed, self.lift_buffers)

    def criteria(self, record, near_zero_fraction):
        """
        Return the joint criteria of a record, compiled (the same doubles as the numpy twin).

        Parameters
        ----------
        record : ndarray
            RECORD_SIZE values.
        near_zero_fraction : float
            A reaction below this fraction of its cycle RMS is near zero.

        """
        return self._kernel.criteria(record, near_zero_fraction, REACTION_FLOOR_FRACTION)
