"""
Charts of the Earles-Wu joint criteria and the coil-spring design (Kang, Lee & Yoon 1990).

:func:`plot_criteria` writes four PNG files and returns markdown with the numbers:

- ``criteria_ratio_vs_crank.png``: |gamma_dot / R| against crank angle at joints A, B, O4
  (the paper's 1, 2, 3) and O2, log scale, for the original mechanism, the paper's spring and
  the design found by :func:`core.spring_design.design_spring`; true maxima marked.
- ``criteria_force_vs_crank.png``: reaction magnitude R against crank angle, same cases, with
  the force limits 1.5 R0 of Eq. 19.
- ``criteria_grid_vs_true.png``: the 1-degree-grid maxima (Table 2) against the refined true
  maxima per joint, and a zoom on the coupler-rocker peak with the grid samples.
- ``criteria_input_torque.png``: input torque with the limits of Eqs. 16-17.
"""

import dataclasses
import math
import pathlib

from matplotlib.figure import Figure
import numpy as np

from ..core import criteria, spring_design
from ..core.dynamics import solve_dynamics
from ..core.kinematics import solve_kinematics
from ..core.mechanism import JOINT_NAMES, load_mechanism, Spring

# Curve resolution [deg]: finer than the narrowest peak (about 1 degree wide).
CURVE_STEP_DEG = 0.02
PAPER_JOINT = {'A': 'joint 1 (A)', 'B': 'joint 2 (B)', 'O4': 'joint 3 (O4)', 'O2': 'O2'}
CASE_STYLE = {  # label colour
    'original': ('original (no spring)', 'tab:red'),
    'paper': ('paper spring K = 20, theta0 = 279.14 deg', 'tab:blue'),
    'design': ('this design', 'tab:green'),
}
# Kang 1990, Table 2 (1-degree grid), joints A, B, O4.
TABLE_2 = {'original': (42.77, 1319.45, 1011.35), 'paper': (15.80, 22.44, 22.03)}


def _cases(mechanism, design):
    paper_k, paper_deg = spring_design.PAPER_DESIGN
    return {'original': dataclasses.replace(mechanism, spring=None),
            'paper': dataclasses.replace(mechanism,
                                         spring=Spring(paper_k, math.radians(paper_deg))),
            'design': dataclasses.replace(mechanism,
                                          spring=Spring(design.stiffness, design.theta0))}


def plot_criteria(out_dir, mechanism=None):
    """
    Write the criteria charts into `out_dir`.

    Parameters
    ----------
    out_dir : str or pathlib.Path
        Directory (created if missing).
    mechanism : Mechanism or None
        Default: Kang 1990 (``config/kang1990.yaml``).

    Returns
    -------
    dict
        'charts': list of pathlib.Path; 'text': markdown with the numbers.

    """
    mechanism = mechanism or load_mechanism('kang1990')
    out = pathlib.Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    speed = mechanism.crank_speed
    found = spring_design.design_spring(mechanism)
    cases = _cases(mechanism, found['design'])
    theta_deg = np.arange(0.0, 360.0, CURVE_STEP_DEG)
    curves = {name: criteria.criterion_curves(mech, np.radians(theta_deg), speed)
              for name, mech in cases.items()}
    maxima = {name: criteria.evaluate_criteria(mech, speed) for name, mech in cases.items()}
    torques = {name: solve_dynamics(mech, solve_kinematics(mech, np.radians(theta_deg), speed))
               .input_torque for name, mech in cases.items()}
    design = found['design']
    labels = {name: style[0] for name, style in CASE_STYLE.items()}
    labels['design'] = (f'this design K = {design.stiffness:.2f}, theta0 = '
                        f'{math.degrees(design.theta0):.2f} deg')
    charts = [
        _plot_ratio(theta_deg, curves, maxima, labels, out / 'criteria_ratio_vs_crank.png'),
        _plot_force(theta_deg, curves, found, labels, out / 'criteria_force_vs_crank.png'),
        _plot_grid_vs_true(mechanism, maxima, out / 'criteria_grid_vs_true.png'),
        _plot_torque(theta_deg, torques, found, labels, out / 'criteria_input_torque.png'),
    ]
    return {'charts': charts, 'text': _text(maxima, found, speed)}


def _plot_ratio(theta_deg, curves, maxima, labels, path):
    fig = Figure(figsize=(11, 7.5), layout='constrained')
    axes = fig.subplots(2, 2, sharex=True).ravel()
    for ax, joint in zip(axes, ('A', 'B', 'O4', 'O2')):
        j = JOINT_NAMES.index(joint)
        for name, (_, colour) in CASE_STYLE.items():
            label = labels[name]
            peak = maxima[name][joint]
            ax.semilogy(theta_deg, curves[name]['ratio'][j], color=colour, lw=1.1,
                        label=f'{label}: max {peak.max_ratio:.2f}')
            ax.plot(math.degrees(peak.at_crank_angle), peak.max_ratio, 'v', color=colour, ms=7)
        ax.set_title(f'{PAPER_JOINT[joint]}')
        ax.set_ylim(1e-3, None)
        ax.grid(True, which='both', alpha=0.3)
        ax.legend(fontsize=7.5, loc='lower left')
        ax.set_ylabel('|gamma_dot / R|  [rad/(s N)]')
    for ax in axes[2:]:
        ax.set_xlabel('crank angle [deg] (0 = crank along O2->O4)')
        ax.set_xticks(np.arange(0, 361, 45))
    fig.suptitle('Earles-Wu criterion at 900 rpm (triangles: refined true maxima)')
    fig.savefig(path, dpi=110)
    return path


def _plot_force(theta_deg, curves, found, labels, path):
    fig = Figure(figsize=(11, 7.5), layout='constrained')
    axes = fig.subplots(2, 2, sharex=True).ravel()
    for ax, joint in zip(axes, ('A', 'B', 'O4', 'O2')):
        j = JOINT_NAMES.index(joint)
        for name, (_, colour) in CASE_STYLE.items():
            label = labels[name]
            ax.plot(theta_deg, curves[name]['force'][j], color=colour, lw=1.1, label=label)
        if joint in spring_design.DESIGN_JOINTS:
            limit = found['design'].constraints[f'force_{joint}']['limit']
            ax.axhline(limit, color='k', ls='--', lw=0.9, label='limit 1.5 R0 (Eq. 19)')
        ax.set_title(PAPER_JOINT[joint])
        ax.set_ylabel('reaction R [N]')
        ax.set_ylim(0.0, None)
        ax.grid(True, alpha=0.3)
    for ax in axes[2:]:
        ax.set_xlabel('crank angle [deg]')
        ax.set_xticks(np.arange(0, 361, 45))
    fig.legend(*axes[0].get_legend_handles_labels(), loc='outside lower center', ncols=4,
               fontsize=8)
    fig.suptitle('Joint reaction magnitude (zero-clearance rigid mechanism, 900 rpm)')
    fig.savefig(path, dpi=110)
    return path


def _plot_grid_vs_true(mechanism, maxima, path):
    fig = Figure(figsize=(12, 4.8), layout='constrained')
    left, right = fig.subplots(1, 2, width_ratios=(1.1, 1.0))
    joints = ('A', 'B', 'O4')
    x = np.arange(len(joints))
    width = 0.2
    for offset, (name, hatch) in zip((-1.5, 0.5), (('original', ''), ('paper', ''))):
        colour = CASE_STYLE[name][1]
        grid = [maxima[name][j].max_ratio_on_grid for j in joints]
        true = [maxima[name][j].max_ratio for j in joints]
        left.bar(x + offset * width, grid, width, color=colour, alpha=0.45,
                 label=f'{name}: 1-deg grid')
        left.bar(x + (offset + 1) * width, true, width, color=colour,
                 label=f'{name}: true maximum')
        for k, j in enumerate(joints):
            left.annotate(f'+{maxima[name][j].grid_shortfall_percent:.2f} %',
                          (x[k] + (offset + 1) * width, true[k]), ha='center', va='bottom',
                          fontsize=7.5)
        left.plot(x + offset * width, TABLE_2[name], 'k_', ms=14, mew=2)
    left.plot([], [], 'k_', ms=14, mew=2, label='Kang 1990 Table 2')
    left.set_yscale('log')
    left.set_xticks(x, [PAPER_JOINT[j] for j in joints])
    left.set_ylabel('max |gamma_dot / R| [rad/(s N)]')
    left.set_title('grid sample vs true maximum (label: how much the grid misses)')
    left.legend(fontsize=7.5, loc='upper left')
    left.grid(True, axis='y', which='both', alpha=0.3)

    peak = maxima['original']['B']
    centre = math.degrees(peak.at_crank_angle)
    fine = np.linspace(centre - 3.0, centre + 3.0, 3001)
    grid = np.arange(math.ceil(centre - 3.0), centre + 3.0, 1.0)
    j = JOINT_NAMES.index('B')
    for values, style, label in (
            (fine, '-', 'continuous'), (grid, 'o', '1-deg grid samples (Table 2)')):
        curve = criteria.criterion_curves(mechanism, np.radians(values))['ratio'][j]
        right.plot(values, curve, style, color='tab:red' if style == '-' else 'k', label=label)
    right.plot(centre, peak.max_ratio, 'v', color='tab:red', ms=9,
               label=f'true max {peak.max_ratio:.1f} at {centre:.3f} deg')
    right.axhline(TABLE_2['original'][1], color='0.4', ls=':', label='Table 2: 1319.45')
    right.set_xlabel('crank angle [deg]')
    right.set_ylabel('|gamma_dot / R| [rad/(s N)]')
    right.set_title('joint 2 (B), original: the peak is about a degree wide')
    right.legend(fontsize=7.5)
    right.grid(True, alpha=0.3)
    fig.savefig(path, dpi=110)
    return path


def _plot_torque(theta_deg, torques, found, labels, path):
    fig = Figure(figsize=(9, 4.5), layout='constrained')
    ax = fig.subplots()
    for name, (_, colour) in CASE_STYLE.items():
        label = labels[name]
        ax.plot(theta_deg, torques[name], color=colour, lw=1.2, label=label)
    limits = found['design'].constraints
    ax.axhline(limits['torque_max']['limit'], color='k', ls='--', lw=0.9,
               label='limits 1.7 TQ0 (Eqs. 16-17)')
    ax.axhline(limits['torque_min']['limit'], color='k', ls='--', lw=0.9)
    ax.axhline(0.0, color='0.5', lw=0.6)
    ax.set_xlabel('crank angle [deg]')
    ax.set_ylabel('input torque [N m]')
    ax.set_xticks(np.arange(0, 361, 45))
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title('Input torque at 900 rpm')
    fig.savefig(path, dpi=110)
    return path


def _text(maxima, found, speed):
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
