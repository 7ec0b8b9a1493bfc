"""
The transfer-matrix beam check (Kim & Moon): accuracy, speed and root-search effort.

Numbers for the report's beam charts (:mod:`report.beam`): first-frequency errors of the
three TMM mass lumpings and consistent-mass FE against segments (:func:`error_table`), the
first frequency itself (:func:`frequency_table`), wall time against accuracy
(:func:`timing_table`), root-search iterations against the scan step
(:func:`iteration_table`) and the observed order of convergence (:func:`observed_order`),
with the paper's Tables 2-3 for comparison.
"""

import time

import numpy as np

from ..core.tmm import beams
from ..core.tmm import eigen
from ..core.tmm import exact as tmm_exact
from ..core.tmm import roots
from ..core.tmm import solve

# The methods compared: TMM with lumping 1, 2, 3, and consistent-mass FE.
METHODS = ('tmm1', 'tmm2', 'tmm3', 'fe')
ERROR_SEGMENTS = (2, 3, 4, 6, 8, 12, 16, 24, 32, 48, 64, 96, 128)
TIMING_SEGMENTS = (6, 12, 24, 48, 96, 192)
TIMING_REPEATS = 5        # best of, per point, after one untimed warm-up call
TIMING_MODES = 3
SCAN_STEPS_RAD_S = (10.0, 50.0, 100.0, 500.0)
PAPER_SEGMENTS = 6
ORDER_FIT_SEGMENTS = (12, 48)  # segment range the convergence order is fitted over
# Kim & Moon Table 3 (mode 1; FPM, NRM) and Table 2 (HIS, d_omega = 10), |D| <= 1e-6.
PAPER_TABLE3_MODE1 = {
    'fixed-fixed': {'false-position': (1, 1, 1, 2), 'newton': (1, 1, 1, 3)},
    'fixed-supported': {'false-position': (2, 3, 4, 5), 'newton': (4, 5, 5, 7)},
    'cantilever': {'false-position': (3, 4, 4, 14), 'newton': (3, 4, 4, 4)},
    'supported': {'false-position': (6, 9, 10, 13), 'newton': (7, 9, 11, 10)},
}
PAPER_TABLE2_BISECTION = {'fixed-fixed': 5, 'fixed-supported': 17, 'cantilever': 13,
                          'supported': 27}


def frequencies(beam, bc, segments, method, modes=1, search='newton', step=50.0,
                verify=True):
    """Lowest `modes` frequencies [rad/s] of `method` ('tmm1'..'tmm3', 'fe'), ndarray (modes,)."""
    if method == 'fe':
        return eigen.fe_frequencies(beam, bc, segments, modes)
    return solve.tmm_frequencies(beam, bc, segments, int(method[-1]), modes, search, step,
                                 verify=verify).frequencies_rad_s


def has_mode(beam, bc, segments, method):
    """Whether `method` with `segments` has at least one mode (e.g. no 1-segment TMM2)."""
    if method == 'fe':
        return segments >= (2 if bc == 'fixed-fixed' else 1)
    if method == 'tmm2' and segments < 2:
        return False
    model = beams.lump_masses(beam, segments, int(method[-1]), bc)
    return roots.available_modes(model, bc) >= 1


def error_table(beam, segment_counts=ERROR_SEGMENTS):
    """
    Relative first-frequency error per boundary condition and method.

    Returns
    -------
    dict
        ``{bc: {method: (segments ndarray (k,), error ndarray (k,))}}``, error signed,
        relative to the exact Euler-Bernoulli value.

    """
    table = {}
    for bc in beams.BOUNDARY_CONDITIONS:
        exact = tmm_exact.exact_frequencies(beam, bc, 1)[0]
        table[bc] = {}
        for method in METHODS:
            counts = [n for n in segment_counts if has_mode(beam, bc, n, method)]
            values = [frequencies(beam, bc, n, method)[0] for n in counts]
            table[bc][method] = (np.array(counts), np.array(values) / exact - 1.0)
    return table


def timing_table(beam, segment_counts=TIMING_SEGMENTS, repeats=TIMING_REPEATS,
                 modes=TIMING_MODES):
    """
    Wall time of one call and the largest error of its first `modes` frequencies.

    TMM calls use the paper's choices (false position, d_omega = 10 rad/s) without the
    stiffness-based skip check; FE calls assemble and solve with scipy.linalg.eigh. Each point
    is the best of `repeats` runs, all methods measured in the same process one after another.

    Returns
    -------
    dict
        ``{bc: {method: (segments (k,), seconds (k,), max relative error (k,))}}``.

    """
    table = {}
    for bc in beams.BOUNDARY_CONDITIONS:
        exact = tmm_exact.exact_frequencies(beam, bc, modes)
        table[bc] = {}
        for method in METHODS:
            seconds, errors = [], []
            for n in segment_counts:
                best = np.inf
                for repeat in range(repeats + 1):
                    start = time.perf_counter()
                    values = frequencies(beam, bc, n, method, modes, 'false-position',
                                         roots.DEFAULT_STEP_RAD_S, verify=False)
                    if repeat:  # the first call only warms caches up
                        best = min(best, time.perf_counter() - start)
                seconds.append(best)
                errors.append(np.max(np.abs(values / exact - 1.0)))
            table[bc][method] = (np.array(segment_counts), np.array(seconds), np.array(errors))
    return table


def iteration_table(beam, steps=SCAN_STEPS_RAD_S, segments=PAPER_SEGMENTS):
    """
    Count iterations to the paper's |D| <= 1e-6 (kgf-mm) for mode 1, lumping method 3.

    Returns
    -------
    dict
        ``{bc: {search label: [count per step]}}`` with labels 'bisection',
        'false position (plain)', 'false position (Illinois)', 'newton'; also
        ``'... (tight)'`` entries with the iterations to the default tolerances.

    """
    variants = (('bisection', 'bisection', True),
                ('false position (plain)', 'false-position', False),
                ('false position (Illinois)', 'false-position', True),
                ('newton', 'newton', True))
    table = {}
    for bc in beams.BOUNDARY_CONDITIONS:
        table[bc] = {}
        for label, search, illinois in variants:
            loose, tight = [], []
            for step in steps:
                root = solve.tmm_frequencies(beam, bc, segments, 3, 1, search, step,
                                             illinois=illinois).roots[0]
                loose.append(root.iterations_paper_criterion)
                tight.append(root.iterations)
            table[bc][label] = loose
            table[bc][label + ' (tight)'] = tight
    return table


def observed_order(segments, errors, fit_range=ORDER_FIT_SEGMENTS):
    """
    Exponent p of |error| ~ h^p, least squares over segments within `fit_range`.

    The range stops short of the finest models, where the stiffness-based FE reaches its
    round-off floor, and of the coarsest, where the error is not yet asymptotic.

    """
    segments, errors = np.asarray(segments), np.abs(np.asarray(errors))
    keep = (segments >= fit_range[0]) & (segments <= fit_range[1]) & (errors > 0)
    return float(-np.polyfit(np.log(segments[keep]), np.log(errors[keep]), 1)[0])


def frequency_table(beam, max_segments=20):
    """
    First frequency of every method against segments 2..max_segments (paper's Figs. 2-5).

    Parameters
    ----------
    beam : beams.UniformBeam
        The beam.
    max_segments : int
        Largest number of segments.

    Returns
    -------
    dict
        ``{bc: {'exact': float, method: (segments list, frequency list [rad/s])}}``.

    """
    table = {}
    for bc in beams.BOUNDARY_CONDITIONS:
        table[bc] = {'exact': tmm_exact.exact_frequencies(beam, bc, 1)[0]}
        for method in METHODS:
            counts = [n for n in range(2, max_segments + 1) if has_mode(beam, bc, n, method)]
            table[bc][method] = (counts, [frequencies(beam, bc, n, method)[0] for n in counts])
    return table


__all__ = ['METHODS', 'ERROR_SEGMENTS', 'TIMING_SEGMENTS', 'TIMING_REPEATS', 'TIMING_MODES',
           'SCAN_STEPS_RAD_S', 'PAPER_SEGMENTS', 'ORDER_FIT_SEGMENTS', 'PAPER_TABLE3_MODE1',
           'PAPER_TABLE2_BISECTION', 'frequencies', 'has_mode', 'error_table', 'timing_table',
           'iteration_table', 'observed_order', 'frequency_table']
