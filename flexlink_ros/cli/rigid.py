"""
Rigid-body commands: ``flexlink kinematics``, ``flexlink criteria``, ``flexlink design-spring``.

    flexlink kinematics --mechanism M [--crank-deg 0:360:10] [--rpm R] [--json]
    flexlink criteria --mechanism M [--spring K THETA0_DEG] [--grid-deg 1] [--rpm R] [--json]
                      [--suggest-thresholds [--rate-hz 1000]]
    flexlink design-spring --mechanism M [--rpm R] [--seed S] [--theta0-max-deg 360] [--json]

``M`` is a mechanism file or a bare name (``kang1990``). Criteria JSON:
``{"joints": {"O2": J, "A": J, "B": J, "O4": J}, ...}`` with ``J`` holding ``max_ratio``
(true maximum of |gamma_dot / R| [rad/(s N)]), ``at_crank_deg``, ``max_ratio_on_grid``,
``at_grid_deg``, ``grid_shortfall_percent``, ``min_force_n``, ``near_zero_force`` and more.
Design JSON: ``k_nm_per_rad``, ``theta0_deg``, ``objective``, ``paper_objective``, per-joint
maxima, constraints with margins, active limits and the paper's design evaluated alike.
"""

import argparse
import dataclasses
import math

import numpy as np

from .main import degree_range, emit
from ..core import criteria as core_criteria
from ..core import spring_design
from ..core.criteria_thresholds import suggest_thresholds
from ..core.kinematics import dead_centres, solve_kinematics, transmission_extremes
from ..core.mechanism import Spring
from ..core.mechanism_file import load_mechanism
from ..names import JOINT_NAMES, LINK_NAMES

# Paper numbering of the clearance joints (Kang 1990).
PAPER_JOINT = {'A': 1, 'B': 2, 'O4': 3}


def register(subparsers):
    """Add the `kinematics`, `criteria` and `design-spring` subcommands."""
    kin = subparsers.add_parser('kinematics', help='rigid-body link angles, rates, joint '
                                'positions, transmission angle and dead centres')
    _mechanism_args(kin)
    kin.add_argument('--crank-deg', default='0:360:10',
                     help='crank angles START:STOP:STEP or a comma list [deg] (default 0:360:10)')
    kin.add_argument('--accel', default='0', help='crank acceleration [rad/s^2] (default 0)')
    kin.set_defaults(func=kinematics_command)

    crit = subparsers.add_parser('criteria', help='Earles-Wu joint criteria |gamma_dot/R|: '
                                 'true maxima, grid maxima, minimum forces')
    _mechanism_args(crit)
    crit.add_argument('--spring', nargs=2, metavar=('K', 'THETA0_DEG'), default=None,
                      help='coil spring between coupler and lever [N m/rad, deg] '
                           "(replaces the file's)")
    crit.add_argument('--grid-deg', default='1', help='user grid step from 0 [deg] (default 1)')
    crit.add_argument('--scan-points', default=str(core_criteria.SCAN_POINTS),
                      help='scan size before peak refinement')
    crit.add_argument('--suggest-thresholds', action='store_true',
                      help="also derive the node's diagnostics.criterion_warn / "
                      'criterion_error from this cycle (docs/criterion-thresholds.md)')
    crit.add_argument('--rate-hz', default='1000',
                      help='input sample rate of the maxima the node sees (default 1000)')
    crit.set_defaults(func=criteria_command)

    design = subparsers.add_parser('design-spring', help='coil-spring design against '
                                   'contact loss (Kang 1990) by a global search')
    _mechanism_args(design)
    design.add_argument('--seed', default='0', help='differential-evolution seed (default 0)')
    design.add_argument('--maxiter', default='60', help='generations (default 60)')
    design.add_argument('--popsize', default='15', help='population multiplier (default 15)')
    design.add_argument('--k-max', default=str(spring_design.STIFFNESS_MAX),
                        help="upper bound of K [N m/rad] (default 20, the paper's)")
    design.add_argument('--theta0-max-deg', default='360',
                        help="upper bound of theta0 [deg] (default 360, the paper's; larger "
                             'means a spring pre-wound by more than a turn)')
    design.set_defaults(func=design_spring_command)


def _mechanism_args(parser):
    parser.add_argument('--mechanism', default='kang1990',
                        help='mechanism file or bare name (default kang1990)')
    parser.add_argument('--rpm', default=None,
                        help="crank speed [rpm] (default: the mechanism file's)")
    parser.add_argument('--json', action='store_true', help='print one JSON object')


def _number(text, name, positive=False, integer=False):
    try:
        value = int(text) if integer else float(text)
    except (TypeError, ValueError):
        kind = 'an integer' if integer else 'a number'
        raise ValueError(f'`--{name}` must be {kind}, got {text!r}') from None
    if not math.isfinite(value) or (positive and value <= 0):
        raise ValueError(f'`--{name}` must be {"positive" if positive else "finite"}, '
                         f'got {text!r}')
    return value


def _speed(args, mechanism, required=True):
    """Crank speed [rad/s] from --rpm or the mechanism file."""
    if args.rpm is not None:
        rpm = _number(args.rpm, 'rpm')
        if rpm == 0.0:
            raise ValueError('`--rpm` must be non-zero')
        return rpm * 2.0 * math.pi / 60.0
    if mechanism.crank_speed is None and required:
        raise ValueError('the mechanism file gives no crank speed: pass `--rpm`')
    return mechanism.crank_speed


def kinematics_result(mechanism, crank_deg, crank_speed, crank_accel=0.0):
    """
    JSON-ready rigid-body kinematics at given crank angles.

    Parameters
    ----------
    mechanism : Mechanism
        The linkage.
    crank_deg : sequence of float
        Crank angles [deg].
    crank_speed, crank_accel : float
        [rad/s], [rad/s^2].

    Returns
    -------
    dict

    """
    theta = np.radians(np.asarray(crank_deg, dtype=float))
    state = solve_kinematics(mechanism, theta, crank_speed, crank_accel)
    links = {name: {'angle_deg': np.degrees(state.angle[k]),
                    'omega_rad_s': state.omega[k], 'alpha_rad_s2': state.alpha[k]}
             for k, name in enumerate(LINK_NAMES)}
    joints = {name: {'x_m': state.joints[name].real, 'y_m': state.joints[name].imag}
              for name in JOINT_NAMES}
    low, high = transmission_extremes(mechanism)
    return {'mechanism': mechanism.name, 'crank_deg': list(map(float, crank_deg)),
            'crank_speed_rad_s': crank_speed, 'crank_accel_rad_s2': crank_accel,
            'links': links, 'joints': joints,
            'transmission_angle_deg': np.degrees(state.transmission_angle),
            'transmission_extremes_deg': [math.degrees(low), math.degrees(high)],
            'dead_centres_deg': [math.degrees(a) for a in dead_centres(mechanism)]}


def kinematics_command(args):
    """`flexlink kinematics`."""
    mechanism = load_mechanism(args.mechanism)
    try:
        crank_deg = degree_range(args.crank_deg)
    except argparse.ArgumentTypeError as exc:
        raise ValueError(f'`--crank-deg`: {exc}') from None
    speed = _speed(args, mechanism, required=False)
    speed = 1.0 if speed is None else speed
    result = kinematics_result(mechanism, crank_deg, speed, _number(args.accel, 'accel'))
    lines = [f'{mechanism.name}: crank speed {speed:g} rad/s; dead centres (crank) '
             + ', '.join(f'{a:.3f}' for a in result['dead_centres_deg']) + ' deg; '
             f'transmission angle {result["transmission_extremes_deg"][0]:.2f} .. '
             f'{result["transmission_extremes_deg"][1]:.2f} deg',
             f'{"crank":>8} {"coupler":>9} {"lever":>9} {"w3":>9} {"w4":>9} {"a3":>10} '
             f'{"a4":>10} {"mu":>7}   [deg, rad/s, rad/s^2]']
    for k, theta in enumerate(crank_deg):
        values = [result['links']['coupler']['angle_deg'][k],
                  result['links']['lever']['angle_deg'][k],
                  result['links']['coupler']['omega_rad_s'][k],
                  result['links']['lever']['omega_rad_s'][k],
                  result['links']['coupler']['alpha_rad_s2'][k],
                  result['links']['lever']['alpha_rad_s2'][k],
                  result['transmission_angle_deg'][k]]
        lines.append(f'{theta:8.2f} {values[0]:9.3f} {values[1]:9.3f} {values[2]:9.3f} '
                     f'{values[3]:9.3f} {values[4]:10.1f} {values[5]:10.1f} {values[6]:7.2f}')
    return emit(result, '\n'.join(lines), args.json)


def criteria_result(mechanism, crank_speed, grid_deg=1.0,
                    scan_points=core_criteria.SCAN_POINTS):
    """
    JSON-ready Earles-Wu criteria of every joint.

    Parameters
    ----------
    mechanism : Mechanism
        With its spring, if any.
    crank_speed : float
        [rad/s].
    grid_deg : float
        User-grid step [deg] from 0.
    scan_points : int
        Points of the scan that brackets each criterion's extremes.

    Returns
    -------
    dict

    """
    found = core_criteria.evaluate_criteria(mechanism, crank_speed, grid_deg,
                                            scan_points=scan_points)
    spring = mechanism.spring
    return {'mechanism': mechanism.name, 'crank_speed_rad_s': crank_speed,
            'rpm': crank_speed * 60.0 / (2.0 * math.pi), 'grid_deg': grid_deg,
            'spring': None if spring is None else {
                'k_nm_per_rad': spring.stiffness, 'theta0_deg': math.degrees(spring.theta0)},
            'joints': {j: c.as_dict() for j, c in found.items()},
            'objective': sum(found[j].max_ratio for j in spring_design.DESIGN_JOINTS),
            'objective_on_grid': sum(found[j].max_ratio_on_grid
                                     for j in spring_design.DESIGN_JOINTS),
            'near_zero_force_fraction': core_criteria.NEAR_ZERO_FRACTION}


def criteria_command(args):
    """`flexlink criteria`."""
    mechanism = load_mechanism(args.mechanism)
    if args.spring is not None:
        stiffness = _number(args.spring[0], 'spring K')
        if stiffness < 0:
            raise ValueError(f'`--spring` K must be >= 0, got {args.spring[0]!r}')
        theta0 = math.radians(_number(args.spring[1], 'spring THETA0_DEG'))
        mechanism = dataclasses.replace(mechanism, spring=Spring(stiffness, theta0))
    speed = _speed(args, mechanism)
    grid = _number(args.grid_deg, 'grid-deg', positive=True)
    scan = _number(args.scan_points, 'scan-points', positive=True, integer=True)
    result = criteria_result(mechanism, speed, grid, scan)
    spring = result['spring']
    lines = [f'{mechanism.name} at {result["rpm"]:g} rpm, '
             + ('no spring' if spring is None else
                f'spring K = {spring["k_nm_per_rad"]:g} N m/rad, '
                f'theta0 = {spring["theta0_deg"]:g} deg')
             + f'; |gamma_dot/R| [rad/(s N)], grid {grid:g} deg from 0',
             f'{"joint":6} {"true max":>11} {"at deg":>8} {"grid max":>11} {"at deg":>7} '
             f'{"grid low %":>10} {"min R N":>9} {"at deg":>8}']
    for joint, c in result['joints'].items():
        label = f'{joint}' + (f' ({PAPER_JOINT[joint]})' if joint in PAPER_JOINT else '')
        flag = '  near-zero R' if c['near_zero_force'] else ''
        lines.append(f'{label:6} {c["max_ratio"]:11.4f} {c["at_crank_deg"]:8.3f} '
                     f'{c["max_ratio_on_grid"]:11.4f} {c["at_grid_deg"]:7.1f} '
                     f'{c["grid_shortfall_percent"]:10.3f} {c["min_force_n"]:9.3f} '
                     f'{c["at_min_force_deg"]:8.3f}{flag}')
    lines.append(f'objective (A + B + O4): true {result["objective"]:.4f}, '
                 f'on grid {result["objective_on_grid"]:.4f}')
    if args.suggest_thresholds:
        result['thresholds'] = suggest_thresholds(
            mechanism, speed, _number(args.rate_hz, 'rate-hz', positive=True))
        lines += threshold_lines(result['thresholds'])
    return emit(result, '\n'.join(lines), args.json)


def threshold_lines(found):
    """Say the suggested thresholds, what they come from and the joints left out."""
    lines = [f'suggested thresholds ({found["warn_margin"]:g} and {found["error_factor"]:g} '
             f'times the largest true maximum, {found["basis"]:.4g} rad/(s N)):',
             f'  diagnostics.criterion_warn: {found["warn"]:.6g}',
             f'  diagnostics.criterion_error: {found["error"]:.6g}',
             f'  sampled at {found["rate_hz"]:g} Hz the node sees at most: ' + ', '.join(
                 f'{j} {v["sampled_max"]:.4g}' for j, v in found['joints'].items())]
    for joint, value in found['joints'].items():
        if not value['used']:
            lines.append(f'  {joint}: its reaction falls to {100 * value["min_over_rms"]:.2g} % '
                         f'of its RMS (criterion peak {value["true_max"]:.4g}): a contact-loss '
                         'risk in this cycle itself, left out; the node flags it when its '
                         'samples meet the peak')
    return lines


def design_result(found):
    """JSON-ready form of :func:`core.spring_design.design_spring`'s result."""
    design, paper = found['design'], found['paper']
    out = design.as_dict()
    out['paper_objective'] = paper.objective
    out['paper'] = paper.as_dict()
    out['improvement_percent'] = 100.0 * (1.0 - design.objective / paper.objective)
    out['reference'] = found['reference']
    out['limits'] = {'force_factor': spring_design.FORCE_FACTOR,
                     'torque_factor': spring_design.TORQUE_FACTOR}
    out['search'] = found['search']
    return out


def design_spring_command(args):
    """`flexlink design-spring`."""
    mechanism = load_mechanism(args.mechanism)
    speed = _speed(args, mechanism)
    theta0_max = _number(args.theta0_max_deg, 'theta0-max-deg', positive=True)
    found = spring_design.design_spring(
        mechanism, speed, seed=_number(args.seed, 'seed', integer=True),
        maxiter=_number(args.maxiter, 'maxiter', positive=True, integer=True),
        popsize=_number(args.popsize, 'popsize', positive=True, integer=True),
        theta0_bounds_deg=(0.0, theta0_max),
        stiffness_max=_number(args.k_max, 'k-max', positive=True))
    result = design_result(found)
    lines = []
    for title, entry in (('design', result), ('paper', result['paper'])):
        ratios = ', '.join(f'{j} {entry["max_ratio"][j]:.3f}'
                           for j in spring_design.DESIGN_JOINTS)
        lines.append(f'{title:7} K = {entry["k_nm_per_rad"]:8.4f} N m/rad, theta0 = '
                     f'{entry["theta0_deg"]:8.3f} deg: objective {entry["objective"]:.4f} '
                     f'rad/(s N) ({ratios}); feasible {entry["feasible"]}, active: '
                     f'{", ".join(entry["active"]) or "none"}')
    margins = ', '.join(f'{name} {c["margin"] * 100:.2f} %'
                        for name, c in result['constraints'].items())
    lines.append(f'design limit margins: {margins}')
    lines.append(f'improvement over the paper: {result["improvement_percent"]:.1f} %')
    return emit(result, '\n'.join(lines), args.json)
