"""
Small measures used to compare the flexible four-bar with the claims of Cho 1992 Sec. 4.

Harmonic content of a periodic signal, orientation of a closed path, and the resemblance of
a link's bending to a simply supported beam under uniform load.
"""

import numpy as np

from ..core.kinematics import solve_kinematics


def harmonic_shares(signal):
    """
    Share of the variance of a periodic signal in each harmonic of the revolution.

    Parameters
    ----------
    signal : ndarray, shape (P,) or (P, c)
        Equally spaced samples over exactly one period (components summed).

    Returns
    -------
    ndarray, shape (P // 2 + 1,)
        Entry h is the share of harmonic h (entry 0, the mean, is zero); sums to 1.

    """
    values = np.asarray(signal, dtype=float)
    if values.ndim == 1:
        values = values[:, None]
    spectrum = np.fft.rfft(values - values.mean(axis=0), axis=0)
    power = np.sum(np.abs(spectrum) ** 2, axis=1)
    if values.shape[0] % 2 == 0:
        power[-1] *= 0.5  # Nyquist bin appears once in the two-sided sum
    total = power.sum()
    return power / total if total > 0.0 else power


def signed_area(x, y):
    """
    Signed area of a closed polygon [units of x * y]: positive if counter-clockwise.

    Parameters
    ----------
    x, y : ndarray, shape (P,)
        Vertices in order (the closing edge is implied).

    Returns
    -------
    float

    """
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    return float(0.5 * np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def uniform_load_shape(s):
    """Deflection of a simply supported beam under uniform load at s = x / L (max 1 at 0.5)."""
    s = np.asarray(s, dtype=float)
    return s * (1.0 - 2.0 * s ** 2 + s ** 3) / (5.0 / 16.0)


def bending_deflection(model, displacement, crank_angle, link, points_per_element=8):
    """
    Transverse deflection of a link relative to the chord of its deflected ends.

    Parameters
    ----------
    model : FlexibleLinkage
        The model of ``displacement``.
    displacement : ndarray, shape (N, n)
        System vectors U at the crank angles.
    crank_angle : ndarray, shape (N,)
        [rad].
    link : int
        A modelled link.
    points_per_element : int
        Points drawn per beam element.

    Returns
    -------
    s : ndarray, shape (P,)
        Positions along the link divided by its length.
    bending : ndarray, shape (N, P)
        Deflection across the link [m], ends at zero.

    """
    theta = np.atleast_1d(np.asarray(crank_angle, dtype=float))
    _, operator = model.shape_operator(theta, points_per_element)
    deflection = np.einsum('kpcn,kn->kpc', operator[:, link], np.atleast_2d(displacement))
    angle = solve_kinematics(model.mechanism, theta).angle[link]
    across = (np.cos(angle)[:, None] * deflection[..., 1]
              - np.sin(angle)[:, None] * deflection[..., 0])
    s = np.linspace(0.0, 1.0, across.shape[1])
    chord = across[:, :1] + s[None, :] * (across[:, -1:] - across[:, :1])
    return s, across - chord


def shape_correlation(values, template):
    """Cosine similarity of each row of ``values`` (N, P) with ``template`` (P,), ndarray (N,)."""
    values = np.atleast_2d(values)
    norms = np.linalg.norm(values, axis=1) * np.linalg.norm(template)
    with np.errstate(invalid='ignore', divide='ignore'):
        return np.where(norms > 0.0, values @ template / norms, 0.0)


def peak_to_peak(response):
    """Peak-to-peak of each output of a periodic response over its revolution [m]."""
    return response.outputs.max(axis=0) - response.outputs.min(axis=0)


def coupler_mid_path(mechanism, crank_angle):
    """Rigid-body path of the coupler mid-point [m], complex, shape (P,)."""
    state = solve_kinematics(mechanism, crank_angle)
    return state.point(1, 0.5 * mechanism.lengths[2])[0]


__all__ = ['peak_to_peak', 'coupler_mid_path', 'harmonic_shares', 'signed_area',
           'uniform_load_shape', 'bending_deflection', 'shape_correlation']
