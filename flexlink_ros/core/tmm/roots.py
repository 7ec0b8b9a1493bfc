"""
Roots of the frequency determinant |D(omega)| (Kim & Moon, Eqs. 5-7).

Roots are bracketed by an incremental scan from omega = 0 with step d_omega
(:func:`scan_brackets`), then refined by bisection (Eq. 5), false position (Eq. 6) or Newton
(Eq. 7, the derivative propagated exactly by the extended transfer matrix), :func:`refine_root`.

Convergence: an iterate is accepted when the frequency change from the previous iterate is at
most ``rtol * omega`` (default 1e-12) *and* |D| is at most ``dtol`` (default 1e-6) times the
larger |D| at the bracket ends. The paper stopped at |D| <= 1e-6 in kgf-mm units, which for the
fixed-fixed beam accepts the first false-position iterate 1198.96312 rad/s (Table 5) while the
root is 1198.963684 rad/s; the iteration at which that loose test is first met is reported too.
"""

import dataclasses
import math

import numpy as np

from .matrices import determinant_to_kgf_mm, frequency_determinant, frequency_determinants
from ...errors import ConvergenceError

# The paper's convergence test: |D| <= 1e-6 with D in kgf and mm units (Tables 2-5).
PAPER_DETERMINANT_TOL = 1e-6
# Default root-search tolerances (see module docstring).
DEFAULT_RTOL = 1e-12
DEFAULT_DTOL = 1e-6
DEFAULT_STEP_RAD_S = 10.0      # the paper's d_omega for Tables 2, 4, 5
MAX_ITERATIONS = 200
MAX_SCAN_STEPS = 2_000_000
SEARCHES = ('bisection', 'false-position', 'newton')


@dataclasses.dataclass(frozen=True)
class RootResult:
    """
    One refined root of |D(omega)| = 0.

    Attributes
    ----------
    frequency_rad_s : float
        Converged natural frequency.
    iterations : int
        Iterates computed until both tolerances held.
    iterations_paper_criterion : int or None
        First iterate meeting the paper's |D| <= 1e-6 (kgf-mm units), None if never met.
    bracket : tuple of float
        Scan interval (omega_1, omega_2) with a sign change.
    history : tuple of float
        Every iterate [rad/s].

    """

    frequency_rad_s: float
    iterations: int
    iterations_paper_criterion: object
    bracket: tuple
    history: tuple


def refine_root(model, bc, bracket, search='false-position', rtol=DEFAULT_RTOL,
                dtol=DEFAULT_DTOL, max_iterations=MAX_ITERATIONS, paper_scale=None,
                illinois=True):
    """
    Refine a bracketed root of |D(omega)| by bisection, false position or Newton.

    Bisection takes the midpoint (Eq. 5); false position the secant through the bracket ends
    (Eq. 6); Newton steps omega - |D|/|D|' (Eq. 7) from the bracket end with the smaller |D|,
    with the exact derivative of :func:`frequency_determinant` and a bisection step whenever
    a Newton step would leave the current bracket. Every method keeps the bracket (sign
    change) up to date. The paper's false position is plain regula falsi, whose one end can
    stay put while the other crawls (on a 5000 rad/s bracket it needs thousands of
    iterations); with `illinois` (default) the retained end's |D| is halved whenever the same
    end is kept twice in a row (Dowell & Jarratt 1971), which restores superlinear
    convergence and leaves the first two iterates as in the paper.

    Parameters
    ----------
    model : LumpedBeam
        The lumped-mass beam (:func:`core.tmm.beams.lump_masses`).
    bc : str
        Boundary condition, one of :data:`BOUNDARY_CONDITIONS`.
    bracket : tuple of float
        (omega_1, omega_2) [rad/s] with |D| of opposite signs at the ends.
    search : str
        'bisection', 'false-position' or 'newton'.
    rtol : float
        Relative tolerance on the change of frequency between iterates.
    dtol : float
        Tolerance on |D| relative to the larger |D| at the bracket ends.
    max_iterations : int
        Iterates allowed before ConvergenceError.
    paper_scale : float, optional
        SI-to-kgf-mm factor of |D| for the paper's criterion (default from `bc`).
    illinois : bool
        Illinois modification of false position (False: the paper's plain Eq. 6).

    Returns
    -------
    RootResult

    Raises
    ------
    ConvergenceError
        If the tolerances are not met within `max_iterations`.

    """
    if search not in SEARCHES:
        raise ValueError(f'`search` must be one of {", ".join(SEARCHES)}, got {search!r}')
    if paper_scale is None:
        paper_scale = determinant_to_kgf_mm(bc)
    newton = search == 'newton'

    def evaluate(omega):
        return frequency_determinant(model, bc, omega, derivative=newton)

    state, reference = _start_search(evaluate, bracket, newton)
    history = []
    paper_iteration = None
    for iteration in range(1, max_iterations + 1):
        omega = state.next_iterate(search, bool(history))
        result = evaluate(omega)
        f = result[0] if newton else result
        history.append(omega)
        if paper_iteration is None and abs(f * paper_scale) <= PAPER_DETERMINANT_TOL:
            paper_iteration = iteration
        converged = (abs(omega - state.previous) <= rtol * abs(omega)
                     and abs(f) <= dtol * reference) or f == 0.0
        if converged:
            return RootResult(omega, iteration, paper_iteration, (bracket[0], bracket[1]),
                              tuple(history))
        state.narrow(omega, f, illinois and search == 'false-position')
        state.previous, state.current_value = omega, f
        if newton:
            state.slope = result[1]
    raise ConvergenceError(f'{search} root search in ({bracket[0]:g}, {bracket[1]:g}) rad/s',
                           max_iterations, abs(f) / reference)


@dataclasses.dataclass
class _Search:
    """
    State of a bracketed root search of |D(omega)|.

    Attributes
    ----------
    low, high, f_low, f_high : float
        Bracket ends [rad/s] and |D| there (Illinois-scaled for false position).
    previous, current_value : float
        Last iterate [rad/s] and its |D|.
    slope : float or None
        d|D|/d(omega) at the last iterate (Newton only).
    kept_before : str or None
        Bracket end ('low' or 'high') retained by the previous iterate.

    """

    low: float
    high: float
    f_low: float
    f_high: float
    previous: float
    current_value: float
    slope: object
    kept_before: object = None

    def next_iterate(self, search, started):
        """Return the next iterate: midpoint (Eq. 5), secant (Eq. 6) or Newton step (Eq. 7)."""
        low, high = self.low, self.high
        if search == 'bisection':
            omega = 0.5 * (low + high)
        elif search == 'false-position':
            omega = low + self.f_low / (self.f_low - self.f_high) * (high - low)
        else:
            omega = (self.previous - self.current_value / self.slope if self.slope != 0.0
                     else math.nan)
            if not (low < omega < high):
                omega = 0.5 * (low + high)
        if omega in (low, high) and started:
            omega = self.previous  # bracket collapsed to adjacent floats: nothing left to gain
        return omega

    def narrow(self, omega, f, illinois):
        """Replace the bracket end whose |D| has the sign of ``f``; Illinois halving if asked."""
        if f * self.f_low > 0:
            self.low, self.f_low = omega, f
            kept = 'high'
        else:
            self.high, self.f_high = omega, f
            kept = 'low'
        if illinois and kept == self.kept_before:
            if kept == 'high':
                self.f_high *= 0.5
            else:
                self.f_low *= 0.5
        self.kept_before = kept


def _start_search(evaluate, bracket, newton):
    """Evaluate the bracket ends; start from the end with the smaller |D|. Also the |D| scale."""
    low, high = float(bracket[0]), float(bracket[1])
    at_low, at_high = evaluate(low), evaluate(high)
    f_low, f_high = (at_low[0], at_high[0]) if newton else (at_low, at_high)
    if f_low * f_high > 0:
        raise ValueError(f'`bracket` ({low}, {high}) does not change the sign of |D|')
    reference = max(abs(f_low), abs(f_high))
    start_low = abs(f_low) <= abs(f_high)
    slope = (at_low if start_low else at_high)[1] if newton else None
    state = _Search(low=low, high=high, f_low=f_low, f_high=f_high,
                    previous=low if start_low else high,
                    current_value=f_low if start_low else f_high, slope=slope)
    return state, reference


def scan_brackets(model, bc, count, step=DEFAULT_STEP_RAD_S, start=0.0,
                  max_steps=MAX_SCAN_STEPS):
    """
    Bracket the lowest `count` roots by stepping omega from `start` in increments `step`.

    An interval is kept when |D| changes sign across it (a scan point where |D| is exactly 0
    is a root and brackets itself). Two roots closer than `step` cancel and are missed; use
    :func:`lumped_frequencies` to check.

    Returns
    -------
    brackets : list of tuple of float
        `count` intervals (omega_1, omega_2) [rad/s].
    evaluations : int
        Determinants evaluated by the scan.

    """
    if not (math.isfinite(step) and step > 0):
        raise ValueError(f'`step` must be a positive number of rad/s, got {step!r}')
    brackets = []
    evaluations = 0
    chunk = 256  # scan points evaluated per vectorised call
    previous = None
    while len(brackets) < count:
        if evaluations > max_steps:
            raise ConvergenceError(f'frequency scan with step {step:g} rad/s', evaluations,
                                   math.nan)
        omegas = start + step * np.arange(evaluations, evaluations + chunk)
        values = frequency_determinants(model, bc, omegas)
        for omega, f in zip(omegas, values):
            evaluations += 1
            if previous is not None:
                if previous[1] == 0.0 and previous[0] > 0:
                    brackets.append((previous[0], previous[0]))
                elif previous[1] * f < 0:
                    brackets.append((previous[0], float(omega)))
            previous = (float(omega), float(f))
            if len(brackets) == count:
                break
    return brackets, evaluations


def available_modes(model, bc):
    """
    Count the natural frequencies of a lumped model: masses whose deflection is free.

    Returns
    -------
    int

    """
    eps = 1e-12 * model.length
    # every boundary condition of Eq. 3 pins the left end; all but the cantilever the right
    pinned = model.positions <= eps
    if bc != 'cantilever':
        pinned = pinned | (model.positions >= model.length - eps)
    return int(np.sum(~pinned & (model.masses > 0)))
