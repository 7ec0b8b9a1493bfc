"""
Studies of the flexible four-bar FE model for the Cho, Park & Lee (1992) report (Sec. 4).

- The paper's frequency cases (Figs. 7-13) as :class:`FrequencyCase` and their frozen-mode
  sweeps over the crank angle (:func:`sweep_case`).
- Mode veering and order swaps over a parameter sweep (:func:`detect_mode_events`): a veering
  is a local minimum of the gap between neighbouring frequencies across which the two modes
  exchange their shapes (the lower mode on one side resembles the upper mode on the other,
  by the mass-weighted modal assurance criterion); a swap is a step between neighbouring
  samples at which a mode's best match is another index (a crossing the sampling resolves
  only as a jump).
- Modal truncation error against the full-order reference (:func:`truncation_study`), and the
  number of modes an output needs for a tolerance (:func:`modes_needed`).
- Small measures used to compare with the paper's claims: relative RMS error, harmonic
  content of a periodic signal, orientation of a closed path, and the resemblance of a link's
  bending to a simply supported beam under uniform load.

Numpy/scipy only; the FE model is :mod:`core.assembly`, the responses :mod:`core.simulate`.
"""

import dataclasses

import numpy as np
import scipy.optimize

from ..core.numerics import RPM, relative_rms
from ..core.options import ModelOptions
from ..core.fe.linkage import FlexibleLinkage
from ..core.kinematics import solve_kinematics
from ..core.fe.modes import solve_frozen_modes
from ..core.fe.simulate import DEFAULT_POINTS, DEFAULT_STEPS, periodic_response
from ..core.fe.simulate import _residual_flexibility  # same correction as periodic_response applies

# Crank speeds of the paper's frequency plots [rad/s] (Figs. 8-13) and deflection plots [rpm].
PAPER_SPEEDS_RAD_S = (30.0, 45.0)
PAPER_RPM = (269.0, 391.0)
# Relative RMS error targets of the modes-needed study.
TOLERANCES = (0.01, 0.05)
# Output points of :attr:`PeriodicResponse.outputs` grouped per physical point.
OUTPUT_POINTS = (('lever_tip', slice(0, 2)), ('coupler_mid', slice(2, 4)))


def quasi_static_axial_force(mechanism, state, link, x):
    """
    Axial force [N] of a link from the FE quasi-static solution K U = R (tension > 0).

    The paper obtains its axial loads this way ("by a quasi-static displacement analysis",
    Conclusion 1 of Cho 1992); the rigid-body analysis (``core.dynamics.axial_force``) gives
    the same element means (test_assembly). Same signature as ``core.dynamics.axial_force``,
    so it can stand in for it; the force is constant over each element (A.4 as printed).

    Parameters
    ----------
    mechanism : Mechanism
    state : LinkageState
        Rigid-body state at N crank angles (crank speed ``state.omega[0]``, acceleration
        ``state.alpha[0]``).
    link : int
    x : ndarray, shape (m,)
        Positions along the link [m].

    Returns
    -------
    ndarray, shape (N, m)

    """
    model = FlexibleLinkage(mechanism, ModelOptions.full_model(geometric_stiffness=False))
    theta = np.atleast_1d(state.angle[0])
    system = model.assemble(theta)
    speed = np.broadcast_to(np.asarray(state.omega[0], dtype=float), theta.shape)
    accel = np.broadcast_to(np.asarray(state.alpha[0], dtype=float), theta.shape)
    load = (system.load['1'] + accel[:, None] * system.load['a']
            + (speed * speed)[:, None] * system.load['w2'])
    displacement = np.linalg.solve(system.stiffness, load[..., None])[..., 0]
    forces = model.element_axial_forces(displacement, theta)[link]
    length = model.link_matrices[link].element_length
    element = np.minimum((np.asarray(x, dtype=float) / length).astype(int), forces.shape[1] - 1)
    return forces[:, element]


@dataclasses.dataclass(frozen=True)
class FrequencyCase:
    """
    One curve family of the paper's frequency plots.

    Attributes
    ----------
    key : str
        Short identifier.
    label : str
        Legend text.
    options : ModelOptions
    speed_rad_s : float
        Crank speed of the axial forces in K_G [rad/s] (irrelevant without K_G).

    """

    key: str
    label: str
    options: ModelOptions
    speed_rad_s: float = 0.0


def paper_frequency_cases(geometric):
    """
    The cases of Figs. 7-13 of Cho 1992 (bearings rigid unless named).

    Without geometric stiffness the frequencies do not depend on speed, so only the
    speed-free cases are returned; with it, the K_G cases at 30 and 45 rad/s are added.

    Parameters
    ----------
    geometric : bool
        Whether K_G can be assembled.

    Returns
    -------
    dict of str to FrequencyCase

    """
    cases = [
        FrequencyCase('flex', 'all flexible, no K_G', ModelOptions.full_model(geometric_stiffness=False)),
        FrequencyCase('rigid_crank', 'rigid crank, no K_G',
                      ModelOptions.full_model(rigid_crank=True, geometric_stiffness=False)),
        FrequencyCase('rigid_crank_bearings', 'rigid crank, flexible bearings, no K_G',
                      ModelOptions.full_model(rigid_crank=True, bearings='flexible',
                                   geometric_stiffness=False)),
    ]
    if geometric:
        for speed in PAPER_SPEEDS_RAD_S:
            tag = f'{speed:g} rad/s'
            cases += [
                FrequencyCase(f'flex_kg_{speed:g}', f'all flexible, K_G at {tag}',
                              ModelOptions.full_model(), speed),
                FrequencyCase(f'rigid_crank_kg_{speed:g}', f'rigid crank, K_G at {tag}',
                              ModelOptions.full_model(rigid_crank=True), speed),
                FrequencyCase(f'rigid_crank_bearings_kg_{speed:g}',
                              f'rigid crank, flexible bearings, K_G at {tag}',
                              ModelOptions.full_model(rigid_crank=True, bearings='flexible'), speed),
            ]
    return {case.key: case for case in cases}


@dataclasses.dataclass(frozen=True)
class Sweep:
    """
    Frozen modes of one case over crank angles.

    Attributes
    ----------
    case : FrequencyCase
    crank_deg : ndarray, shape (N,)
    frequencies_hz : ndarray, shape (N, m)
    shapes : ndarray, shape (N, n, m)
        Mass-normalised mode shapes.
    mass : ndarray, shape (N, n, n)
    dominant_link : ndarray of int, shape (N, m)
        Link with the largest strain-energy share (0 crank, 1 coupler, 2 lever).
    strain_share : ndarray, shape (N, m, 4)
        Crank, coupler, lever, springs.
    events : list of ModeEvent
        Veerings and swaps over the cycle (:func:`detect_mode_events`, periodic).

    """

    case: FrequencyCase
    crank_deg: np.ndarray
    frequencies_hz: np.ndarray
    shapes: np.ndarray
    mass: np.ndarray
    dominant_link: np.ndarray
    strain_share: np.ndarray
    events: list


def sweep_case(mechanism, case, crank_deg, count=3):
    """
    Frozen eigen-analysis of a case over crank angles, with its mode events.

    One extra mode is solved so that the event detector sees the neighbour of the highest
    requested mode; it is not returned.

    Parameters
    ----------
    mechanism : Mechanism
    case : FrequencyCase
    crank_deg : ndarray, shape (N,)
        Crank angles [deg]; a full turn (equal steps) is treated as periodic.
    count : int
        Modes returned.

    Returns
    -------
    Sweep

    """
    crank_deg = np.asarray(crank_deg, dtype=float)
    model = FlexibleLinkage(mechanism, case.options)
    system = model.assemble(np.radians(crank_deg))
    solved = min(count + 1, model.size)
    frozen = solve_frozen_modes(system, solved, case.speed_rad_s)
    steps = np.diff(crank_deg)
    periodic = bool(len(crank_deg) > 2 and np.allclose(steps, steps[0])
                    and np.isclose(crank_deg[-1] + steps[0] - crank_deg[0], 360.0))
    events = [refine_mode_event(model, case.speed_rad_s, e, steps[0] if len(steps) else 1.0)
              for e in detect_mode_events(crank_deg, frozen.frequencies_hz, frozen.shapes,
                                          system.mass, periodic=periodic)
              if max(e.modes) < count]
    keep = slice(0, count)
    return Sweep(case=case, crank_deg=crank_deg, frequencies_hz=frozen.frequencies_hz[:, keep],
                 shapes=frozen.shapes[:, :, keep], mass=system.mass,
                 dominant_link=frozen.dominant_link[:, keep],
                 strain_share=frozen.strain_share[:, keep], events=events)


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


# -- mode events -------------------------------------------------------------------------------


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
    second : ndarray, shape (n, q)
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
    parameter = np.asarray(parameter, dtype=float)
    frequencies = np.asarray(frequencies, dtype=float)
    shapes = np.asarray(shapes, dtype=float)
    count, modes = frequencies.shape
    if count < 3 or modes < 2:
        return []
    weights = None if mass is None else np.asarray(mass, dtype=float)

    def weight(k):
        if weights is None:
            return None
        return weights if weights.ndim == 2 else weights[k % count]

    def neighbour(k):
        return (k + 1) % count if periodic else k + 1

    events = []
    last = count if periodic else count - 1
    for k in range(last):
        k1 = neighbour(k)
        matrix = mac(shapes[k], shapes[k1], weight(k))
        best = matrix.argmax(axis=1)
        pairs = {tuple(sorted((i, int(best[i])))) for i in range(modes)
                 if best[i] != i and matrix[i, best[i]] > exchange_threshold}
        for i, j in sorted(pairs):
            step = parameter[k1] - parameter[k]
            if periodic and k1 == 0:
                step = parameter[1] - parameter[0]
            gap = abs(frequencies[k, j] - frequencies[k, i])
            events.append(ModeEvent('swap', (i, j), k, float(parameter[k] + 0.5 * step),
                                    float(gap), float(gap / np.mean(frequencies[k, [i, j]])),
                                    float(max(matrix[i, j], matrix[j, i]))))
    swapped = {(e.modes, e.index) for e in events}
    window = count // 2 if periodic else count
    for i in range(modes - 1):
        gap = frequencies[:, i + 1] - frequencies[:, i]
        relative = gap / (0.5 * (frequencies[:, i + 1] + frequencies[:, i]))
        for k in range(count):
            if not periodic and (k == 0 or k == count - 1):
                continue
            before, after = gap[(k - 1) % count], gap[(k + 1) % count]
            if not (gap[k] <= before and gap[k] < after) or relative[k] > max_relative_gap:
                continue
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
            if left is None or right is None:
                continue
            if any(((i, i + 1), s) in swapped for s in _between(left, right, count)):
                continue  # a jump inside the window is reported as a swap
            cross = mac(shapes[left][:, [i]], shapes[right][:, [i, i + 1]], weight(k))[0]
            if cross[1] > exchange_threshold and cross[1] > cross[0]:
                events.append(ModeEvent('veering', (i, i + 1), k, float(parameter[k]),
                                        float(gap[k]), float(relative[k]), float(cross[1])))
    return sorted(events, key=lambda e: (e.parameter, e.modes))


def _between(left, right, count):
    """Sample indices from left up to (not including) right, wrapping around."""
    k, out = left, []
    while k != right:
        out.append(k)
        k = (k + 1) % count
    return out


# -- modal truncation --------------------------------------------------------------------------


def output_errors(outputs, reference):
    """Relative RMS error of the lever tip and the coupler mid-point, ndarray shape (2,)."""
    return np.array([relative_rms(outputs[:, cols], reference[:, cols])
                     for _, cols in OUTPUT_POINTS])


def truncation_study(model, speed, mode_counts, steps=DEFAULT_STEPS, points=DEFAULT_POINTS,
                     zeta=None, reference=None):
    """
    Error of mode superposition with N frozen modes against the full-order response.

    Both use the same integrator and time step (:func:`core.simulate.periodic_response`), so
    the error is that of the modal approximation, not of the time discretisation; with all
    modes it vanishes to round-off.

    Parameters
    ----------
    model : FlexibleLinkage
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
        # The static correction only post-processes the modal state (core.simulate does the
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
    tolerance : float

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


# -- measures for the paper's claims -------------------------------------------------------------


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
    displacement : ndarray, shape (N, n)
        System vectors U at the crank angles.
    crank_angle : ndarray, shape (N,)
        [rad].
    link : int
        A modelled link.
    points_per_element : int

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


__all__ = ['PAPER_SPEEDS_RAD_S', 'PAPER_RPM', 'TOLERANCES', 'OUTPUT_POINTS',
           'quasi_static_axial_force', 'FrequencyCase',
           'paper_frequency_cases', 'Sweep', 'sweep_case', 'refine_mode_event', 'ModeEvent',
           'mac', 'detect_mode_events', 'output_errors', 'truncation_study',
           'modes_needed', 'harmonic_shares', 'signed_area', 'uniform_load_shape',
           'bending_deflection', 'shape_correlation']
