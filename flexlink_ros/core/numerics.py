"""Small numeric helpers shared across the core: unit factors, angle wrapping, error measures."""

import math

import numpy as np

TWO_PI = 2.0 * math.pi
RPM = TWO_PI / 60.0   # rad/s per rpm


def wrap_to_2pi(angle):
    """Angle wrapped to [0, 2 pi) [rad] (a float; exact at multiples of 2 pi)."""
    wrapped = math.fmod(angle, TWO_PI)
    if wrapped < 0.0:
        wrapped += TWO_PI
    return wrapped if wrapped < TWO_PI else 0.0


def wrap_to_pi(angle):
    """Angle wrapped to [-pi, pi) [rad] (floats or arrays)."""
    return (angle + math.pi) % TWO_PI - math.pi


def relative_rms(estimate, reference):
    """
    Relative RMS error, ``sqrt(mean |e - r|^2 / mean |r|^2)`` over every component.

    Rows of 2-D arrays are points (P, 2) and 1-D arrays one series; either way the ratio is
    over all elements. A zero reference gives 0 for a zero estimate, else infinity.

    Parameters
    ----------
    estimate, reference : array_like of equal shape
        The values compared and the values they should be.

    Returns
    -------
    float

    """
    estimate = np.asarray(estimate, dtype=float)
    reference = np.asarray(reference, dtype=float)
    scale = np.mean(np.sum(reference ** 2, axis=-1))
    if scale == 0.0:
        return 0.0 if np.allclose(estimate, 0.0) else float('inf')
    return float(np.sqrt(np.mean(np.sum((estimate - reference) ** 2, axis=-1)) / scale))
