"""
Charts of the transfer-matrix beam check (Kim & Moon): accuracy, speed and root-search effort.

:func:`plot_beam` writes four PNG files:

- ``beam_error_vs_segments.png``: first-frequency error [%] against segments for the three
  mass-lumping methods and consistent-mass FE, one panel per boundary condition, with the
  observed order of convergence in the legend.
- ``beam_frequency_vs_segments.png``: the first frequency itself against segments with the
  exact value dashed, as the paper's Figs. 2-5 draw it.
- ``beam_speed_vs_accuracy.png``: wall time of one call (first three modes) against the
  largest error of those modes, measured side by side in one run.
- ``beam_root_search_iterations.png``: iterations of bisection, false position (plain and
  Illinois) and Newton to the paper's |D| <= 1e-6 test against the scan step, with the
  paper's Tables 2-3 as markers.
"""

import pathlib

from matplotlib.figure import Figure
from matplotlib.ticker import FuncFormatter
import numpy as np

from ..core.tmm import beams, eigen
from ..core.tmm import exact as tmm_exact
from ..studies.beam_check import (error_table, frequency_table, iteration_table, observed_order,
                                  PAPER_SEGMENTS, PAPER_TABLE2_BISECTION, PAPER_TABLE3_MODE1,
                                  SCAN_STEPS_RAD_S, TIMING_REPEATS, timing_table)

METHOD_STYLE = {  # label, colour, marker
    'tmm1': ('TMM, lumping 1 (segment centres)', 'tab:blue', 'o'),
    'tmm2': ('TMM, lumping 2 (interior points)', 'tab:orange', 's'),
    'tmm3': ('TMM, lumping 3 (Kim & Moon)', 'tab:green', '^'),
    'fe': ('FE, cubic, consistent mass', 'tab:red', 'D'),
}


def _grid(title):
    figure = Figure(figsize=(12, 9), layout='constrained')
    axes = figure.subplots(2, 2)
    figure.suptitle(title, fontsize=13)
    return figure, dict(zip(beams.BOUNDARY_CONDITIONS, axes.ravel()))


def _panel_title(bc, beam):
    exact = tmm_exact.exact_frequencies(beam, bc, 1)[0]
    name = 'supported-supported' if bc == 'supported' else bc
    return f'{name}  (exact first frequency {exact:.3f} rad/s)'


def plot_errors(table, beam, path):
    """Chart 1: |error| [%] of the first frequency against segments (log-log)."""
    figure, axes = _grid('Kim & Moon beam: first-frequency error against number of segments')
    for bc, ax in axes.items():
        for method, (counts, errors) in table[bc].items():
            label, colour, marker = METHOD_STYLE[method]
            order = observed_order(counts, errors)
            ax.loglog(counts, 100 * np.abs(errors), color=colour,
                      label=f'{label}: order {order:.1f}')
            # filled: below the exact value, open: above it (a dip is a sign change)
            below = errors < 0
            ax.loglog(counts[below], 100 * np.abs(errors[below]), ls='none', marker=marker,
                      color=colour, ms=5)
            ax.loglog(counts[~below], 100 * np.abs(errors[~below]), ls='none', marker=marker,
                      mfc='white', color=colour, ms=5)
        ax.axvline(PAPER_SEGMENTS, color='grey', ls=':', lw=1)
        ax.text(PAPER_SEGMENTS * 1.05, 0.97, 'paper: 6', transform=ax.get_xaxis_transform(),
                va='top', fontsize=8, color='grey')
        ax.set_title(_panel_title(bc, beam), fontsize=10)
        ax.set_xlabel('number of segments (TMM) / elements (FE)')
        ax.set_ylabel('|frequency error| [%]')
        ax.grid(True, which='major', alpha=0.4)
        ax.legend(fontsize=8, loc='lower left')
    figure.text(0.5, 0.0, 'Order: exponent p of error ~ h^p fitted over 12-48 segments. '
                'Filled markers lie below the exact frequency, open ones above (a dip is a '
                'sign change).\nSupported-supported: lumping 1 and 3 give identical '
                'frequencies (the green curve hides the blue). FE levels off near 1e-7 % on '
                'fine meshes:\nthe assembled stiffness loses ~eps (L/h)^4 to round-off, the '
                'transfer matrices do not.', ha='center', va='top', fontsize=9)
    figure.savefig(path, dpi=110, bbox_inches='tight')
    return path


def plot_frequencies(table, beam, path, max_segments=20):
    """Chart 2: the first frequency against segments 2..max_segments (paper's Figs. 2-5)."""
    figure, axes = _grid('Kim & Moon beam: first frequency against number of segments '
                         "(cf. the paper's Figs. 2-5)")
    for bc, ax in axes.items():
        exact = table[bc]['exact']
        for method, (label, colour, marker) in METHOD_STYLE.items():
            counts, values = table[bc][method]
            ax.plot(counts, values, marker=marker, color=colour, ms=4, label=label)
        ax.axhline(exact, color='black', ls='--', lw=1, label='exact Euler-Bernoulli')
        ax.axvline(PAPER_SEGMENTS, color='grey', ls=':', lw=1)
        ax.set_ylim(exact * 0.85, exact * 1.12)
        ax.set_xticks(range(0, max_segments + 1, 2))
        ax.set_title(_panel_title(bc, beam), fontsize=10)
        ax.set_xlabel('number of segments (TMM) / elements (FE)')
        ax.set_ylabel('first natural frequency [rad/s]')
        ax.grid(True, alpha=0.4)
        ax.legend(fontsize=8, loc='lower right')
    figure.savefig(path, dpi=110, bbox_inches='tight')
    return path


def plot_speed(table, path):
    """Chart 3: wall time per call against the largest error of the first three modes."""
    figure, axes = _grid('Speed against accuracy: first three frequencies, one call each '
                         f'(best of {TIMING_REPEATS}, same run)')
    for bc, ax in axes.items():
        for method, (counts, seconds, errors) in table[bc].items():
            label, colour, marker = METHOD_STYLE[method]
            ax.loglog(1e3 * seconds, 100 * errors, marker=marker, color=colour, ms=5,
                      label=label)
            for n, x, y in zip(counts[[0, -1]], 1e3 * seconds[[0, -1]], 100 * errors[[0, -1]]):
                ax.annotate(f'n={n}', (x, y), textcoords='offset points', xytext=(4, 3),
                            fontsize=7, color=colour)
        name = 'supported-supported' if bc == 'supported' else bc
        ax.set_title(name, fontsize=10)
        ax.xaxis.set_major_formatter(FuncFormatter(lambda value, _: f'{value:g}'))
        ax.xaxis.set_minor_formatter(FuncFormatter(lambda value, _: ''))
        ax.set_xlabel('wall time per call [ms]')
        ax.set_ylabel('largest |error| of modes 1-3 [%]')
        ax.grid(True, which='major', alpha=0.4)
        ax.legend(fontsize=8, loc='lower left')
    segments = ', '.join(str(n) for n in next(iter(table.values()))['fe'][0])
    figure.text(0.5, 0.0, f'Segments per curve: {segments}. TMM: scan from 0 with d_omega '
                '= 10 rad/s, then false position; FE: assembly, then scipy.linalg.eigh (up to '
                f'{eigen.DENSE_EIGEN_LIMIT} DOFs) or sparse LU + ARPACK.',
                ha='center', va='top', fontsize=9)
    figure.savefig(path, dpi=110, bbox_inches='tight')
    return path


def plot_iterations(table, path, steps=SCAN_STEPS_RAD_S):
    """Chart 4: iterations to |D| <= 1e-6 against the scan step, with Tables 2-3."""
    labels = ('bisection', 'false position (plain)', 'false position (Illinois)', 'newton')
    colours = ('tab:grey', 'tab:blue', 'tab:cyan', 'tab:purple')
    figure, axes = _grid('Root searches, mode 1, lumping 3, 6 segments: iterations to the '
                         "paper's |D| <= 1e-6 (kgf-mm)")
    x = np.arange(len(steps))
    width = 0.2
    for bc, ax in axes.items():
        for k, (label, colour) in enumerate(zip(labels, colours)):
            counts = [np.nan if c is None else c for c in table[bc][label]]
            ax.bar(x + (k - 1.5) * width, counts, width, color=colour, label=label)
        paper = PAPER_TABLE3_MODE1[bc]
        ax.plot(x - 0.5 * width, paper['false-position'], 'kx', ms=8, mew=2,
                label='paper FPM (Table 3)')
        ax.plot(x + 1.5 * width, paper['newton'], 'k+', ms=10, mew=2,
                label='paper NRM (Table 3)')
        ax.plot([-1.5 * width], [PAPER_TABLE2_BISECTION[bc]], 'k*', ms=9,
                label='paper HIS (Table 2)')
        ax.set_xticks(x, [f'{s:g}' for s in steps])
        name = 'supported-supported' if bc == 'supported' else bc
        ax.set_title(name, fontsize=10)
        ax.set_xlabel('scan step d_omega [rad/s]')
        ax.set_ylabel('iterations')
        ax.grid(True, axis='y', alpha=0.4)
    handles, names = axes['fixed-fixed'].get_legend_handles_labels()
    figure.legend(handles, names, loc='outside lower center', ncol=7, fontsize=8)
    figure.text(0.5, 1.0, 'Counts depend on the tolerance and the arithmetic: the paper '
                'stops at |D| <= 1e-6 in kgf-mm units, which for supported-supported '
                '(|D| ~ 1e3) asks for ~1e-11 relative accuracy.', ha='center', va='bottom',
                fontsize=9)
    figure.savefig(path, dpi=110, bbox_inches='tight')
    return path


def plot_beam(out_dir, beam=None):
    """
    Write the beam charts into `out_dir`.

    Parameters
    ----------
    out_dir : str or pathlib.Path
        Directory (created if missing).
    beam : beams.UniformBeam, optional
        Default: the Kim & Moon beam.

    Returns
    -------
    list of pathlib.Path
        The PNG files written.

    """
    beam = beam or beams.UniformBeam.kim_moon()
    out = pathlib.Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    return [
        plot_errors(error_table(beam), beam, out / 'beam_error_vs_segments.png'),
        plot_frequencies(frequency_table(beam), beam,
                         out / 'beam_frequency_vs_segments.png'),
        plot_speed(timing_table(beam), out / 'beam_speed_vs_accuracy.png'),
        plot_iterations(iteration_table(beam), out / 'beam_root_search_iterations.png'),
    ]


__all__ = ['METHOD_STYLE', 'plot_errors', 'plot_frequencies', 'plot_speed', 'plot_iterations',
           'plot_beam']
