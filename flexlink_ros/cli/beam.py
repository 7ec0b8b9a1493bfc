"""
``flexlink beam``: natural frequencies of a uniform beam by transfer matrices or FE (Kim & Moon).

    flexlink beam --bc fixed-fixed|fixed-supported|cantilever|supported --segments N
                  --method tmm1|tmm2|tmm3|fe [--search bisection|false-position|newton]
                  [--step RAD_S] [--modes K] [--json]

The Kim & Moon strip (Table 1) is the default beam; ``--length-m``, ``--width-m``,
``--thickness-m``, ``--youngs-modulus-pa`` and ``--density-kg-m3`` replace its values. JSON
keys: ``frequencies_rad_s``, ``iterations`` (per mode, null for FE),
``iterations_paper_criterion``, ``exact_rad_s``, ``error_percent``, ``scan_evaluations``,
``wall_time_s``, ``tolerance``, ``beam`` and the inputs.
"""

import math
import time

from .main import emit
from ..core.tmm import beams
from ..core.tmm import eigen
from ..core.tmm import exact as tmm_exact
from ..core.tmm import roots
from ..core.tmm import solve

METHODS = ('tmm1', 'tmm2', 'tmm3', 'fe')


def register(subparsers):
    """Add the `beam` subcommand."""
    parser = subparsers.add_parser(
        'beam', help='beam natural frequencies: transfer matrices (Kim & Moon) or cubic FE')
    # Strings, checked in beam_command, so that bad input gives a one-line reason.
    parser.add_argument('--bc', default='cantilever',
                        help='fixed-fixed, fixed-supported, cantilever (default) or supported')
    parser.add_argument('--segments', default='6',
                        help='number of equal segments / elements (default 6)')
    parser.add_argument('--method', default='tmm3',
                        help='tmm1, tmm2, tmm3 (mass-lumping method, default) or fe')
    parser.add_argument('--search', default='false-position',
                        help='bisection, false-position (default) or newton')
    parser.add_argument('--step', default=str(roots.DEFAULT_STEP_RAD_S),
                        help='scan increment d_omega [rad/s] (default 10)')
    parser.add_argument('--modes', default='3', help='number of frequencies (default 3)')
    parser.add_argument('--rtol', default=str(roots.DEFAULT_RTOL),
                        help='relative frequency tolerance of the root search (default 1e-12)')
    parser.add_argument('--plain-false-position', action='store_true',
                        help="the paper's regula falsi without the Illinois modification")
    for name, unit in (('length', 'm'), ('width', 'm'), ('thickness', 'm'),
                       ('youngs-modulus', 'pa'), ('density', 'kg-m3')):
        parser.add_argument(f'--{name}-{unit}', default=None,
                            help=f'replace the Kim & Moon {name.replace("-", " ")}')
    parser.add_argument('--json', action='store_true', help='print one JSON object')
    parser.set_defaults(func=beam_command)


def _positive_int(text, name):
    try:
        value = int(text)
    except (TypeError, ValueError):
        raise ValueError(f'`--{name}` must be a positive integer, got {text!r}') from None
    if value < 1:
        raise ValueError(f'`--{name}` must be a positive integer, got {text!r}')
    return value


def _positive_float(text, name):
    try:
        value = float(text)
    except (TypeError, ValueError):
        raise ValueError(f'`--{name}` must be a positive number, got {text!r}') from None
    if not (math.isfinite(value) and value > 0):
        raise ValueError(f'`--{name}` must be a positive number, got {text!r}')
    return value


def _choice(text, choices, name):
    if text not in choices:
        raise ValueError(f'`--{name}` must be one of {", ".join(choices)}, got {text!r}')
    return text


def beam_from_args(args):
    """
    Return the Kim & Moon beam with any dimension or material given on the command line.

    Returns
    -------
    beams.UniformBeam

    """
    base = beams.UniformBeam.kim_moon()
    width, thickness = 0.030, 0.0015
    density = base.mass_per_length / (width * thickness)
    given = {key: _positive_float(value, key.replace('_', '-'))
             for key, value in (('length_m', args.length_m), ('width_m', args.width_m),
                                ('thickness_m', args.thickness_m),
                                ('youngs_modulus_pa', args.youngs_modulus_pa),
                                ('density_kg_m3', args.density_kg_m3))
             if value is not None}
    if not given:
        return base
    return beams.UniformBeam.rectangular(
        E=given.get('youngs_modulus_pa', base.E),
        density=given.get('density_kg_m3', density),
        length=given.get('length_m', base.length),
        width=given.get('width_m', width),
        thickness=given.get('thickness_m', thickness))


def beam_frequencies(beam, bc, segments, method='tmm3', search='false-position',
                     step=roots.DEFAULT_STEP_RAD_S, modes=3, rtol=roots.DEFAULT_RTOL,
                     illinois=True):
    """
    Frequencies, search effort and error against the exact Euler-Bernoulli values.

    Parameters
    ----------
    beam : beams.UniformBeam
        The beam.
    bc : str
        One of :data:`flexlink_ros.core.tmm.beams.BOUNDARY_CONDITIONS`.
    segments : int
        Segments (TMM) or elements (FE).
    method : str
        'tmm1', 'tmm2', 'tmm3' or 'fe'.
    search : str
        Root search of the TMM.
    step : float
        Scan increment [rad/s].
    modes : int
        Lowest modes computed.
    rtol : float
        Relative tolerance of the TMM root search.
    illinois : bool
        Illinois variant of false position.

    Returns
    -------
    dict
        JSON-ready result (see the module docstring).

    """
    _choice(method, METHODS, 'method')
    start = time.perf_counter()
    if method == 'fe':
        frequencies = list(eigen.fe_frequencies(beam, bc, segments, modes))
        iterations = paper_iterations = [None] * modes
        scan_evaluations = None
    else:
        result = solve.tmm_frequencies(beam, bc, segments, int(method[-1]), modes, search, step,
                                       rtol=rtol, illinois=illinois)
        frequencies = list(result.frequencies_rad_s)
        iterations = result.iterations
        paper_iterations = [root.iterations_paper_criterion for root in result.roots]
        scan_evaluations = result.scan_evaluations
    elapsed = time.perf_counter() - start
    exact = list(tmm_exact.exact_frequencies(beam, bc, modes))
    return {
        'boundary_condition': bc, 'method': method, 'segments': segments,
        'search': None if method == 'fe' else search,
        'step_rad_s': None if method == 'fe' else step, 'modes': modes,
        'frequencies_rad_s': frequencies,
        'iterations': iterations,
        'iterations_paper_criterion': paper_iterations,
        'scan_evaluations': scan_evaluations,
        'exact_rad_s': exact,
        'error_percent': [100.0 * (f - e) / e for f, e in zip(frequencies, exact)],
        'wall_time_s': elapsed,
        'tolerance': {'rtol': rtol, 'dtol_relative_to_bracket': roots.DEFAULT_DTOL,
                      'paper_determinant_kgf_mm': roots.PAPER_DETERMINANT_TOL,
                      'illinois': illinois},
        'beam': {'E_pa': beam.E, 'I_m4': beam.I, 'mass_per_length_kg_m': beam.mass_per_length,
                 'length_m': beam.length},
    }


def _table(result):
    head = (f'{result["boundary_condition"]} beam, {result["method"]}, '
            f'{result["segments"]} segments')
    if result['method'] != 'fe':
        head += (f', {result["search"]} search, step {result["step_rad_s"]:g} rad/s '
                 f'({result["scan_evaluations"]} scan points)')
    lines = [head, f'{"mode":>4} {"omega [rad/s]":>16} {"exact [rad/s]":>16} {"error %":>11} '
                   f'{"iterations":>10} {"paper crit.":>11}']
    rows = zip(result['frequencies_rad_s'], result['exact_rad_s'], result['error_percent'],
               result['iterations'], result['iterations_paper_criterion'])
    for mode, (omega, exact, error, count, paper) in enumerate(rows, start=1):
        lines.append(f'{mode:>4} {omega:>16.6f} {exact:>16.6f} {error:>11.4g} '
                     f'{"-" if count is None else count:>10} '
                     f'{"-" if paper is None else paper:>11}')
    lines.append(f'wall time {1e3 * result["wall_time_s"]:.2f} ms')
    return '\n'.join(lines)


def beam_command(args):
    """Run `flexlink beam`; returns the exit code."""
    bc = _choice(args.bc, beams.BOUNDARY_CONDITIONS, 'bc')
    method = _choice(args.method, METHODS, 'method')
    search = _choice(args.search, roots.SEARCHES, 'search')
    segments = _positive_int(args.segments, 'segments')
    modes = _positive_int(args.modes, 'modes')
    step = _positive_float(args.step, 'step')
    rtol = _positive_float(args.rtol, 'rtol')
    result = beam_frequencies(beam_from_args(args), bc, segments, method, search, step, modes,
                              rtol, illinois=not args.plain_false_position)
    return emit(result, _table(result), args.json)
