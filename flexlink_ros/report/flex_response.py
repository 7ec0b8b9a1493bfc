"""
Response charts of the flexible four-bar (Cho 1992, Figs. 16-22) and its modal truncation.

Draws the responses computed by :func:`studies.flex_data.compute_flex`: the deflected linkage
(Figs. 16-19), the lever-tip and coupler mid-point deflections (Figs. 20-21), the coupler
mid-point path (Fig. 22) and the truncation error against the number of modes.
"""

from matplotlib import colormaps
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator
import numpy as np

from ..core.kinematics import solve_kinematics
from ..studies.flex_data import SHAPE_SPEED_RAD_S
from ..studies.flex_frequencies import BEARINGS, PAPER_RPM
from ..studies.flex_measures import coupler_mid_path
from ..studies.flex_text import deflection_unit
from ..studies.flex_truncation import TOLERANCES

# Quarter-turn panels of Figs. 16-19 [deg] (start, stop) every 3 degrees.
QUARTERS_DEG = ((45.0, 132.0), (135.0, 222.0), (225.0, 312.0), (315.0, 402.0))
DPI = 120


def _exaggeration(deflection, reference_length):
    """Choose a round factor making the largest deflection about 5 % of reference_length."""
    peak = np.abs(deflection).max()
    raw = 0.05 * reference_length / max(peak, 1e-12)
    for factor in (1, 2, 5, 10, 20, 50, 100, 200, 500, 1000):
        if factor >= raw:
            return factor
    return 1000


def plot_deflected_linkage(linkage, mechanism, path):
    """Draw the deflected linkage every 3 degrees at 30 rad/s in quarter turns (Figs. 16-19)."""
    deg = linkage['crank_deg']
    positions, deflection = linkage['positions'], linkage['deflection']
    factor = _exaggeration(deflection, mechanism.lengths[2])
    figure = Figure(figsize=(12.0, 9.0), layout='constrained')
    axes = figure.subplots(2, 2, sharex=True, sharey=True)
    cmap = colormaps['viridis']
    for ax, (start, stop), fig in zip(axes.ravel(), QUARTERS_DEG, (16, 17, 18, 19)):
        chosen = [k for k, d in enumerate(deg)
                  if (d - start) % 360.0 <= (stop - start) + 1e-9 and
                  np.isclose((d - start) % 3.0, 0.0, atol=1e-6)]
        chosen.sort(key=lambda k: (deg[k] - start) % 360.0)   # in order of travel
        for rank, k in enumerate(chosen):
            colour = cmap(rank / max(len(chosen) - 1, 1))
            for link in range(3):
                shape = positions[k, link] + factor * deflection[k, link]
                ax.plot(shape[:, 0] * 1e3, shape[:, 1] * 1e3, color=colour, linewidth=0.8)
        ground = np.array([0.0, mechanism.ground_length]) * 1e3
        ax.plot(ground, [0.0, 0.0], 'k^', markersize=9)
        ax.set_title(f'crank {start:g} to {stop % 360:g} deg (Fig. {fig}); colour: '
                     f'early (purple) to late (yellow)', fontsize=9)
        ax.set_aspect('equal')
        ax.grid(True, alpha=0.3)
    for ax in axes[1]:
        ax.set_xlabel('X [mm]')
    for ax in axes[:, 0]:
        ax.set_ylabel('Y [mm]')
    coupler = np.abs(deflection[:, 1]).max()
    figure.suptitle(f'Deflected linkage every 3 deg at {SHAPE_SPEED_RAD_S:g} rad/s, all links '
                    'flexible, pins, K_G on'
                    f': deflections x {factor} (largest true coupler deflection '
                    f'{1e3 * coupler:.2f} mm)', fontsize=10)
    figure.savefig(path, dpi=DPI)
    return path


def plot_point_deflections(responses, columns, name, fig, path):
    """X (solid) and Y (dashed) deflection of one point, bearings x speeds (Figs. 20-21)."""
    figure = Figure(figsize=(11.0, 7.0), layout='constrained')
    axes = figure.subplots(2, 2, sharex=True)
    for row, bearings in enumerate(BEARINGS):
        for col, rpm in enumerate(PAPER_RPM):
            ax = axes[row, col]
            response = responses[bearings, rpm]
            deg = np.mod(np.degrees(response.crank_angle), 360.0)
            order = np.argsort(deg)
            values = response.outputs[:, columns]
            scale, unit = deflection_unit(values)
            p2p = values.max(axis=0) - values.min(axis=0)
            # one periodic revolution: repeat the first sample at +360 degrees
            deg_closed = np.append(deg[order], deg[order[0]] + 360.0)
            closed = np.vstack([values[order], values[order[:1]]])
            ax.plot(deg_closed, scale * closed[:, 0], color='tab:blue', label='X')
            ax.plot(deg_closed, scale * closed[:, 1], color='tab:red', linestyle='--',
                    label='Y')
            ax.set_title(f'({"abcd"[2 * row + col]}) {bearings} bearings, {rpm:g} rpm: '
                         f'peak-to-peak X {scale * p2p[0]:.3g}, Y {scale * p2p[1]:.3g} {unit}',
                         fontsize=9)
            ax.set_ylabel(f'deflection [{unit}]')
            ax.set_xlim(0, 360)
            ax.set_xticks(np.arange(0, 361, 60))
            ax.axhline(0.0, color='0.6', linewidth=0.6)
            ax.grid(True, alpha=0.3)
    for ax in axes[1]:
        ax.set_xlabel('crank angle [deg]')
    axes[0, 0].legend(fontsize=8)
    figure.suptitle(f'{name}: ground-frame elastic deflection (Fig. {fig}); rigid crank, '
                    'K_G on, zeta = 0.02, full order; '
                    'note the different scales', fontsize=10)
    figure.savefig(path, dpi=DPI)
    return path


def plot_coupler_path(responses, mechanism, path):
    """Coupler mid-point paths, rigid and flexible (Fig. 22), and the deflection loops."""
    figure = Figure(figsize=(12.0, 9.5), layout='constrained')
    axes = figure.subplots(2, 2)
    styles = {'rigid': ('tab:blue', 'flexible links, pins'),
              'flexible': ('tab:red', 'flexible links and bearings')}
    for col, rpm in enumerate(PAPER_RPM):
        ax, loop = axes[0, col], axes[1, col]
        angles = responses['rigid', rpm].crank_angle
        rigid = coupler_mid_path(mechanism, angles)
        closed = np.append(rigid, rigid[0])
        ax.plot(closed.real * 1e3, closed.imag * 1e3, 'k--', linewidth=1.2, label='rigid')
        for bearings in BEARINGS:
            out = responses[bearings, rpm].outputs[:, 2:]
            moved = rigid + out[:, 0] + 1j * out[:, 1]
            moved = np.append(moved, moved[0])
            colour, label = styles[bearings]
            ax.plot(moved.real * 1e3, moved.imag * 1e3, color=colour, linewidth=1.0,
                    label=label)
            loop_closed = np.vstack([out, out[:1]]) * 1e3
            loop.plot(loop_closed[:, 0], loop_closed[:, 1], color=colour, label=label)
            loop.plot(*loop_closed[0], 'o', color=colour, markersize=5)
        state = solve_kinematics(mechanism, 0.0)
        joints = [state.joints[j][0] for j in ('O2', 'A', 'B', 'O4')]
        ax.plot([z.real * 1e3 for z in joints], [z.imag * 1e3 for z in joints], color='0.5',
                marker='o', linewidth=1.5, label='rigid linkage at 0 deg')
        span = max(len(rigid) // 15, 1)   # about 24 degrees of crank
        for k in (len(rigid) // 8, 5 * len(rigid) // 8):
            ax.annotate('', xy=(rigid[k + span].real * 1e3, rigid[k + span].imag * 1e3),
                        xytext=(rigid[k].real * 1e3, rigid[k].imag * 1e3),
                        arrowprops={'arrowstyle': '-|>', 'color': 'black', 'lw': 1.5,
                                    'mutation_scale': 15, 'shrinkA': 0, 'shrinkB': 0})
        ax.set_title(f'{rpm:g} rpm: coupler mid-point path (true scale)', fontsize=9)
        ax.set_aspect('equal')
        ax.set_xlabel('X [mm]')
        ax.set_ylabel('Y [mm]')
        ax.grid(True, alpha=0.3)
        loop.set_title(f'{rpm:g} rpm: elastic deflection of the coupler mid-point '
                       '(dot = crank 0 deg)', fontsize=9)
        loop.set_aspect('equal', adjustable='datalim')
        loop.set_xlabel('dX [mm]')
        loop.set_ylabel('dY [mm]')
        loop.grid(True, alpha=0.3)
    for ax in axes[0]:
        low, high = ax.get_ylim()
        ax.set_ylim(low, high + 0.25 * (high - low))
    axes[0, 0].legend(fontsize=8, loc='upper left')
    axes[1, 0].legend(fontsize=8)
    figure.suptitle('Fig. 22: coupler mid-point paths, rigid crank, full order (arrow: '
                    'direction of travel)', fontsize=10)
    figure.savefig(path, dpi=DPI)
    return path


def plot_truncation(truncation, path):
    """Relative RMS error of mode superposition vs N (both speeds and bearing models)."""
    figure = Figure(figsize=(12.0, 8.0), layout='constrained')
    axes = figure.subplots(2, 2, sharey=True)
    floor = 1e-6
    for row, bearings in enumerate(BEARINGS):
        for col, rpm in enumerate(PAPER_RPM):
            ax = axes[row, col]
            study = truncation[bearings, rpm]
            for key, style, text in (('plain', '--', 'modes only'),
                                     ('static', '-', 'with static correction')):
                for o, (name, colour) in enumerate((('lever tip', 'tab:red'),
                                                    ('coupler mid-point', 'tab:blue'))):
                    ax.plot(study['modes'], np.maximum(study[key][:, o], floor), style,
                            color=colour, marker='o', markersize=3,
                            label=f'{name}, {text}')
            for tol in TOLERANCES:
                ax.axhline(tol, color='0.4', linewidth=0.8, linestyle=':')
                ax.text(study['modes'][-1], tol, f'{tol:.0%}', va='bottom', ha='right',
                        fontsize=8, color='0.3')
            ax.set_yscale('log')
            ax.set_ylim(floor * 0.7, 2.0)
            ax.set_title(f'{bearings} bearings, {rpm:g} rpm ({study["steps"]} steps/rev)',
                         fontsize=9)
            ax.grid(True, which='both', alpha=0.3)
            ax.set_xlabel('number of frozen modes N')
            ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    for ax in axes[:, 0]:
        ax.set_ylabel('relative RMS error vs full order')
    handles, labels = axes[0, 0].get_legend_handles_labels()
    figure.legend(handles, labels, loc='outside lower center', ncol=4, fontsize=8)
    figure.suptitle('Modal truncation: mode superposition vs the full-order periodic response '
                    '(rigid crank, same integrator and step; errors below 1e-6 drawn at 1e-6)',
                    fontsize=10)
    figure.savefig(path, dpi=DPI)
    return path


__all__ = ['plot_deflected_linkage', 'plot_point_deflections', 'plot_coupler_path',
           'plot_truncation']
