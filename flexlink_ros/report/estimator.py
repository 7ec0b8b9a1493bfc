"""
Charts of the streaming estimator: accuracy against cost, and estimate against reference.

- :func:`plot_error_vs_cost`: relative RMS error of the coupler mid-point and the lever tip
  against the streaming cost per sample, one point per model configuration, the default
  marked, the tolerance drawn.
- :func:`plot_estimate`: the estimated deflections over the last revolution against the
  full-order reference (ground-frame dx, dy of both points).
- :func:`plot_estimator`: the report section (``flexlink report``): the bench of Cho 1992
  and its 391 rpm estimate (:func:`studies.bench.estimator_report_data`), drawn.
"""

import pathlib

import numpy as np

from ..core.mechanism_file import load_mechanism
from ..core.options import ModelOptions
from ..errors import FlexlinkError
from ..studies.bench import estimator_report_data

CHANNELS = (('coupler_mid', 'coupler mid-point'), ('lever_tip', 'lever tip'))


# Markers of the configurations after the default's star (colours: matplotlib's tab10).
MARKERS = ('o', 's', '^', 'v', 'D', 'P', 'X', '<', '>', 'h')


def error_vs_cost_figure(configurations, tolerance=None):
    """
    Draw error against cost per sample, one marker per configuration, named in the legend.

    The configurations sit close together (a few us apart, errors within a decade), so they
    are named in one legend under both panels rather than beside their markers, where the
    labels overlapped each other and the axes' edge.

    Parameters
    ----------
    configurations : list of dict
        Each with 'label' (str), 'us_per_sample' (float), 'error_coupler_mid' and
        'error_lever_tip' (relative RMS, float) and optionally 'default' (bool).
    tolerance : float or None
        Relative error target, drawn as a horizontal line.

    Returns
    -------
    matplotlib.figure.Figure

    """
    from matplotlib.figure import Figure   # only when drawing: `flexlink bench` starts fast

    figure = Figure(figsize=(10.0, 4.8), layout='constrained')
    axes = figure.subplots(1, 2, sharex=True)
    others = iter(zip(MARKERS * 2, ('tab:blue', 'tab:orange', 'tab:green', 'tab:purple',
                                    'tab:brown', 'tab:pink', 'tab:gray', 'tab:olive',
                                    'tab:cyan', 'k') * 2))
    styles = [('*', 'tab:red', 140) if c.get('default') else (*next(others), 40)
              for c in configurations]
    for ax, (key, title) in zip(axes, CHANNELS):
        for config, (marker, colour, size) in zip(configurations, styles):
            ax.scatter(config['us_per_sample'], max(config[f'error_{key}'], 1e-6), s=size,
                       marker=marker, color=colour, zorder=3, label=config['label'])
        if tolerance is not None:
            ax.axhline(tolerance, color='grey', linestyle='--', linewidth=1.0,
                       label=f'tolerance {tolerance:g}')
        errors = [max(c[f'error_{key}'], 1e-6) for c in configurations]
        low, high = min(errors + [tolerance or errors[0]]), max(errors + [tolerance or 0.0])
        ax.set_ylim(low / 3.0, high * 3.0)
        ax.set_yscale('log')
        ax.set_title(f'{title}: relative RMS error')
        ax.set_xlabel('streaming update, median [us/sample]')
        ax.grid(True, which='both', alpha=0.3)
        ax.margins(x=0.15)
    axes[0].set_ylabel('error vs full-order reference')
    handles, labels = axes[0].get_legend_handles_labels()
    figure.legend(handles, labels, loc='outside lower center', fontsize=8,
                  ncols=min(len(labels), 4))
    return figure


def plot_error_vs_cost(configurations, path, tolerance=None):
    """
    Write :func:`error_vs_cost_figure` to a PNG file.

    Parameters
    ----------
    configurations : list of dict
        As :func:`error_vs_cost_figure`.
    path : str or Path
        PNG file to write.
    tolerance : float or None
        Relative error target, drawn as a horizontal line.

    Returns
    -------
    pathlib.Path

    """
    path = pathlib.Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    error_vs_cost_figure(configurations, tolerance).savefig(path, dpi=120)
    return path


def plot_estimate(crank_deg, estimate, reference, path, title=''):
    """
    Estimated and reference deflections over crank angle.

    Parameters
    ----------
    crank_deg : ndarray, shape (m,)
        Crank angle [deg] of each sample.
    estimate, reference : dict
        'lever_tip' and 'coupler_mid', each ndarray (m, 2) of (dx, dy) [m].
    path : str or Path
        PNG file to write.
    title : str
        Figure title.

    Returns
    -------
    pathlib.Path

    """
    from matplotlib.figure import Figure   # only when drawing

    path = pathlib.Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    order = np.argsort(crank_deg)
    figure = Figure(figsize=(10.0, 6.0), layout='constrained')
    axes = figure.subplots(2, 2, sharex=True)
    for row, (key, name) in enumerate(CHANNELS):
        for col, axis_name in enumerate(('dx', 'dy')):
            ax = axes[row, col]
            ax.plot(crank_deg[order], 1e3 * np.asarray(reference[key])[order, col],
                    color='black', linewidth=1.5, label='full-order reference')
            ax.plot(crank_deg[order], 1e3 * np.asarray(estimate[key])[order, col],
                    color='tab:red', linewidth=1.0, linestyle='--', label='streaming estimate')
            ax.set_title(f'{name} {axis_name}')
            ax.set_ylabel('deflection [mm]')
            ax.grid(True, alpha=0.3)
    for ax in axes[1]:
        ax.set_xlabel('crank angle [deg]')
    axes[0, 0].legend(fontsize=8)
    if title:
        figure.suptitle(title)
    figure.savefig(path, dpi=120)
    return path


def bench_table(configurations):
    """
    Markdown table of the bench's configurations.

    Parameters
    ----------
    configurations : list of dict
        :func:`studies.bench.run_bench`'s rows.

    Returns
    -------
    str

    """
    lines = ['| configuration | r | us/sample p50 | p99 | offline samples/s | coupler error '
             '| lever error | MB |', '|---|---|---|---|---|---|---|---|']
    for row in configurations:
        lines.append(f'| {row["label"]} | {row["size"]} | {row["us_per_sample"]:.1f} | '
                     f'{row["us_per_sample_p99"]:.1f} | {row["offline_samples_per_s"]:.0f} | '
                     f'{row["error_coupler_mid"]:.2%} | {row["error_lever_tip"]:.2%} | '
                     f'{row["bytes"] / 1e6:.2f} |')
    return '\n'.join(lines)


def plot_estimator(out_dir, options=None, progress=None):
    """
    Report section: bench of the Cho 1992 estimator and the 391 rpm estimate.

    Parameters
    ----------
    out_dir : str or Path
        Directory of the charts.
    options : ModelOptions, optional
        The default model (default: the node's, :class:`core.options.ModelOptions`).
    progress : callable or None
        ``progress(done, total, what)`` of the bench (:func:`studies.bench.run_bench`).

    Returns
    -------
    dict
        'charts' (paths) and 'text' (markdown table), or only 'text' saying why the flexible
        model is not available in this checkout.

    """
    out = pathlib.Path(out_dir)
    try:
        data = estimator_report_data(load_mechanism('cho1992'),
                                     options or ModelOptions(), progress)
    except FlexlinkError as exc:
        return {'charts': [], 'text': f'_Streaming estimator not available: {exc}_'}
    bench = data['bench']
    bench_chart = plot_error_vs_cost(bench['configurations'],
                                     out / 'estimator_error_vs_cost.png')
    chart = plot_estimate(data['crank_deg'], data['estimate'], data['reference'],
                          out / 'estimator_391rpm.png',
                          title=f'Cho 1992 at {data["rpm"]:g} rpm, 1 kHz')
    return {'charts': [str(bench_chart), str(chart)],
            'text': bench_table(bench['configurations'])}
