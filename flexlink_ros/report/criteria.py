"""
Charts of the Earles-Wu joint criteria and the coil-spring design (Kang, Lee & Yoon 1990).

:func:`plot_criteria` writes four PNG files and returns markdown with the numbers:

- ``criteria_ratio_vs_crank.png``: |gamma_dot / R| against crank angle at joints O2, A, B,
  O4 (the node's names; the paper's 1, 2, 3 are A, B, O4), log scale, for the original
  mechanism, the paper's spring and the design found by
  :func:`core.spring_design.design_spring`; true maxima marked.
- ``criteria_force_vs_crank.png``: reaction magnitude R against crank angle, same cases, with
  the force limits 1.5 R0 of Eq. 19.
- ``criteria_grid_vs_true.png``: the 1-degree-grid maxima (Table 2) against the refined true
  maxima per joint, and a zoom on the coupler-rocker peak with the grid samples.
- ``criteria_input_torque.png``: input torque with the limits of Eqs. 16-17.
"""

import math
import pathlib

from matplotlib.figure import Figure
import numpy as np

from ..core import spring_design
from ..names import JOINT_NAMES
from ..studies.criteria_check import criteria_data, criteria_text, TABLE_2

# Joints named as the node names them (names.JOINT_NAMES, its /diagnostics and outputs), the
# paper's numbers (Kang 1990: 1, 2, 3 for A, B, O4) after them.
JOINT_TITLE = {'O2': 'O2 (ground-crank; no number in Kang 1990)',
               'A': 'A (Kang 1990 joint 1)', 'B': 'B (Kang 1990 joint 2)',
               'O4': 'O4 (Kang 1990 joint 3)'}

CASE_STYLE = {  # label colour
    'original': ('original (no spring)', 'tab:red'),
    'paper': ('paper spring K = 20, theta0 = 279.14 deg', 'tab:blue'),
    'design': ('this design', 'tab:green'),
}


def plot_criteria(out_dir, mechanism=None, data=None):
    """
    Write the criteria charts into `out_dir`.

    Parameters
    ----------
    out_dir : str or pathlib.Path
        Directory (created if missing).
    mechanism : Mechanism or None
        Default: Kang 1990 (``config/kang1990.yaml``).
    data : dict or None
        A :func:`studies.criteria_check.criteria_data` result to draw (computed for
        ``mechanism`` if None).

    Returns
    -------
    dict
        'charts': list of pathlib.Path; 'text': markdown with the numbers.

    """
    out = pathlib.Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    if data is None:
        data = criteria_data(mechanism)
    theta_deg, curves, maxima = data['theta_deg'], data['curves'], data['maxima']
    found = data['found']
    design = found['design']
    labels = {name: style[0] for name, style in CASE_STYLE.items()}
    labels['design'] = (f'this design K = {design.stiffness:.2f}, theta0 = '
                        f'{math.degrees(design.theta0):.2f} deg')
    charts = [
        _plot_ratio(theta_deg, curves, maxima, labels, out / 'criteria_ratio_vs_crank.png'),
        _plot_force(theta_deg, curves, found, labels, out / 'criteria_force_vs_crank.png'),
        _plot_grid_vs_true(data['zoom'], maxima, out / 'criteria_grid_vs_true.png'),
        _plot_torque(theta_deg, data['torques'], found, labels,
                     out / 'criteria_input_torque.png'),
    ]
    return {'charts': charts, 'text': criteria_text(data)}


def _plot_ratio(theta_deg, curves, maxima, labels, path):
    fig = Figure(figsize=(11, 7.5), layout='constrained')
    axes = fig.subplots(2, 2, sharex=True).ravel()
    for ax, joint in zip(axes, JOINT_NAMES):
        j = JOINT_NAMES.index(joint)
        for name, (_, colour) in CASE_STYLE.items():
            label = labels[name]
            peak = maxima[name][joint]
            ax.semilogy(theta_deg, curves[name]['ratio'][j], color=colour, lw=1.1,
                        label=f'{label}: max {peak.max_ratio:.2f}')
            ax.plot(math.degrees(peak.at_crank_angle), peak.max_ratio, 'v', color=colour, ms=7)
        ax.set_title(JOINT_TITLE[joint])
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
    for ax, joint in zip(axes, JOINT_NAMES):
        j = JOINT_NAMES.index(joint)
        for name, (_, colour) in CASE_STYLE.items():
            label = labels[name]
            ax.plot(theta_deg, curves[name]['force'][j], color=colour, lw=1.1, label=label)
        if joint in spring_design.DESIGN_JOINTS:
            limit = found['design'].constraints[f'force_{joint}']['limit']
            ax.axhline(limit, color='k', ls='--', lw=0.9, label='limit 1.5 R0 (Eq. 19)')
        ax.set_title(JOINT_TITLE[joint])
        ax.set_ylabel('reaction R [N]')
        ax.set_ylim(0.0, None)
        ax.grid(True, alpha=0.3)
    for ax in axes[2:]:
        ax.set_xlabel('crank angle [deg]')
        ax.set_xticks(np.arange(0, 361, 45))
    entries = {}    # every case and the force limit (drawn only at the design's joints)
    for ax in axes:
        for handle, label in zip(*ax.get_legend_handles_labels()):
            entries.setdefault(label, handle)
    fig.legend(entries.values(), entries.keys(), loc='outside lower center', ncols=4,
               fontsize=8)
    fig.suptitle('Joint reaction magnitude (zero-clearance rigid mechanism, 900 rpm)')
    fig.savefig(path, dpi=110)
    return path


def _plot_grid_vs_true(zoom, maxima, path):
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
    left.set_xticks(x, [JOINT_TITLE[j].replace(' (', '\n(') for j in joints])
    left.set_ylabel('max |gamma_dot / R| [rad/(s N)]')
    left.set_title('grid sample vs true maximum (label: how much the grid misses)')
    left.legend(fontsize=7.5, loc='upper left')
    left.grid(True, axis='y', which='both', alpha=0.3)

    peak, centre = zoom['peak'], zoom['centre']
    for key, style, label in (('fine', '-', 'continuous'),
                              ('grid', 'o', '1-deg grid samples (Table 2)')):
        values, curve = zoom[key]
        right.plot(values, curve, style, color='tab:red' if style == '-' else 'k', label=label)
    right.plot(centre, peak.max_ratio, 'v', color='tab:red', ms=9,
               label=f'true max {peak.max_ratio:.1f} at {centre:.3f} deg')
    right.axhline(TABLE_2['original'][1], color='0.4', ls=':', label='Table 2: 1319.45')
    right.set_xlabel('crank angle [deg]')
    right.set_ylabel('|gamma_dot / R| [rad/(s N)]')
    right.set_title(f'{JOINT_TITLE["B"]}, original: a peak 1 deg wide')
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


__all__ = ['plot_criteria']
