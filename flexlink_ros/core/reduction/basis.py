"""
Constant reduced basis of the frozen system: frozen modes and static responses, compressed.

One constant basis V (n x r) serves the whole cycle: the frozen modes at every grid angle and
at several speeds, stacked, mass-weighted and compressed by an SVD (proper orthogonal
decomposition), optionally augmented by the static responses to the load pieces. The
projected damping is fitted in w^2 over a few speeds (:func:`fit_in_w2`).
"""

import dataclasses

import numpy as np
import scipy   # scipy.linalg loads on first use: a replay from the cache never needs it

from ..mechanism_checks import check_first_frequency

# Exponent of the (omega_1 / omega) weight of frozen-mode snapshots in the POD.
MODE_WEIGHT_POWER = 2.0
# Static snapshots per angle and speed: the load at that speed ('w') and the acceleration piece.
STATIC_PIECES = ('w', 'a')


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
        geometric, as core/fe/modes.py); None to use the symmetric part of ``stiffness``.

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
        """Return the number of grid angles N."""
        return self.mass.shape[0]

    @property
    def dofs(self):
        """Return the full-order size n."""
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
            check_first_frequency(omega[0] / (2.0 * np.pi), 2.0 * np.pi * k / samples.grid_size,
                                  w)
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
