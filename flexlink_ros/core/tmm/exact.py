"""Exact natural frequencies of a uniform Euler-Bernoulli beam (Kim & Moon, Table 5)."""

import math

import numpy as np
from scipy.optimize import brentq

from .beams import check_boundary_condition

# Characteristic equations of the continuous beam, written to stay bounded for large beta L,
# with the approximate location of root k (k = 1, 2, ...).
_CHARACTERISTIC = {
    'fixed-fixed': (lambda x: np.cos(x) - 1.0 / np.cosh(x), lambda k: (k + 0.5) * np.pi),
    'fixed-supported': (lambda x: np.sin(x) - np.cos(x) * np.tanh(x),
                        lambda k: (k + 0.25) * np.pi),
    'cantilever': (lambda x: np.cos(x) + 1.0 / np.cosh(x), lambda k: (k - 0.5) * np.pi),
    'supported': (lambda x: np.sin(x), lambda k: k * np.pi),
}


def exact_beta_l(bc, modes=3):
    """
    Roots beta L of the Euler-Bernoulli characteristic equation for boundary condition `bc`.

    cos(bL) cosh(bL) = 1 (fixed-fixed), tan(bL) = tanh(bL) (fixed-supported),
    cos(bL) cosh(bL) = -1 (cantilever), sin(bL) = 0 (supported).

    Returns
    -------
    ndarray, shape (modes,)

    """
    check_boundary_condition(bc)
    equation, guess = _CHARACTERISTIC[bc]
    roots = [brentq(equation, guess(k) - 0.4, guess(k) + 0.4, xtol=1e-15, rtol=1e-15)
             for k in range(1, modes + 1)]
    return np.array(roots)


def exact_frequencies(beam, bc, modes=3):
    """
    Exact Euler-Bernoulli frequencies (beta L)^2 sqrt(EI / (m L^4)) [rad/s].

    Returns
    -------
    ndarray, shape (modes,)

    """
    scale = math.sqrt(beam.flexural_rigidity / (beam.mass_per_length * beam.length ** 4))
    return exact_beta_l(bc, modes) ** 2 * scale
