"""
Modal truncation error of the flexible four-bar against its full-order response.

:func:`truncation_study` compares mode superposition with N frozen modes (with and without
the static correction) to the full-order periodic response; :func:`modes_needed` reads the
number of modes an output needs for a tolerance.
"""

import numpy as np

from ..core.fe.simulate import _residual_flexibility  # same correction as periodic_response
from ..core.fe.simulate import DEFAULT_POINTS, DEFAULT_STEPS, periodic_response
from ..core.numerics import relative_rms

# Relative RMS error targets of the modes-needed study.
TOLERANCES = (0.01, 0.05)
# Output points of :attr:`PeriodicResponse.outputs` grouped per physical point.
OUTPUT_POINTS = (('lever_tip', slice(0, 2)), ('coupler_mid', slice(2, 4)))


def output_errors(outputs, reference):
    """Relative RMS error of the lever tip and the coupler mid-point, ndarray shape (2,)."""
    return np.array([relative_rms(outputs[:, cols], reference[:, cols])
                     for _, cols in OUTPUT_POINTS])


def truncation_study(model, speed, mode_counts, steps=DEFAULT_STEPS, points=DEFAULT_POINTS,
                     zeta=None, reference=None):
    """
    Error of mode superposition with N frozen modes against the full-order response.

    Both use the same integrator and time step (:func:`core.fe.simulate.periodic_response`), so
    the error is that of the modal approximation, not of the time discretisation; with all
    modes it vanishes to round-off.

    Parameters
    ----------
    model : FlexibleLinkage
        The full-order model.
    speed : float
        Crank speed [rad/s].
    mode_counts : sequence of int
        Values of N (each in 1..model.size).
    steps, points : int
        Time steps and output points per revolution.
    zeta : float or None
        Modal damping ratio (the mechanism's if None).
    reference : PeriodicResponse or None
        Full-order response at the same steps and points (computed if None).

    Returns
    -------
    dict
        'modes' ndarray (k,); 'plain' and 'static' ndarray (k, 2): relative RMS error of
        (lever tip, coupler mid-point) without and with the static correction; 'reference'
        PeriodicResponse; 'wall_s' total modal solve time [s].

    """
    if reference is None:
        reference = periodic_response(model, speed, 'full', steps=steps, points=points,
                                      zeta=zeta)
    counts = np.asarray(mode_counts, dtype=int)
    errors = {'plain': np.empty((len(counts), 2)), 'static': np.empty((len(counts), 2))}
    operator = model.output_operator(reference.crank_angle)
    wall = 0.0
    for row, count in enumerate(counts):
        run = periodic_response(model, speed, 'modal', modes=int(count), steps=steps,
                                points=points, zeta=zeta)
        wall += run.info['wall_s']
        errors['plain'][row] = output_errors(run.outputs, reference.outputs)
        # The static correction only post-processes the modal state (core.fe.simulate does the
        # same inside periodic_response), so one integration serves both.
        corrected = run.displacement
        if count < model.size:
            corrected = corrected + _residual_flexibility(model, run.crank_angle, speed,
                                                          run.displacement, run.velocity,
                                                          int(count))
        outputs = np.einsum('kon,kn->ko', operator, corrected)
        errors['static'][row] = output_errors(outputs, reference.outputs)
    return {'modes': counts, 'plain': errors['plain'], 'static': errors['static'],
            'reference': reference, 'wall_s': wall}


def modes_needed(mode_counts, errors, tolerance):
    """
    Smallest N whose error, and that of every larger N tried, is within ``tolerance``.

    Parameters
    ----------
    mode_counts : ndarray, shape (k,)
        Increasing.
    errors : ndarray, shape (k,)
        Error of each N.
    tolerance : float
        Largest error accepted.

    Returns
    -------
    int or None
        None if even the largest N misses the tolerance.

    """
    counts = np.asarray(mode_counts)
    ok = np.asarray(errors) <= tolerance
    if not ok[-1]:
        return None
    failing = np.flatnonzero(~ok)
    return int(counts[0] if failing.size == 0 else counts[failing[-1] + 1])


__all__ = ['TOLERANCES', 'OUTPUT_POINTS', 'output_errors', 'truncation_study', 'modes_needed']
