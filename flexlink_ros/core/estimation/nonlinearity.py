"""
The validity indicator per estimate: :func:`core.validity.nonlinearity_indicator` from q.

The detuning ratio of :mod:`core.validity` (Eq. 3 there) from the reduced state: the link-mean
elastic axial forces over the Euler loads are one table row per link dotted with
(q, 1, a, w^2) (:mod:`core.reduction.nonlinearity_tables`), the reference modes are
interpolated in w^2, and the distance to the nearest crank harmonic is computed per sample.
:class:`NonlinearityIndicator` gives it per sample (the streaming estimator's
``Sample.nonlinearity``) and for many samples at once (the offline estimate); NaN for a model
built without the tables. The threshold is :data:`core.validity.VALIDITY_THRESHOLD`.
"""

import math

import numpy as np

from ..reduction.cells import CELL_POWERS
from ..validity import detuning_ratio, REST_SPEED, VALIDITY_THRESHOLD

_POWERS = tuple(range(CELL_POWERS))


class NonlinearityIndicator:
    """
    The validity indicator of a reduced model's estimates.

    Parameters
    ----------
    model : ReducedModel
        With its ``nonlinearity`` tables (None: every value is NaN).

    """

    def __init__(self, model):
        tables = model.nonlinearity
        self.available = tables is not None
        self.threshold = VALIDITY_THRESHOLD
        if not self.available:
            return
        self._grid = model.grid_size
        self._cell_scale = model.grid_size / (2.0 * math.pi)
        table = np.asarray(tables['nonlinearity_table'], dtype=float)
        self._table = np.ascontiguousarray(table)                 # (N, P, links, r + 3)
        self._speeds2 = np.asarray(tables['nonlinearity_speeds'], dtype=float) ** 2
        self._omega = np.asarray(tables['nonlinearity_omega'], dtype=float)
        self._share = np.asarray(tables['nonlinearity_share'], dtype=float)
        self._zeta = float(model.zeta)
        self._speed_max = float(model.speed_max)
        self._size = model.size
        self._x = np.zeros(model.size + 3)
        self._x[model.size] = 1.0
        # Per-sample form: the reference modes per interval of the (uniform) w^2 grid.
        self._inverse_step2 = (self._speeds2.size - 1) / self._speeds2[-1]
        self._last_interval = self._speeds2.size - 2
        self._links = table.shape[2]
        self._flat_table = self._table.reshape(table.shape[0], -1, table.shape[3])
        omega_step, share_step = np.diff(self._omega, axis=0), np.diff(self._share, axis=0)
        self._reference_rows = [
            list(zip(self._omega[i].tolist(), omega_step[i].tolist(), self._share[i].tolist(),
                     share_step[i].tolist())) for i in range(self._speeds2.size - 1)]

    def __call__(self, crank_angle, speed, accel, q):
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
        q : ndarray, shape (r,)
            Reduced coordinates.

        """
        if not (self.available and math.isfinite(speed) and math.isfinite(accel)):
            return math.nan
        x = (crank_angle % (2.0 * math.pi)) * self._cell_scale
        k = min(int(x), self._grid - 1)
        t = x - k
        speed = min(max(speed, -self._speed_max), self._speed_max)
        speed2 = speed * speed
        extended = self._x
        extended[:self._size] = q
        extended[self._size + 1] = accel
        extended[self._size + 2] = speed2
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

    def batch(self, crank_angles, speeds, accels, modal):
        """
        Return the indicator of many samples, shape (m,) (NaN without tables, or where q is).

        Parameters
        ----------
        crank_angles, speeds, accels : ndarray, shape (m,)
            Crank state as the model saw it.
        modal : ndarray, shape (m, r)
            Reduced coordinates.

        """
        angles = np.asarray(crank_angles, dtype=float)
        if not self.available:
            return np.full(angles.shape, math.nan)
        speeds = np.clip(np.asarray(speeds, dtype=float), -self._speed_max, self._speed_max)
        accels = np.broadcast_to(np.asarray(accels, dtype=float), speeds.shape)
        x = np.mod(angles, 2.0 * math.pi) * self._cell_scale
        cells = np.minimum(np.floor(x).astype(int), self._grid - 1)
        powers = (x - cells)[:, None] ** np.array(_POWERS)
        extended = np.concatenate([np.asarray(modal, dtype=float),
                                   np.ones((angles.size, 1)), accels[:, None],
                                   (speeds ** 2)[:, None]], axis=1)
        ratios = np.einsum('mp,mplc,mc->ml', powers, self._table[cells], extended)
        speed2 = speeds ** 2
        omega = np.stack([np.interp(speed2, self._speeds2, column)
                          for column in self._omega.T], axis=-1)
        share = np.stack([np.interp(speed2, self._speeds2, column)
                          for column in self._share.reshape(self._share.shape[0], -1).T],
                         axis=-1).reshape((angles.size,) + self._share.shape[1:])
        return detuning_ratio(omega, share, ratios, speeds, self._zeta)
