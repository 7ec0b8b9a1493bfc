"""
Frozen eigen-analysis of the flexible four-bar (Cho, Park & Lee 1992, Sec. 4.1-4.2).

At a crank angle the input shaft is held and the linkage is a structure; its natural modes
solve the generalized symmetric eigenproblem ::

    (K + K_G(w, a)) phi = omega^2 M phi,      phi^T M phi = 1

(K: elastic, bearings, shaft; K_G: A.4 with the quasi-static axial forces at speed w and
acceleration a). As in the paper there is no -w^2 M term, so without K_G the frequencies do
not depend on speed; ``centrifugal=True`` adds the symmetric part of K_c(w, a) (in a link's own
frame the centrifugal softening -w_L^2 M). A mode's dominant link is the one storing the largest
share of its elastic strain energy; kinetic-energy shares are reported too.
"""

import dataclasses

import numpy as np
import scipy   # scipy.linalg loads on first use: a replay from the cache never needs it

from ...names import LINK_NAMES


@dataclasses.dataclass(frozen=True)
class FrozenModes:
    """
    Frozen modes at N crank angles.

    Attributes
    ----------
    crank_angle : ndarray, shape (N,)
        [rad].
    eigenvalues : ndarray, shape (N, m)
        omega^2 [rad^2/s^2], ascending (negative if K + K_G has lost definiteness).
    shapes : ndarray, shape (N, n, m)
        Mass-normalised mode shapes; the largest component of each is positive.
    kinetic_share : ndarray, shape (N, m, 3)
        Share of phi^T M phi per link (crank, coupler, lever; joint masses with their link).
    strain_share : ndarray, shape (N, m, 4)
        Share of the elastic strain energy phi^T K phi in crank, coupler, lever and in the
        bearing and shaft springs.

    """

    crank_angle: np.ndarray
    eigenvalues: np.ndarray
    shapes: np.ndarray
    kinetic_share: np.ndarray
    strain_share: np.ndarray

    @property
    def omega(self):
        """Circular frequencies [rad/s], shape (N, m) (zero where omega^2 < 0)."""
        return np.sqrt(np.maximum(self.eigenvalues, 0.0))

    @property
    def frequencies_hz(self):
        """Natural frequencies [Hz], shape (N, m)."""
        return self.omega / (2.0 * np.pi)

    @property
    def dominant_link(self):
        """Index of the link with the largest strain-energy share, shape (N, m)."""
        return np.argmax(self.strain_share[..., :3], axis=-1)

    @property
    def dominant_link_names(self):
        """Names of :attr:`dominant_link`, nested lists (N, m)."""
        return [[LINK_NAMES[i] for i in row] for row in self.dominant_link]


def solve_frozen_modes(system, count=None, speed=0.0, accel=0.0, centrifugal=False):
    """
    Lowest frozen modes of an assembled system at every one of its crank angles.

    Parameters
    ----------
    system : FrozenSystem
        From :meth:`core.fe.linkage.FlexibleLinkage.assemble`.
    count : int or None
        Number of modes (all if None).
    speed, accel : float
        Crank speed [rad/s] and acceleration [rad/s^2] of the axial forces in K_G (and of
        the centrifugal term).
    centrifugal : bool
        Add the symmetric part of K_c (off in the paper).

    Returns
    -------
    FrozenModes

    """
    n = system.size
    count = n if count is None else int(count)
    if not 1 <= count <= n:
        raise ValueError(f'`count` must be in 1..{n}, got {count}')
    stiffness = system.frozen_stiffness(speed, accel, centrifugal)
    values = np.empty((len(system), count))
    shapes = np.empty((len(system), n, count))
    for k in range(len(system)):
        values[k], shapes[k] = scipy.linalg.eigh(stiffness[k], system.mass[k],
                                                 subset_by_index=[0, count - 1])
    # Sign convention: the largest-magnitude component of each shape is positive.
    largest = np.take_along_axis(shapes, np.abs(shapes).argmax(axis=1)[:, None, :], axis=1)
    shapes = shapes * np.where(largest < 0.0, -1.0, 1.0)
    kinetic = np.einsum('kim,klij,kjm->kml', shapes, system.link_mass, shapes)
    strain_links = np.einsum('kim,klij,kjm->kml', shapes, system.link_stiffness, shapes)
    elastic = np.einsum('kim,kij,kjm->km', shapes, system.stiffness, shapes)
    springs = elastic - strain_links.sum(axis=-1)
    strain = np.concatenate([strain_links, springs[..., None]], axis=-1) / elastic[..., None]
    kinetic = kinetic / kinetic.sum(axis=-1, keepdims=True)
    return FrozenModes(crank_angle=system.crank_angle, eigenvalues=values, shapes=shapes,
                       kinetic_share=kinetic, strain_share=strain)


def frozen_mode_sweep(model, crank_angles, count=3, speed=0.0, accel=0.0, centrifugal=False):
    """
    Assemble and solve the frozen eigenproblem over crank angles (:func:`solve_frozen_modes`).

    Parameters
    ----------
    model : FlexibleLinkage
        The FE model (:class:`core.fe.linkage.FlexibleLinkage`).
    crank_angles : ndarray, shape (N,)
        [rad].
    count, speed, accel, centrifugal
        As in :func:`solve_frozen_modes`.

    Returns
    -------
    FrozenModes

    """
    return solve_frozen_modes(model.assemble(crank_angles), count, speed, accel, centrifugal)


def modal_damping(mass, eigenvalues, shapes, zeta):
    """
    Modal damping matrix ``C_d = M Phi diag(2 zeta omega_i) Phi^T M`` of mass-normalised modes.

    With all modes it gives ``Phi^T C_d Phi = diag(2 zeta omega_i)`` exactly.

    Parameters
    ----------
    mass : ndarray, shape (..., n, n)
        Mass matrices M.
    eigenvalues : ndarray, shape (..., m)
        omega_i^2 (negative values are taken as zero).
    shapes : ndarray, shape (..., n, m)
        Mode shapes Phi (columns), mass-normalised.
    zeta : float
        Damping ratio of every mode.

    Returns
    -------
    ndarray, shape (..., n, n)

    """
    weights = 2.0 * zeta * np.sqrt(np.maximum(eigenvalues, 0.0))
    left = mass @ shapes
    return np.einsum('...im,...m,...jm->...ij', left, weights, left)


__all__ = ['FrozenModes', 'solve_frozen_modes', 'frozen_mode_sweep', 'modal_damping']
