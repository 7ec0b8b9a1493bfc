"""
Lowest natural frequencies of a beam by the transfer-matrix method of Kim & Moon (Eqs. 2-7).

The beam is lumped (:mod:`core.tmm.beams`), the roots of |D(omega)| (:mod:`core.tmm.matrices`)
are bracketed and refined (:mod:`core.tmm.roots`), and the result is checked against the
stiffness-based frequencies of the same lumped model (:mod:`core.tmm.eigen`).
"""

import dataclasses

import numpy as np

from .beams import check_boundary_condition, lump_masses
from .eigen import lumped_frequencies
from .matrices import determinant_to_kgf_mm
from .roots import (available_modes, DEFAULT_DTOL, DEFAULT_RTOL, DEFAULT_STEP_RAD_S,
                    refine_root, RootResult, scan_brackets, SEARCHES)
from ...errors import FlexlinkError

# Relative gap between a found root and the stiffness-based lumped frequency that means a skip.
VERIFY_RTOL = 1e-4


@dataclasses.dataclass(frozen=True)
class TmmResult:
    """
    Lowest natural frequencies by the transfer-matrix method.

    Attributes
    ----------
    frequencies_rad_s : ndarray, shape (modes,)
    roots : tuple of RootResult
        Per mode: iterations, paper-criterion iterations, bracket, iterate history.
    scan_evaluations : int
        Determinants evaluated by the incremental scan.

    """

    frequencies_rad_s: np.ndarray
    roots: tuple
    scan_evaluations: int

    @property
    def iterations(self):
        """Refinement iterations per mode, list of int."""
        return [root.iterations for root in self.roots]


def tmm_frequencies(beam, bc, segments, method=3, modes=3, search='false-position',
                    step=DEFAULT_STEP_RAD_S, rtol=DEFAULT_RTOL, dtol=DEFAULT_DTOL,
                    verify=True, illinois=True):
    """
    Lowest `modes` natural frequencies of a lumped beam by transfer matrices (Eqs. 2-7).

    Parameters
    ----------
    beam : UniformBeam
        The uniform beam.
    bc : str
        One of :data:`BOUNDARY_CONDITIONS`.
    segments : int
        Number of equal segments.
    method : int
        Mass-lumping method 1, 2 or 3.
    modes : int
        How many frequencies, at most :func:`available_modes`.
    search : str
        'bisection', 'false-position' or 'newton'.
    step : float
        Scan increment d_omega [rad/s].
    rtol, dtol : float
        Tolerances of :func:`refine_root`.
    illinois : bool
        Illinois-modified false position (False: the paper's plain Eq. 6).
    verify : bool
        Check with :func:`lumped_frequencies` that the scan skipped no root (two roots
        within one step); raises FlexlinkError naming a smaller step if it did.

    Returns
    -------
    TmmResult

    """
    check_boundary_condition(bc)
    model = lump_masses(beam, segments, method, bc)
    _check_request(model, bc, segments, method, modes, search)
    brackets, evaluations = scan_brackets(model, bc, modes, step)
    scale = determinant_to_kgf_mm(bc)
    roots = tuple(
        RootResult(a, 0, 0, (a, b), ()) if a == b else
        refine_root(model, bc, (a, b), search, rtol, dtol, paper_scale=scale,
                    illinois=illinois)
        for a, b in brackets)
    frequencies = np.array([root.frequency_rad_s for root in roots])
    if verify:
        _verify_scan(model, bc, frequencies, step)
    return TmmResult(frequencies_rad_s=frequencies, roots=roots, scan_evaluations=evaluations)


def _check_request(model, bc, segments, method, modes, search):
    """Raise ValueError unless ``modes`` and ``search`` suit the lumped ``model``."""
    limit = available_modes(model, bc)
    if isinstance(modes, bool) or not isinstance(modes, (int, np.integer)) or modes < 1:
        raise ValueError(f'`modes` must be a positive integer, got {modes!r}')
    if modes > limit:
        raise ValueError(f'`modes` = {modes} exceeds the {limit} modes of {segments} segments '
                         f'with lumping method {method} ({bc})')
    if search not in SEARCHES:
        raise ValueError(f'`search` must be one of {", ".join(SEARCHES)}, got {search!r}')


def _verify_scan(model, bc, frequencies, step):
    """
    Raise FlexlinkError if the scan skipped a root (two roots within one step).

    The found roots are compared with :func:`lumped_frequencies` of the same lumped model.
    """
    reference = lumped_frequencies(model, bc, len(frequencies))
    # loose on purpose: beam modes are far apart, and the stiffness-based reference
    # loses ~eps (L/h)^4 to round-off on fine models while the transfer matrices do not
    mismatch = np.abs(frequencies - reference) > VERIFY_RTOL * reference
    if np.any(mismatch):
        k = int(np.argmax(mismatch))
        raise FlexlinkError(
            f'the scan with step {step:g} rad/s skipped a root below {frequencies[k]:.6g} '
            f'rad/s (mode {k + 1} is {reference[k]:.6g} rad/s); use a smaller step')
