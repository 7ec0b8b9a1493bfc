"""
Mode veering and order swaps over a parameter sweep of the flexible four-bar (Cho 1992 Sec. 4).

A veering is a local minimum of the gap between neighbouring frequencies across which the two
modes exchange their shapes (the lower mode on one side resembles the upper mode on the
other, by the mass-weighted modal assurance criterion, :func:`mac`); a swap is a step between
neighbouring samples at which a mode's best match is another index (a crossing the sampling
resolves only as a jump). :func:`refine_mode_event` finds the smallest gap between samples.
"""

import dataclasses

import numpy as np
import scipy.optimize

from ..core.fe.modes import solve_frozen_modes


@dataclasses.dataclass(frozen=True)
class ModeEvent:
    """
    A veering or a swap of two modes over a sweep.

    Attributes
    ----------
    kind : str
        'veering' (avoided crossing: order kept, shapes exchanged) or 'swap' (the sampled
        order changes: a crossing, or a veering sharper than the sampling).
    modes : tuple of int
        The two mode indices (0-based, ascending order at each sample).
    index : int
        Sample of the smallest gap (veering) or the sample before the jump (swap).
    parameter : float
        Parameter value there (for a swap, midway between the two samples).
    gap : float
        Frequency difference of the two modes there (units of the input frequencies).
    relative_gap : float
        ``gap`` divided by the mean of the two frequencies.
    exchange : float
        Veering: MAC between the lower mode before and the upper mode after the minimum.
        Swap: MAC between mode i before and mode j after the jump.
    refined_parameter, refined_gap : float or None
        Parameter and gap of the smallest gap found between samples
        (:func:`refine_mode_event`), None if not refined.

    """

    kind: str
    modes: tuple
    index: int
    parameter: float
    gap: float
    relative_gap: float
    exchange: float
    refined_parameter: float = None
    refined_gap: float = None


def mac(first, second, mass=None):
    """
    Modal assurance criterion between the columns of two shape sets (mass-weighted).

    ``MAC_ij = (a_i^T M b_j)^2 / ((a_i^T M a_i)(b_j^T M b_j))``, in [0, 1].

    Parameters
    ----------
    first : ndarray, shape (n, p)
        Shapes a_i as columns.
    second : ndarray, shape (n, q)
        Shapes b_j as columns.
    mass : ndarray, shape (n, n) or None
        Weighting (identity if None).

    Returns
    -------
    ndarray, shape (p, q)

    """
    first = np.asarray(first, dtype=float)
    second = np.asarray(second, dtype=float)
    weighted = second if mass is None else np.asarray(mass) @ second
    cross = first.T @ weighted
    norm_first = np.einsum('ip,ip->p', first, first if mass is None else np.asarray(mass) @ first)
    norm_second = np.einsum('iq,iq->q', second, weighted)
    return cross ** 2 / np.outer(norm_first, norm_second)


def detect_mode_events(parameter, frequencies, shapes, mass=None, periodic=False,
                       spread=3.0, exchange_threshold=0.5, max_relative_gap=0.5):
    """
    Veerings and order swaps of neighbouring modes over a sampled parameter sweep.

    Swap: between samples k and k+1, mode i's best MAC match at k+1 is mode j != i (and
    above ``exchange_threshold``). Veering: a local minimum of the gap f_{i+1} - f_i (relative
    gap below ``max_relative_gap``) such that, taking the nearest samples on either side where
    the gap has grown to ``spread`` times its minimum (or the end of a half-sweep window), the
    lower mode before resembles the upper mode after (MAC above ``exchange_threshold``) more
    than it resembles the lower mode after.

    Parameters
    ----------
    parameter : ndarray, shape (N,)
        Sweep parameter (e.g. crank angle), increasing.
    frequencies : ndarray, shape (N, m)
        Ascending at each sample.
    shapes : ndarray, shape (N, n, m)
        Mode shapes at each sample (columns in the order of ``frequencies``).
    mass : ndarray, shape (N, n, n) or (n, n) or None
        Weighting of the MAC (identity if None).
    periodic : bool
        The last sample is followed by the first (a full crank turn).
    spread : float
        Gap growth that delimits a veering's sides.
    exchange_threshold : float
        MAC above which two shapes count as the same mode.
    max_relative_gap : float
        Larger relative gaps at a local minimum are not considered veerings.

    Returns
    -------
    list of ModeEvent
        Sorted by parameter.

    """
    frequencies = np.asarray(frequencies, dtype=float)
    count, modes = frequencies.shape
    if count < 3 or modes < 2:
        return []
    sweep = _SampledSweep(np.asarray(parameter, dtype=float), frequencies,
                          np.asarray(shapes, dtype=float),
                          None if mass is None else np.asarray(mass, dtype=float), periodic)
    events = _swap_events(sweep, exchange_threshold)
    swapped = {(e.modes, e.index) for e in events}
    for i in range(modes - 1):
        events += _veering_events(sweep, i, swapped, spread, exchange_threshold,
                                  max_relative_gap)
    return sorted(events, key=lambda e: (e.parameter, e.modes))


@dataclasses.dataclass(frozen=True)
class _SampledSweep:
    """The samples of a sweep as :func:`detect_mode_events` reads them."""

    parameter: np.ndarray
    frequencies: np.ndarray
    shapes: np.ndarray
    weights: np.ndarray
    periodic: bool

    def weight(self, k):
        """MAC weighting at sample k (None for the identity)."""
        if self.weights is None:
            return None
        return self.weights if self.weights.ndim == 2 else self.weights[k % len(self.parameter)]

    def neighbour(self, k):
        """Return the sample after k (wrapping around if periodic)."""
        return (k + 1) % len(self.parameter) if self.periodic else k + 1


def _swap_events(sweep, exchange_threshold):
    """Order swaps: mode i's best MAC match at the next sample is another mode j."""
    parameter, frequencies = sweep.parameter, sweep.frequencies
    count, modes = frequencies.shape
    events = []
    last = count if sweep.periodic else count - 1
    for k in range(last):
        k1 = sweep.neighbour(k)
        matrix = mac(sweep.shapes[k], sweep.shapes[k1], sweep.weight(k))
        best = matrix.argmax(axis=1)
        pairs = {tuple(sorted((i, int(best[i])))) for i in range(modes)
                 if best[i] != i and matrix[i, best[i]] > exchange_threshold}
        for i, j in sorted(pairs):
            step = parameter[k1] - parameter[k]
            if sweep.periodic and k1 == 0:
                step = parameter[1] - parameter[0]
            gap = abs(frequencies[k, j] - frequencies[k, i])
            events.append(ModeEvent('swap', (i, j), k, float(parameter[k] + 0.5 * step),
                                    float(gap), float(gap / np.mean(frequencies[k, [i, j]])),
                                    float(max(matrix[i, j], matrix[j, i]))))
    return events


def _veering_events(sweep, i, swapped, spread, exchange_threshold, max_relative_gap):
    """Veerings of modes i and i + 1: gap minima across which the two exchange shapes."""
    frequencies, periodic = sweep.frequencies, sweep.periodic
    count = frequencies.shape[0]
    gap = frequencies[:, i + 1] - frequencies[:, i]
    relative = gap / (0.5 * (frequencies[:, i + 1] + frequencies[:, i]))
    events = []
    for k in range(count):
        if not periodic and (k == 0 or k == count - 1):
            continue
        before, after = gap[(k - 1) % count], gap[(k + 1) % count]
        if not (gap[k] <= before and gap[k] < after) or relative[k] > max_relative_gap:
            continue
        left, right = _veering_sides(gap, k, spread, periodic)
        if left is None or right is None:
            continue
        if any(((i, i + 1), s) in swapped for s in _between(left, right, count)):
            continue  # a jump inside the window is reported as a swap
        cross = mac(sweep.shapes[left][:, [i]], sweep.shapes[right][:, [i, i + 1]],
                    sweep.weight(k))[0]
        if cross[1] > exchange_threshold and cross[1] > cross[0]:
            events.append(ModeEvent('veering', (i, i + 1), k, float(sweep.parameter[k]),
                                    float(gap[k]), float(relative[k]), float(cross[1])))
    return events


def _veering_sides(gap, k, spread, periodic):
    """
    Nearest samples either side of k where the gap has grown to ``spread`` times gap[k].

    Searched within half a sweep if periodic (the whole sweep otherwise); a side is the last
    sample searched when the gap never grows that much, None when there is no sample there.
    """
    count = len(gap)
    window = count // 2 if periodic else count
    left = right = None
    for d in range(1, window):
        kl = k - d
        if not periodic and kl < 0:
            break
        left = kl % count
        if gap[left] >= spread * gap[k]:
            break
    for d in range(1, window):
        kr = k + d
        if not periodic and kr >= count:
            break
        right = kr % count
        if gap[right] >= spread * gap[k]:
            break
    return left, right


def _between(left, right, count):
    """Sample indices from left up to (not including) right, wrapping around."""
    k, out = left, []
    while k != right:
        out.append(k)
        k = (k + 1) % count
    return out


def refine_mode_event(model, speed, event, step_deg):
    """
    Smallest frequency gap of an event's two modes between the neighbouring samples.

    The gap ``f_j - f_i`` of the frozen eigenproblem is minimised over the crank angle within
    one sample step either side of the event (bounded scalar search), so a sharp veering that
    the sampling shows as a swap gets its true minimum gap (a gap that does not close is an
    avoided crossing; symmetric one-parameter families cross only non-generically).

    Parameters
    ----------
    model : FlexibleLinkage
        The model of the sweep.
    speed : float
        Crank speed of the axial forces in K_G [rad/s].
    event : ModeEvent
        From :func:`detect_mode_events` with the crank angle [deg] as parameter.
    step_deg : float
        Sample step [deg].

    Returns
    -------
    ModeEvent
        A copy with ``refined_parameter`` [deg] and ``refined_gap`` [Hz].

    """
    low, high = event.modes

    def gap(deg):
        frozen = solve_frozen_modes(model.assemble(np.radians([deg])), high + 1, speed)
        f = frozen.frequencies_hz[0]
        return f[high] - f[low]

    centre = event.parameter
    found = scipy.optimize.minimize_scalar(gap, bounds=(centre - step_deg, centre + step_deg),
                                           method='bounded', options={'xatol': 1e-3})
    best = min((found.fun, found.x), (event.gap, event.parameter))
    return dataclasses.replace(event, refined_parameter=float(best[1] % 360.0),
                               refined_gap=float(best[0]))


__all__ = ['ModeEvent', 'mac', 'detect_mode_events', 'refine_mode_event']
