"""
The streaming estimator drawn: estimate against reference, the configurations' accuracy.

- :func:`plot_estimate`: the estimated deflections over the last revolution against the
  full-order reference (ground-frame dx, dy of both points).
- :func:`configuration_table`: each model configuration's size and error, a Markdown table.
- :func:`plot_estimator`: the report section (``flexlink report``): the configurations of
  Cho 1992 and its 391 rpm estimate (:func:`studies.configurations.estimator_report_data`).
  Their cost per sample is a benchmark (``python benchmarks/estimator_bench.py``).
"""

import pathlib

import numpy as np

from ..core.mechanism_file import load_mechanism
from ..core.options import ModelOptions
from ..errors import FlexlinkError
from ..studies.configurations import estimator_report_data

CHANNELS = (('coupler_mid', 'coupler mid-point'), ('lever_tip', 'lever tip'))


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


def configuration_table(configurations):
    """
    Markdown table of the model configurations: sizes and errors against the reference.

    Parameters
    ----------
    configurations : list of dict
        :func:`studies.configurations.configuration_rows`.

    Returns
    -------
    str

    """
    lines = ['| configuration | r | p | grid | coupler error | lever error | MB |',
             '|---|---|---|---|---|---|---|']
    for row in configurations:
        lines.append(f'| {row["label"]} | {row["size"]} | {row["step_size"]} | '
                     f'{row["grid_size"]} | {row["error_coupler_mid"]:.2%} | '
                     f'{row["error_lever_tip"]:.2%} | {row["bytes"] / 1e6:.2f} |')
    return '\n'.join(lines)


def plot_estimator(out_dir, options=None, progress=None):
    """
    Report section: the Cho 1992 estimator's configurations and its 391 rpm estimate.

    Parameters
    ----------
    out_dir : str or Path
        Directory of the charts.
    options : ModelOptions, optional
        The default model (default: the node's, :class:`core.options.ModelOptions`).
    progress : callable or None
        ``progress(done, total, what)`` of the configurations
        (:func:`studies.configurations.configuration_rows`).

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
    chart = plot_estimate(data['crank_deg'], data['estimate'], data['reference'],
                          out / 'estimator_391rpm.png',
                          title=f'Cho 1992 at {data["rpm"]:g} rpm, 1 kHz')
    return {'charts': [str(chart)], 'text': configuration_table(data['configurations'])}
