"""
The Earles-Wu joint criteria and the coil-spring design of Kang, Lee & Yoon (1990), computed.

:func:`criteria_data` evaluates, for the original mechanism, the paper's spring and the design
found by :func:`core.spring_design.design_spring`, the criterion and reaction curves, their
refined true maxima, the input torque, and a zoom on the coupler-rocker peak;
:func:`criteria_text` writes the numbers against the paper's Table 2. Drawing is
:mod:`report.criteria`.
"""

import dataclasses
import math

import numpy as np

from ..core import criteria, spring_design
from ..core.dynamics import solve_dynamics
from ..core.kinematics import solve_kinematics
from ..core.mechanism import Spring
from ..core.mechanism_file import load_mechanism
from ..names import JOINT_NAMES

# Curve resolution [deg]: finer than the narrowest peak (about 1 degree wide).
CURVE_STEP_DEG = 0.02
PAPER_JOINT = {'A': 'joint 1 (A)', 'B': 'joint 2 (B)', 'O4': 'joint 3 (O4)', 'O2': 'O2'}
# Kang 1990, Table 2 (1-degree grid), joints A, B, O4.
TABLE_2 = {'original': (42.77, 1319.45, 1011.35), 'paper': (15.80, 22.44, 22.03)}


def paper_cases(mechanism, design):
    """
    Return the three compared mechanisms: no spring, the paper's spring, the design found.

    Parameters
    ----------
    mechanism : Mechanism
        The linkage (its spring is replaced).
    design : object
        The design found (``stiffness`` [N m/rad], ``theta0`` [rad]).

    Returns
    -------
    dict of str to Mechanism
        'original', 'paper', 'design'.

    """
    paper_k, paper_deg = spring_design.PAPER_DESIGN
    return {'original': dataclasses.replace(mechanism, spring=None),
            'paper': dataclasses.replace(mechanism,
                                         spring=Spring(paper_k, math.radians(paper_deg))),
            'design': dataclasses.replace(mechanism,
                                          spring=Spring(design.stiffness, design.theta0))}


def criteria_data(mechanism=None):
    """
    Compute every number of the criteria report section (no plotting).

    Parameters
    ----------
    mechanism : Mechanism or None
        Default: Kang 1990 (``config/kang1990.yaml``).

    Returns
    -------
    dict
        'mechanism', 'speed' [rad/s], 'found' (:func:`core.spring_design.design_spring`),
        'theta_deg', 'curves', 'maxima' and 'torques' per case, 'zoom' (the coupler-rocker
        peak of the original mechanism, :func:`peak_zoom`).

    """
    mechanism = mechanism or load_mechanism('kang1990')
    speed = mechanism.crank_speed
    found = spring_design.design_spring(mechanism)
    cases = paper_cases(mechanism, found['design'])
    theta_deg = np.arange(0.0, 360.0, CURVE_STEP_DEG)
    curves = {name: criteria.criterion_curves(mech, np.radians(theta_deg), speed)
              for name, mech in cases.items()}
    maxima = {name: criteria.evaluate_criteria(mech, speed) for name, mech in cases.items()}
    torques = {name: solve_dynamics(mech, solve_kinematics(mech, np.radians(theta_deg), speed))
               .input_torque for name, mech in cases.items()}
    return {'mechanism': mechanism, 'speed': speed, 'found': found, 'theta_deg': theta_deg,
            'curves': curves, 'maxima': maxima, 'torques': torques,
            'zoom': peak_zoom(mechanism, maxima['original']['B'])}


def peak_zoom(mechanism, peak, joint='B', half_width_deg=3.0):
    """
    Criterion around a peak, continuous and on the 1-degree grid of Table 2.

    Parameters
    ----------
    mechanism : Mechanism
        The linkage.
    peak : object
        The joint's refined maximum (``at_crank_angle`` [rad], ``max_ratio``).
    joint : str
        The joint.
    half_width_deg : float
        Half the zoom window [deg].

    Returns
    -------
    dict
        'centre' [deg], 'peak', and ('fine', 'grid'): (crank angles [deg], |gamma_dot / R|).

    """
    centre = math.degrees(peak.at_crank_angle)
    fine = np.linspace(centre - half_width_deg, centre + half_width_deg, 3001)
    grid = np.arange(math.ceil(centre - half_width_deg), centre + half_width_deg, 1.0)
    j = JOINT_NAMES.index(joint)
    out = {'centre': centre, 'peak': peak}
    for key, values in (('fine', fine), ('grid', grid)):
        out[key] = (values, criteria.criterion_curves(mechanism, np.radians(values))['ratio'][j])
    return out


def criteria_text(data):
    """
    Write the markdown with the numbers: grid and true maxima, and the spring designs.

    Parameters
    ----------
    data : dict
        A :func:`criteria_data` result.

    Returns
    -------
    str

    """
    maxima, found, speed = data['maxima'], data['found'], data['speed']
    design, paper = found['design'], found['paper']
    lines = [f'Kang 1990 crank-rocker at {speed * 60 / (2 * math.pi):.0f} rpm, rigid links, '
             'no gravity. |gamma_dot/R| in rad/(s N); grid = 1 degree from the crank along '
             'O2->O4; true = refined maximum.', '',
             '| case | joint | Table 2 | 1-deg grid | true max | at crank [deg] | grid misses '
             '[%] | min R [N] |', '|---|---|---|---|---|---|---|---|']
    for name in ('original', 'paper'):
        for k, joint in enumerate(('A', 'B', 'O4')):
            c = maxima[name][joint]
            lines.append(f'| {name} | {PAPER_JOINT[joint]} | {TABLE_2[name][k]:.2f} | '
                         f'{c.max_ratio_on_grid:.2f} | {c.max_ratio:.2f} | '
                         f'{math.degrees(c.at_crank_angle):.3f} | '
                         f'{c.grid_shortfall_percent:.2f} | {c.min_force:.2f} |')
    lines += ['', 'Spring design (sum over A, B, O4 of the true maxima; K <= 20 N m/rad, '
              'theta0 in [0, 360] deg, torque within 1.7x and forces within 1.5x the '
              'original extremes):', '',
              '| design | K [N m/rad] | theta0 [deg] | objective | feasible | active limits |',
              '|---|---|---|---|---|---|']
    for label, entry in (('paper', paper), ('this tool', design)):
        lines.append(f'| {label} | {entry.stiffness:.3f} | {math.degrees(entry.theta0):.2f} | '
                     f'{entry.objective:.2f} | {entry.feasible} | '
                     f'{", ".join(entry.active) or "none"} |')
    torque = paper.constraints['torque_max']
    lines += ['', f"The paper's design stops on the torque limit (max torque "
              f'{torque["value"]:.4f} N m against {torque["limit"]:.4f}, '
              f'{-100 * torque["margin"]:.4f} % over); the global search lowers the objective '
              f'by {100 * (1 - design.objective / paper.objective):.0f} %.']
    return '\n'.join(lines)


__all__ = ['CURVE_STEP_DEG', 'PAPER_JOINT', 'TABLE_2', 'paper_cases', 'criteria_data',
           'peak_zoom', 'criteria_text']
