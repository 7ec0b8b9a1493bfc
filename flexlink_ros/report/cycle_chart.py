"""
One chart of a run over crank angle: the deflections and the joint criteria, any mechanism.

``flexlink replay --chart PNG`` and ``flexlink estimate --chart PNG`` draw it: the lever tip's
and the coupler mid-point's elastic deflections (dx, dy) [um] and the Earles-Wu criterion
|dgamma/dt|/R of each joint (log scale, with the WARN and ERROR thresholds) against the crank
angle in [0, 360) degrees; every sample is a dot, so the revolutions of a recording lie on
each other. matplotlib is imported only when a chart is drawn.
"""

import pathlib

import numpy as np

from ..names import JOINT_NAMES

MAX_POINTS = 200_000   # samples drawn at most (evenly thinned above)
JOINT_COLOURS = ('tab:blue', 'tab:orange', 'tab:green', 'tab:red')
COMPONENT_COLOURS = {'dx': 'tab:blue', 'dy': 'tab:orange'}


def _thinned(count):
    return np.arange(0, count, max(1, -(-count // MAX_POINTS)))


def plot_cycle(path, crank_rad, lever_tip, coupler_mid, criterion, title='',
               thresholds=(100.0, 1000.0, '')):
    """
    Draw deflections and joint criteria over crank angle into a PNG.

    Parameters
    ----------
    path : str or os.PathLike
        PNG to write (its folder is created).
    crank_rad : ndarray, shape (m,)
        Crank angle of each sample [rad] (any range).
    lever_tip, coupler_mid : ndarray, shape (m, 2)
        Deflections (dx, dy) [m]; rows with a NaN (skipped samples) are left out.
    criterion : ndarray, shape (m, 4) or None
        |dgamma/dt|/R of O2, A, B, O4 [rad/(s N)]; None or all zero: the panel says so.
    title : str
        Figure title (the mechanism, speed, model).
    thresholds : (float, float) or (float, float, str)
        WARN and ERROR levels of the criterion, drawn as dashed lines, and what they are
        (in the legend: "this linkage's cycle at 60 rpm", "node default").

    Returns
    -------
    pathlib.Path

    """
    from matplotlib.figure import Figure   # only when drawing: replay and estimate start fast

    lever_tip, coupler_mid = np.asarray(lever_tip), np.asarray(coupler_mid)
    kept = np.flatnonzero(np.all(np.isfinite(lever_tip), axis=1)
                          & np.all(np.isfinite(coupler_mid), axis=1))
    kept = kept[_thinned(kept.size)]
    degrees = np.mod(np.degrees(np.asarray(crank_rad)[kept]), 360.0)
    figure = Figure(figsize=(10.0, 9.0), layout='constrained')
    axes = figure.subplots(3, 1, sharex=True)
    for ax, values, name in ((axes[0], lever_tip, 'lever tip'),
                             (axes[1], coupler_mid, 'coupler mid-point')):
        for column, component in enumerate(('dx', 'dy')):
            ax.plot(degrees, 1e6 * values[kept, column], '.', markersize=1.5,
                    color=COMPONENT_COLOURS[component], label=component)
        ax.set_title(f'{name} elastic deflection')
        ax.set_ylabel('deflection [um]')
        ax.legend(loc='upper right', markerscale=6, fontsize=8)
    _criteria_panel(axes[2], degrees, None if criterion is None else
                    np.asarray(criterion)[kept], thresholds)
    for ax in axes:
        ax.grid(True, alpha=0.3)
        ax.set_xlim(0.0, 360.0)
    axes[2].set_xticks(np.arange(0, 361, 45))
    axes[2].set_xlabel('crank angle [deg]')
    if title:
        figure.suptitle(title)
    path = pathlib.Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(path, dpi=100)
    return path


def _criteria_panel(ax, degrees, criterion, thresholds):
    """Draw the joints' criteria on a log scale with the thresholds, or say there are none."""
    ax.set_title('Earles-Wu joint criterion |dgamma/dt| / R')
    ax.set_ylabel('[rad/(s N)]')
    if criterion is None or not np.any(criterion > 0.0):
        ax.text(0.5, 0.5, 'no joint-reaction data in this model', ha='center',
                va='center', transform=ax.transAxes)
        return
    for joint, (name, colour) in enumerate(zip(JOINT_NAMES, JOINT_COLOURS)):
        positive = criterion[:, joint] > 0.0
        ax.plot(degrees[positive], criterion[positive, joint], '.', markersize=1.5,
                color=colour, label=f'joint {name}')
    note = f' ({thresholds[2]})' if len(thresholds) > 2 and thresholds[2] else ''
    for level, value, style in zip(('WARN', 'ERROR'), thresholds[:2], ('--', '-.')):
        ax.axhline(value, color='black', linestyle=style, linewidth=1.0,
                   label=f'{level} {value:.3g}{note}')
    ax.set_yscale('log')
    # Below the panel: inside it the legend hid the highest criteria and the threshold lines.
    ax.legend(loc='upper center', bbox_to_anchor=(0.5, -0.2), markerscale=6, fontsize=8,
              ncol=3)
