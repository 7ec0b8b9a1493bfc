"""
Charts of the streaming estimator: accuracy against cost, and estimate against reference.

- :func:`plot_error_vs_cost`: relative RMS error of the coupler mid-point and the lever tip
  against the streaming cost per sample, one point per model configuration, the default
  marked, the tolerance drawn.
- :func:`plot_estimate`: the estimated deflections over the last revolution against the
  full-order reference (ground-frame dx, dy of both points).
- :func:`plot_estimator`: the report section (``flexlink report``): runs ``flexlink bench``
  on Cho 1992 and draws both charts.
"""

import pathlib

import numpy as np
from matplotlib.figure import Figure

CHANNELS = (('coupler_mid', 'coupler mid-point'), ('lever_tip', 'lever tip'))


def plot_error_vs_cost(configurations, path, tolerance=None):
    """
    Error against cost per sample, one marker per configuration.

    Parameters
    ----------
    configurations : list of dict
        Each with 'label' (str), 'us_per_sample' (float), 'error_coupler_mid' and
        'error_lever_tip' (relative RMS, float) and optionally 'default' (bool).
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
    figure = Figure(figsize=(10.0, 4.2), layout='constrained')
    axes = figure.subplots(1, 2, sharex=True)
    for ax, (key, title) in zip(axes, CHANNELS):
        for config in configurations:
            error = config[f'error_{key}']
            default = config.get('default', False)
            ax.scatter(config['us_per_sample'], max(error, 1e-6), s=90 if default else 30,
                       marker='*' if default else 'o',
                       color='tab:red' if default else 'tab:blue', zorder=3)
            ax.annotate(config['label'], (config['us_per_sample'], max(error, 1e-6)),
                        textcoords='offset points', fontsize=7,
                        # the default's label below its star: neighbours' labels go above
                        xytext=(6, -10) if default else (4, 3),
                        fontweight='bold' if default else 'normal')
        if tolerance is not None:
            ax.axhline(tolerance, color='grey', linestyle='--', linewidth=1.0,
                       label=f'tolerance {tolerance:g}')
            ax.legend(loc='upper right', fontsize=8)
        errors = [max(c[f'error_{key}'], 1e-6) for c in configurations]
        low, high = min(errors + [tolerance or errors[0]]), max(errors + [tolerance or 0.0])
        ax.set_ylim(low / 3.0, high * 3.0)
        ax.set_yscale('log')
        ax.set_title(f'{title}: relative RMS error')
        ax.set_xlabel('streaming update, median [us/sample]')
        ax.grid(True, which='both', alpha=0.3)
    axes[0].set_ylabel('error vs full-order reference')
    figure.savefig(path, dpi=120)
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


def plot_estimator(out_dir):
    """
    Report section: bench of the Cho 1992 estimator and the 391 rpm estimate.

    Returns
    -------
    dict
        'charts' (paths) and 'text' (markdown table), or only 'text' saying why the flexible
        model is not available in this checkout.

    """
    from ..ros import parameters as node_params
    from ..cli.estimate import PAPER_RPM, RPM, run_bench, run_estimate
    from ..core.reduction import model as reduced
    from ..errors import FlexlinkError
    from ..core.mechanism import load_mechanism
    out = pathlib.Path(out_dir)
    try:
        mechanism = load_mechanism('cho1992')
        options = node_params.default_model_options()   # the node's default model
        bench = run_bench(mechanism, options, chart=out / 'estimator_error_vs_cost.png')
        model = reduced.model_for_mechanism(mechanism, options)
        estimate = run_estimate(model, PAPER_RPM[-1])
        angles = np.radians(estimate['crank_deg'])
        reference = reduced.reference_response(mechanism, options, PAPER_RPM[-1] * RPM, angles)
    except FlexlinkError as exc:
        return {'charts': [], 'text': f'_Streaming estimator not available: {exc}_'}
    series = {key: np.column_stack([estimate[key]['dx_m'], estimate[key]['dy_m']])
              for key in ('lever_tip', 'coupler_mid')}
    chart = plot_estimate(np.asarray(estimate['crank_deg']), series, reference,
                          out / 'estimator_391rpm.png',
                          title=f'Cho 1992 at {PAPER_RPM[-1]:g} rpm, 1 kHz')
    lines = ['| configuration | r | us/sample p50 | p99 | offline samples/s | coupler error '
             '| lever error | MB |', '|---|---|---|---|---|---|---|---|']
    for row in bench['configurations']:
        lines.append(f'| {row["label"]} | {row["size"]} | {row["us_per_sample"]:.1f} | '
                     f'{row["us_per_sample_p99"]:.1f} | {row["offline_samples_per_s"]:.0f} | '
                     f'{row["error_coupler_mid"]:.2%} | {row["error_lever_tip"]:.2%} | '
                     f'{row["bytes"] / 1e6:.2f} |')
    return {'charts': [bench['chart'], str(chart)], 'text': '\n'.join(lines)}
