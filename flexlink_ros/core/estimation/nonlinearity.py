"""
The validity indicator per estimate: :func:`core.validity.nonlinearity_indicator` from q.

The detuning ratio of :mod:`core.validity` (Eq. 3 there) from the reduced state: the link-mean
elastic axial forces over the Euler loads are one table row per link dotted with
(q, a q, w^2 q, q', w q', w^2 q', w^4 q', 1, a, w^2) (the mode-acceleration form of
:mod:`core.reduction.nonlinearity_tables`), the reference modes are interpolated in w^2, and
the distance to the nearest crank harmonic is computed per sample.
:class:`NonlinearityIndicator` gives it per sample (the streaming estimator's
``Sample.nonlinearity``) and for many samples at once (the offline estimate); NaN for a model
built without the tables. The threshold is :data:`core.validity.VALIDITY_THRESHOLD`.
"""

import math

import numpy as np

from ..reduction.cells import CELL_POWERS
from ..validity import detuning_ratio, REST_SPEED, VALIDITY_THRESHOLD

try:
    from . import _nonlinearity as kernel       # _nonlinearity.c: the per-sample form in C
except ImportError:     # not built: the Python form serves
    kernel = None

_POWERS = tuple(range(CELL_POWERS))


class NonlinearityIndicator:
    """
    The validity indicator of a reduced model's estimates.

    Parameters
    ----------
    model : ReducedModel
        With its ``nonlinearity`` tables (None: every value is NaN).
    compiled : bool
        Evaluate single samples with the compiled form (_nonlinearity.c) where it is built;
        False: the Python form (the same numbers to rounding, 1e-12).

    Attributes
    ----------
    available : bool
        The model has the tables.
    compiled : bool
        Single samples go through the compiled form.

    """

    def __init__(self, model, compiled=True):
        tables = model.nonlinearity
        self.available = tables is not None
        self.compiled = bool(compiled and self.available and kernel is not None)
        self.threshold = VALIDITY_THRESHOLD
        if not self.available:
            return
        self._grid = model.grid_size
        self._cell_scale = model.grid_size / (2.0 * math.pi)
        table = np.asarray(tables['nonlinearity_table'], dtype=float)
        if table.shape[1:2] + table.shape[3:] != (CELL_POWERS, 7 * model.size + 3):
            raise ValueError(f'the nonlinearity table {table.shape} does not fit the model '
                             f'(r = {model.size})')
        self._table = np.ascontiguousarray(table)               # (N, P, links, 7 r + 3)
        self._speeds2 = np.asarray(tables['nonlinearity_speeds'], dtype=float) ** 2
        self._omega = np.asarray(tables['nonlinearity_omega'], dtype=float)
        self._share = np.asarray(tables['nonlinearity_share'], dtype=float)
        self._zeta = float(model.zeta)
        self._speed_max = float(model.speed_max)
        self._size = model.size
        # The extended state of Eq. (1) there: q times (1, a, w^2), q' times (1, w, w^2, w^4),
        # then 1, a, w^2; filled in place per sample.
        size = model.size
        self._x = np.zeros(7 * size + 3)
        self._x[7 * size] = 1.0
        self._x_q = self._x[:3 * size].reshape(3, size)
        self._x_v = self._x[3 * size:7 * size].reshape(4, size)
        self._monomials_q = np.ones((3, 1))
        self._monomials_v = np.ones((4, 1))
        # Per-sample form: the reference modes per interval of the (uniform) w^2 grid.
        self._inverse_step2 = (self._speeds2.size - 1) / self._speeds2[-1]
        self._last_interval = self._speeds2.size - 2
        self._links = table.shape[2]
        self._flat_table = self._table.reshape(table.shape[0], -1, table.shape[3])
        self._context = np.concatenate([
            [model.grid_size, size, self._links, self._omega.shape[1], self._speeds2.size,
             self._zeta, self._speed_max, self._cell_scale, self._inverse_step2, REST_SPEED],
            self._omega.ravel(), self._share.ravel()])
        omega_step, share_step = np.diff(self._omega, axis=0), np.diff(self._share, axis=0)
        self._reference_rows = [
            list(zip(self._omega[i].tolist(), omega_step[i].tolist(), self._share[i].tolist(),
                     share_step[i].tolist())) for i in range(self._speeds2.size - 1)]

    @property
    def kernel_tables(self):
        """
        Return (context, table) of the compiled form, or None where it is not used.

        The streaming estimator's compiled update evaluates the indicator from them in C
        (_nonlinearity.h, the same kernel as the compiled form).
        """
        return (self._context, self._table) if self.compiled else None

    def __call__(self, crank_angle, speed, accel, state):
        """
        Return the indicator of one sample (NaN without tables or for a non-finite state).

        One matrix-vector product with the cell's table; the rest in floats (two links, two
        reference modes: numpy's per-call cost would dominate).

        Parameters
        ----------
        crank_angle : float
            Crank angle [rad], any range.
        speed, accel : float
            Crank speed [rad/s] and acceleration [rad/s^2] as the model saw them.
        state : ndarray, shape (2 r,)
            Reduced coordinates q and their rates q' (contiguous float64 for the compiled form).

        """
        if self.compiled:
            return kernel.indicator(self._context, self._table, state, crank_angle, speed,
                                    accel)
        if not (self.available and math.isfinite(speed) and math.isfinite(accel)
                and math.isfinite(crank_angle)):
            return math.nan
        x = (crank_angle % (2.0 * math.pi)) * self._cell_scale
        k = min(int(x), self._grid - 1)
        t = x - k
        speed = min(max(speed, -self._speed_max), self._speed_max)
        speed2 = speed * speed
        size, extended = self._size, self._x
        monomials_q, monomials_v = self._monomials_q, self._monomials_v
        monomials_q[1, 0] = extended[-2] = accel
        monomials_q[2, 0] = monomials_v[2, 0] = extended[-1] = speed2
        monomials_v[1, 0], monomials_v[3, 0] = speed, speed2 * speed2
        np.multiply(monomials_q, state[:size], out=self._x_q)
        np.multiply(monomials_v, state[size:2 * size], out=self._x_v)
        values = self._flat_table[k].dot(extended).tolist()     # power-major, (P x links)
        links = self._links
        ratios = [v0 + t * (v1 + t * (v2 + t * v3)) for v0, v1, v2, v3 in zip(
            values[:links], values[links:2 * links], values[2 * links:3 * links],
            values[3 * links:])]
        position = speed2 * self._inverse_step2
        i = min(int(position), self._last_interval)
        f = min(position - i, 1.0)
        rate, zeta, worst = abs(speed), self._zeta, 0.0
        for omega0, omega_step, share0, share_step in self._reference_rows[i]:
            omega = omega0 + f * omega_step
            total = 0.0
            for s0, step, ratio in zip(share0, share_step, ratios):
                total += (s0 + f * step) * ratio
            harmonic = max(round(omega / rate), 1.0) * rate if rate > REST_SPEED else omega
            detuning = abs(0.5 * omega * total) / math.hypot(omega - harmonic, zeta * omega)
            if detuning > worst:
                worst = detuning
        return worst

    def batch(self, crank_angles, speeds, accels, modal, velocity):
        """
        Return the indicator of many samples, shape (m,) (NaN without tables, or where q is).

        Parameters
        ----------
        crank_angles, speeds, accels : ndarray, shape (m,)
            Crank state as the model saw it.
        modal, velocity : ndarray, shape (m, r)
            Reduced coordinates q and their rates q'.

        """
        angles = np.asarray(crank_angles, dtype=float)
        if not self.available:
            return np.full(angles.shape, math.nan)
        speeds = np.clip(np.asarray(speeds, dtype=float), -self._speed_max, self._speed_max)
        accels = np.broadcast_to(np.asarray(accels, dtype=float), speeds.shape)
        x = np.mod(angles, 2.0 * math.pi) * self._cell_scale
        cells = np.minimum(np.floor(x).astype(int), self._grid - 1)
        powers = (x - cells)[:, None] ** np.array(_POWERS)
        q, v = np.asarray(modal, dtype=float), np.asarray(velocity, dtype=float)
        ones, w2 = np.ones(angles.size), speeds ** 2
        extended = np.concatenate(
            [q, accels[:, None] * q, w2[:, None] * q, v, speeds[:, None] * v, w2[:, None] * v,
             (w2 * w2)[:, None] * v, np.stack([ones, accels, w2], axis=1)], axis=1)
        ratios = np.einsum('mp,mplc,mc->ml', powers, self._table[cells], extended)
        speed2 = speeds ** 2
        omega = np.stack([np.interp(speed2, self._speeds2, column)
                          for column in self._omega.T], axis=-1)
        share = np.stack([np.interp(speed2, self._speeds2, column)
                          for column in self._share.reshape(self._share.shape[0], -1).T],
                         axis=-1).reshape((angles.size,) + self._share.shape[1:])
        return detuning_ratio(omega, share, ratios, speeds, self._zeta)
