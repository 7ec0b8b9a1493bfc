"""
Charts of ``flexlink validate``: the package's models against the nonlinear Exudyn peer.

:func:`plot_validation` draws records of :func:`studies.validation.validate_speed`:

- one or a few speeds: per speed a row of four panels (lever tip dX / dY, coupler mid-point
  dX / dY [um]) over one steady revolution, the peer against linear, linear + second order and
  the dynamic pass, with each model's p2p error in the legend;
- a sweep (more than :data:`MAX_ROWS` speeds, or ``sweep=True``): the worse p2p error of the
  lever tip and of the coupler mid-point against speed per model, with the accuracy targets,
  and below it the validity indicator with its threshold, the speeds it flags shaded.
"""

from matplotlib.figure import Figure
import numpy as np

from ..studies.validation import LABELS, MODEL_LABELS, MODELS, OUTPUT_KEYS, TARGETS

# Up to this many speeds are drawn as time series, one row each.
MAX_ROWS = 4
STYLE = {'peer': ('black', '-', 2.4), 'linear': ('tab:gray', ':', 1.6),
         'second_order': ('tab:blue', '--', 1.4), 'dynamic': ('tab:red', '-', 1.1)}


def _closed(values):
    """Append the first sample so a revolution's curve closes at 360 degrees."""
    return np.concatenate([values, values[:1]])


def _speed_row(axes, record, first_row):
    """One speed's four panels: every model and the peer against crank angle."""
    for column, (ax, key) in enumerate(zip(axes, OUTPUT_KEYS)):
        for name in ('peer',) + MODELS:
            series = record['series'][name]
            colour, dash, width = STYLE[name]
            label = MODEL_LABELS[name]
            if name != 'peer':
                label += f" ({100 * record['models'][name][key]['p2p_error']:+.1f} %)"
            angle = _closed(series['crank_deg'])
            angle[-1] = angle[0] + 360.0
            ax.plot(angle, _closed(series['outputs'][:, column]) * 1e6, color=colour,
                    ls=dash, lw=width, label=label)
        start = record['series']['peer']['crank_deg'][0]
        ax.set_xlim(start, start + 360.0)
        ax.set_xticks(start + np.arange(0, 361, 90))
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, title='p2p error vs peer', title_fontsize=7, loc='best',
                  framealpha=0.6)
        if first_row:
            ax.set_title(LABELS[key], fontsize=10)
        if column == 0:
            flag = 'valid' if record['nonlinearity']['valid'] else 'NOT valid'
            ax.set_ylabel(f"{record['rpm']:g} rpm ({flag})\ndeflection [um]")
        ax.set_xlabel('crank angle [deg]')


def _settings_text(record):
    s = record['settings']
    return (f"{s['bearings']} bearings, gravity {'on' if s['gravity'] else 'off'}, rigid "
            f"crank, {s['elements_per_link']} elements per link; package "
            f"{record['damping']}, peer beta {s['beta_s']:g} s")


def plot_speeds(records, path):
    """Time-series chart of up to :data:`MAX_ROWS` speeds, written to ``path``."""
    rows = len(records)
    figure = Figure(figsize=(17, 3.9 * rows + 0.8), layout='constrained')
    axes = np.atleast_2d(figure.subplots(rows, len(OUTPUT_KEYS), squeeze=False))
    for row, record in enumerate(records):
        _speed_row(axes[row], record, row == 0)
    figure.suptitle('Elastic deflection over one steady revolution: Exudyn peer (ANCF, '
                    'geometrically exact) against the package\n' + _settings_text(records[0]),
                    fontsize=11)
    figure.savefig(path, dpi=100)
    return path


def plot_sweep(records, path):
    """Error-and-indicator chart of a speed sweep, written to ``path``."""
    records = sorted(records, key=lambda r: r['rpm'])
    rpm = np.array([r['rpm'] for r in records])
    figure = Figure(figsize=(10, 10.5), layout='constrained')
    axes = figure.subplots(3, 1, sharex=True)
    for ax, point in zip(axes, TARGETS):
        for name in MODELS:
            colour, dash, _ = STYLE[name]
            worst = [max(abs(r['models'][name][f'{point}_{axis}']['p2p_error'])
                         for axis in ('dx', 'dy')) for r in records]
            ax.semilogy(rpm, np.maximum(100 * np.array(worst), 1e-2), color=colour, ls=dash,
                        marker='o', ms=3, label=f'{MODEL_LABELS[name]}: |p2p error|')
            # a p2p can match by chance near resonance; the RMS of the vector cannot
            rms = [r['point_rms_error'][name][point] for r in records]
            ax.semilogy(rpm, 100 * np.array(rms), color=colour, ls='-', lw=4, alpha=0.25,
                        label=f'{MODEL_LABELS[name]}: vector rel RMS')
        ax.axhline(100 * TARGETS[point], color='tab:green', lw=1)
        ax.annotate(f'p2p target {TARGETS[point]:.0%}', (1.0, 100 * TARGETS[point]),
                    xycoords=('axes fraction', 'data'), xytext=(-4, 3),
                    textcoords='offset points', ha='right', fontsize=8, color='tab:green')
        name = 'lever tip' if point == 'lever_tip' else 'coupler mid-point'
        ax.set_ylabel(f'{name} vs peer [%]\n|p2p error| (worse of dX, dY)\nand vector rel RMS')
        ax.grid(alpha=0.3, which='both')
    handles, labels = axes[0].get_legend_handles_labels()
    axes[0].legend(handles, labels, fontsize=8, ncol=3, loc='lower center',
                   bbox_to_anchor=(0.5, 1.0), frameon=False)
    indicator = np.array([r['nonlinearity']['indicator_max'] for r in records])
    axes[2].semilogy(rpm, indicator, 'k.-', label='validity indicator (max per revolution)')
    axes[2].axhline(records[0]['threshold'], color='tab:red', ls='--',
                    label=f"threshold {records[0]['threshold']:g}")
    # each flagged speed shades the band closer to it than to its neighbours
    edges = np.concatenate([rpm[:1], 0.5 * (rpm[1:] + rpm[:-1]), rpm[-1:]])
    flagged = np.flatnonzero(indicator > records[0]['threshold'])
    for ax in axes:
        for index in flagged:
            low, high = edges[index], edges[index + 1]
            if high - low < 1.0:
                low, high = rpm[index] - 0.5, rpm[index] + 0.5
            ax.axvspan(low, high, color='0.88', lw=0)
    axes[2].set_ylabel('nonlinearity indicator')
    axes[2].set_xlabel('crank speed [rpm]  (grey: flagged not valid)')
    axes[2].legend(fontsize=8)
    axes[2].grid(alpha=0.3, which='both')
    figure.suptitle('Validity sweep against the Exudyn peer\n' + _settings_text(records[0]),
                    fontsize=11)
    figure.savefig(path, dpi=100)
    return path


def plot_validation(records, path, sweep=None):
    """
    Write the chart of :mod:`studies.validation` records to ``path`` (PNG).

    ``sweep`` None chooses by the number of speeds (more than :data:`MAX_ROWS`: a sweep).
    """
    if not records:
        raise ValueError('no records to draw')
    if sweep is None:
        sweep = len(records) > MAX_ROWS
    return plot_sweep(records, path) if sweep else plot_speeds(records, path)


__all__ = ['MAX_ROWS', 'plot_speeds', 'plot_sweep', 'plot_validation']
