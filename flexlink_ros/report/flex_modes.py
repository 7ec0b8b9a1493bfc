"""
Frozen-frequency and mode-shape charts of the flexible four-bar (Cho 1992, Figs. 7-15).

Draws the sweeps and mode shapes computed by :func:`studies.flex_data.compute_flex`:
frequencies against the crank angle with the mode events marked (Figs. 7-13) and the lowest
three mode shapes at the paper's angles (Figs. 14-15).
"""

from matplotlib.figure import Figure
import numpy as np

from ..names import LINK_NAMES
from ..studies.flex_data import SHAPE_SPEED_RAD_S

LINK_COLOURS = ('tab:green', 'tab:blue', 'tab:red')
MODE_COLOURS = ('tab:blue', 'tab:orange', 'tab:green', 'tab:purple')
# The paper's mode-shape scale (mass-normalised eigenvector x 4/1000).
SHAPE_SCALE = 4e-3
DPI = 120


def _mark_events(ax, sweep, mode):
    """Mark a mode's veerings (circle) and swaps (cross) on a frequency axis."""
    for event in sweep.events:
        if mode not in event.modes:
            continue
        k = event.index
        deg = sweep.crank_deg[k]
        if event.kind == 'swap':   # drawn midway, at the mean of the two samples
            k1 = (k + 1) % len(sweep.crank_deg)
            deg = event.parameter % 360.0
            f = 0.5 * (sweep.frequencies_hz[k, mode] + sweep.frequencies_hz[k1, mode])
        else:
            f = sweep.frequencies_hz[k, mode]
        ax.plot([deg], [f], marker='o' if event.kind == 'veering' else 'X', color='black',
                markersize=7, markerfacecolor='none' if event.kind == 'veering' else 'black',
                linestyle='none')


def _event_legend(ax):
    """Legend entries for the event markers."""
    ax.plot([], [], marker='o', color='black', markerfacecolor='none', linestyle='none',
            label='veering (smallest gap)')
    ax.plot([], [], marker='X', color='black', linestyle='none',
            label='order swap between samples')


def plot_fig7(sweep, path):
    """Lowest three frequencies vs crank angle, all flexible, no K_G (Fig. 7)."""
    figure = Figure(figsize=(8.0, 4.8), layout='constrained')
    ax = figure.subplots()
    for m in range(sweep.frequencies_hz.shape[1]):
        f = sweep.frequencies_hz[:, m]
        ax.plot(sweep.crank_deg, f, color=MODE_COLOURS[m],
                label=f'mode {m + 1}: {f.min():.2f}-{f.max():.2f} Hz')
    for m in range(sweep.frequencies_hz.shape[1]):
        _mark_events(ax, sweep, m)
    ax.set_xlim(0, 360)
    ax.set_xticks(np.arange(0, 361, 45))
    ax.set_ylim(0, 1.1 * sweep.frequencies_hz.max())
    ax.set_xlabel('crank angle [deg]')
    ax.set_ylabel('natural frequency [Hz]')
    ax.set_title('Frozen natural frequencies, all links flexible, pins, no geometric '
                 'stiffness (Fig. 7)', fontsize=10)
    ax.grid(True, alpha=0.3)
    if sweep.events:
        _event_legend(ax)
    ax.legend(fontsize=8, loc='center right')
    figure.savefig(path, dpi=DPI)
    return path


def _plot_mode_panels(sweeps, styles, path, title):
    """One panel per mode (1-3), one curve per case."""
    figure = Figure(figsize=(13.0, 4.4), layout='constrained')
    axes = figure.subplots(1, 3)
    for m, ax in enumerate(axes):
        for key, style, colour in styles:
            if key not in sweeps:
                continue
            sweep = sweeps[key]
            ax.plot(sweep.crank_deg, sweep.frequencies_hz[:, m], linestyle=style,
                    color=colour, label=sweep.case.label)
            _mark_events(ax, sweep, m)
        ax.set_title(f'mode {m + 1}')
        ax.set_xlim(0, 360)
        ax.set_xticks(np.arange(0, 361, 90))
        ax.set_xlabel('crank angle [deg]')
        ax.grid(True, alpha=0.3)
    axes[0].set_ylabel('natural frequency [Hz]')
    if any(sweeps[key].events for key, _, _ in styles if key in sweeps):
        _event_legend(axes[0])
    handles, labels = axes[0].get_legend_handles_labels()
    figure.legend(handles, labels, loc='outside lower center', ncol=3, fontsize=8)
    figure.suptitle(title, fontsize=10)
    figure.savefig(path, dpi=DPI)
    return path


def plot_fig8_10(sweeps, path):
    """Modes 1-3: all flexible vs rigid crank, with and without K_G (Figs. 8-10)."""
    styles = [('flex_kg_30', '-', 'tab:blue'), ('flex_kg_45', '-', 'tab:cyan'),
              ('rigid_crank_kg_30', '--', 'tab:red'), ('rigid_crank_kg_45', '--', 'tab:pink'),
              ('flex', '-.', 'black'), ('rigid_crank', ':', 'grey')]
    title = ('Figs. 8-10: all flexible (solid) vs rigid crank (dashed) with K_G at 30 and 45 '
             'rad/s, and without K_G (chain, dotted); pins')
    return _plot_mode_panels(sweeps, styles, path, title)


def plot_fig11_13(sweeps, path):
    """Modes 1-3: rigid crank, rigid vs flexible bearings, 30 and 45 rad/s (Figs. 11-13)."""
    styles = [('rigid_crank_kg_30', '-', 'tab:blue'),
              ('rigid_crank_bearings_kg_30', '--', 'tab:red'),
              ('rigid_crank_bearings_kg_45', '-.', 'tab:purple')]
    title = ('Figs. 11-13: rigid crank, pins vs flexible bearings (k = 22.7 kN/m at all four '
             'joints), K_G at 30 and 45 rad/s')
    return _plot_mode_panels(sweeps, styles, path, title)


def plot_mode_shapes(shapes, deg, path):
    """Lowest three mode shapes at one crank angle, all flexible and rigid crank (Figs. 14-15)."""
    figure = Figure(figsize=(13.0, 7.0), layout='constrained')
    axes = figure.subplots(2, 3, sharex=True, sharey=True)
    for row, (key, name) in enumerate((('flex', 'all flexible'),
                                       ('rigid_crank', 'rigid crank'))):
        data = shapes[key]
        for m in range(3):
            ax = axes[row, m]
            positions = data['positions']
            for link in range(3):
                rigid = positions[link]
                ax.plot(rigid[:, 0] * 1e3, rigid[:, 1] * 1e3, color='0.75', linewidth=1.0)
                bent = rigid + SHAPE_SCALE * data['deflection'][m, link]
                ax.plot(bent[:, 0] * 1e3, bent[:, 1] * 1e3, color=LINK_COLOURS[link],
                        linewidth=2.0, label=LINK_NAMES[link])
            share = data['strain_share'][m]
            ax.set_title(f'({"abc"[m] if row == 0 else "def"[m]}) {name}, mode {m + 1}: '
                         f'{data["frequencies_hz"][m]:.1f} Hz\nstrain energy: crank '
                         f'{share[0]:.0%}, coupler {share[1]:.0%}, lever {share[2]:.0%}',
                         fontsize=9)
            ax.set_aspect('equal')
            ax.grid(True, alpha=0.3)
    for ax in axes[1]:
        ax.set_xlabel('X [mm]')
    for ax in axes[:, 0]:
        ax.set_ylabel('Y [mm]')
    axes[0, 0].legend(fontsize=8, loc='upper left')
    figure.suptitle(f'Mode shapes at crank angle {deg:g} deg (Fig. {14 if deg < 90 else 15}): '
                    f'mass-normalised x {SHAPE_SCALE:g} m/sqrt(kg) as in the paper; grey = '
                    f'undeformed; pins, '
                    f'K_G at {SHAPE_SPEED_RAD_S:g} rad/s', fontsize=10)
    figure.savefig(path, dpi=DPI)
    return path


__all__ = ['plot_fig7', 'plot_fig8_10', 'plot_fig11_13', 'plot_mode_shapes']
