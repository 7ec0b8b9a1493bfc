"""
A smooth periodic basis of the reduced model's soft modes over the crank angle.

The reduced model's 26 coordinates hold 16 modes between 28 and 666 Hz and 10 stiff ones
between 2 and 58 kHz that the outputs barely see but that set the step's cost. A second
reduction keeps the p lowest modes: at each grid node the lowest p eigenvectors of K(theta)
(w = a = 0) against M(theta), aligned node to node and with the leftover rotation of one
revolution spread evenly, so the basis Phi(theta) is periodic and smooth; its derivatives in
theta come from the FFT of the node values.

The second reduction is only sound at a spectral gap: the precompute checks the ratio of the
(p+1)-th to the p-th eigenvalue of the effective stiffness K0 + a Ka + w^2 Kw2 against M at
every node and at the corners of the speed and acceleration ranges (:func:`gap_ratios`), and
:func:`choose_soft_size` takes the smallest p whose gap clears :data:`MIN_GAP_RATIO`.
"""

import numpy as np
import scipy   # scipy.linalg loads on first use: a replay from the cache never needs it

from ...errors import FlexlinkError

# The smallest frequency ratio between the highest kept and the lowest dropped mode at which a
# second reduction is sound (eigenvalue ratio MIN_GAP_RATIO^2). The default model has 3.07
# at p = 16 and below 1.45 at every smaller p.
MIN_GAP_RATIO = 3.0


def lowest_modes(mass, stiffness, count):
    """
    Return the eigenvalues (all) and the lowest ``count`` M-normalised modes per grid node.

    Parameters
    ----------
    mass, stiffness : ndarray, shape (N, r, r)
        Reduced mass and stiffness at the grid nodes.
    count : int
        Modes kept.

    Returns
    -------
    eigenvalues : ndarray, shape (N, r)
    modes : ndarray, shape (N, r, count)

    """
    nodes, size, _ = mass.shape
    eigenvalues = np.empty((nodes, size))
    modes = np.empty((nodes, size, count))
    for k in range(nodes):
        values, vectors = scipy.linalg.eigh(stiffness[k], mass[k])
        eigenvalues[k], modes[k] = values, vectors[:, :count]
    return eigenvalues, modes


def _nearest_rotation(cross):
    """Return the orthogonal Q nearest to ``cross`` (polar factor; Procrustes)."""
    left, _, right = np.linalg.svd(cross)
    return left @ right


def align_modes(mass, modes):
    """
    Rotate each node's modes onto the previous node's and spread the holonomy evenly.

    Node k + 1's modes X are replaced by X Q with Q the orthogonal matrix that brings them
    closest to node k's in the mass norm (Procrustes), so the subspace's frame turns no more
    than the subspace does. Around one revolution the frame comes back rotated by H (the
    holonomy); node k is then turned by exp(-k/N log H) so the frame closes on itself.
    The subspace, the M-orthonormality and the modal stiffness's spectrum are unchanged.

    Parameters
    ----------
    mass : ndarray, shape (N, r, r)
        Reduced mass at the grid nodes.
    modes : ndarray, shape (N, r, p)
        M-normalised modes per node.

    Returns
    -------
    ndarray, shape (N, r, p)
        The aligned, periodic frame.

    Raises
    ------
    FlexlinkError
        The subspace turns over around the revolution (det H = -1): no periodic frame exists.

    """
    frame = modes.copy()
    nodes = frame.shape[0]
    for k in range(1, nodes):
        frame[k] = frame[k] @ _nearest_rotation(frame[k].T @ mass[k] @ frame[k - 1])
    closing = _nearest_rotation(frame[0].T @ mass[0] @ frame[-1])
    if np.linalg.det(closing) < 0.0:
        raise FlexlinkError('the soft modes turn over around a revolution: no periodic basis')
    generator = np.real(scipy.linalg.logm(closing.T))
    generator = 0.5 * (generator - generator.T)
    for k in range(1, nodes):
        frame[k] = frame[k] @ scipy.linalg.expm(generator * (k / nodes))
    return frame


def angle_derivatives(values):
    """
    Return the first and second derivatives in theta of periodic node values, by FFT.

    Parameters
    ----------
    values : ndarray, shape (N, ...)
        Samples at theta_k = 2 pi k / N.

    Returns
    -------
    first, second : ndarray, shape (N, ...)
        d/dtheta and d2/dtheta2 [per rad, per rad^2] at the nodes (the Nyquist term is left
        out of the first derivative, which it would make complex).

    """
    nodes = values.shape[0]
    spectrum = np.fft.fft(values, axis=0)
    wavenumber = np.fft.fftfreq(nodes, 1.0 / nodes).reshape((nodes,) + (1,) * (values.ndim - 1))
    first = 1j * wavenumber
    if nodes % 2 == 0:
        first[nodes // 2] = 0.0
    return (np.real(np.fft.ifft(spectrum * first, axis=0)),
            np.real(np.fft.ifft(spectrum * -(wavenumber ** 2), axis=0)))


def gap_ratios(mass, stiffness_pieces, speed_max, accel_limit):
    """
    Return the eigenvalue gap lambda_{i+1} / lambda_i at every i, worst over nodes and corners.

    The effective stiffness K0 + a Ka + w^2 Kw2 at w in {0, speed_max}, a in {-accel_limit, 0,
    accel_limit} (the corners where the geometric and inertia stiffness are largest).

    Parameters
    ----------
    mass : ndarray, shape (N, r, r)
        Reduced mass at the grid nodes.
    stiffness_pieces : dict
        '1', 'a', 'w2': stiffness pieces at the nodes (missing ones taken as zero).
    speed_max, accel_limit : float
        Speed [rad/s] and acceleration [rad/s^2] ranges.

    Returns
    -------
    ndarray, shape (r - 1,)
        The smallest ratio of eigenvalue i + 1 to eigenvalue i (1-based i + 1 kept modes).

    """
    base = stiffness_pieces['1']
    zero = np.zeros_like(base)
    worst = np.full(base.shape[1] - 1, np.inf)
    for w in (0.0, speed_max):
        for a in (-accel_limit, 0.0, accel_limit):
            stiffness = (base + a * stiffness_pieces.get('a', zero)
                         + w * w * stiffness_pieces.get('w2', zero))
            values, _ = lowest_modes(mass, stiffness, 1)
            with np.errstate(divide='ignore', invalid='ignore'):
                ratio = values[:, 1:] / values[:, :-1]
            ratio[~(values[:, :-1] > 0.0)] = 0.0
            worst = np.minimum(worst, ratio.min(axis=0))
    return worst


def soft_basis_text(model):
    """Describe how a reduced model is stepped, e.g. 'stepped on 16 soft modes (gap 3.08x)'."""
    soft = model.info.get('soft') or {}
    if not soft.get('used'):
        reason = soft.get('reason')
        return 'stepped in all of them' + (f' ({reason})' if reason else '')
    gap = soft.get('gap_ratio')
    return (f'stepped on {model.step_size} soft modes'
            + (f' (gap {gap:.2f}x)' if gap else ' (every mode)'))


def choose_soft_size(ratios, requested=-1, min_ratio=MIN_GAP_RATIO):
    """
    Return the soft basis size p: the requested one if its gap is usable, else the smallest.

    Parameters
    ----------
    ratios : ndarray, shape (r - 1,)
        :func:`gap_ratios` (eigenvalue ratios).
    requested : int
        p wanted (-1: the smallest usable; r, all modes, needs no gap).
    min_ratio : float
        Smallest frequency ratio at the gap.

    Raises
    ------
    FlexlinkError
        No usable gap, or none at the requested size (with the ratio found there).

    """
    usable = np.flatnonzero(ratios >= min_ratio ** 2) + 1
    if requested == ratios.size + 1:
        return int(requested)               # every mode: a change of coordinates, no gap
    if requested > 0:
        if requested > ratios.size or requested not in usable:
            found = (f'{np.sqrt(ratios[requested - 1]):.3g}' if requested <= ratios.size
                     else 'none')
            raise FlexlinkError(f'no spectral gap after mode {requested} (frequency ratio '
                                f'{found}, at least {min_ratio:g} needed)')
        return int(requested)
    if usable.size == 0:
        raise FlexlinkError(f'the reduced model has no spectral gap of {min_ratio:g}x in '
                            'frequency over the crank angle, speed and acceleration range')
    return int(usable[0])
