"""
``estimate --nonlinear auto|on|off``: the reduced nonlinear model on the synthetic signal.

``auto`` (the default) runs the linear estimate and adds the nonlinear one only where the
linear model's validity indicator over the scene's last revolution says the linear estimate
is not valid; ``on`` always, ``off`` never. The command says which model it reports and why.
The JSON's deflections are the chosen model's; ``nonlinear`` holds the nonlinear run's
model, damping, cost and Newton figures (None when it did not run).
"""

import math

import numpy as np

from ..core.estimation.nonlinear_follow import CHOICES, choose_nonlinear
from ..core.estimation.nonlinear_stream import estimate_nonlinear, VON_KARMAN_SLOPE
from ..core.reduction.nonlinear_model import nonlinear_model_for
from ..studies.synthetic import last_revolution, synthetic_signal, timing_summary


def run_nonlinear(args, mechanism, options):
    """Run the nonlinear model on the same synthetic signal as ``estimate``; a JSON dict."""
    tables, damping = nonlinear_model_for(mechanism, options, args.cache_dir,
                                          not args.no_cache)
    stamps, angles, speeds = synthetic_signal(args.rpm, args.seconds, args.rate_hz,
                                              args.jitter, args.seed)
    out = estimate_nonlinear(tables, stamps, angles, speeds)
    mask = last_revolution(stamps, args.rpm)
    median, p99 = timing_summary(out['update_ns'][1:])
    chosen = out['outputs'][mask]
    return {'crank_deg': [math.degrees(a) % 360.0 for a in angles[mask]],
            'lever_tip': {'dx_m': chosen[:, 0].tolist(), 'dy_m': chosen[:, 1].tolist()},
            'coupler_mid': {'dx_m': chosen[:, 2].tolist(), 'dy_m': chosen[:, 3].tolist()},
            'us_per_sample_median': median, 'us_per_sample_p99': p99,
            'newton_per_sample': out['newton_iterations'] / max(1, len(stamps) - 1),
            'refused_samples': out['refused'], 'damping': damping,
            'stiffness_damping_s': tables.beta, 'size': tables.size, 'links': tables.links,
            'axial_force_range_n': [float(out['axial_force'][mask].min()),
                                    float(out['axial_force'][mask].max())],
            'link_slope_max_rad': float(np.nanmax(out['link_slope'][mask])),
            'beyond_von_karman_samples': out['beyond_von_karman']}


def nonlinear_lines(nonlinear):
    """Text lines of a nonlinear run."""
    lever = np.hypot(nonlinear['lever_tip']['dx_m'], nonlinear['lever_tip']['dy_m'])
    coupler = np.hypot(nonlinear['coupler_mid']['dx_m'], nonlinear['coupler_mid']['dy_m'])
    low, high = nonlinear['axial_force_range_n']
    return ['nonlinear model (last revolution):',
            f'  lever tip |d| max   {1e3 * lever.max():.4f} mm',
            f'  coupler mid |d| max {1e3 * coupler.max():.4f} mm',
            f"  update {nonlinear['us_per_sample_median']:.1f} us median, "
            f"{nonlinear['us_per_sample_p99']:.1f} us p99 (m = {nonlinear['size']}, "
            f"{nonlinear['links']} lumped axial forces, "
            f"{nonlinear['newton_per_sample']:.2f} Newton iterations per sample, "
            f"{nonlinear['refused_samples']} samples refused)",
            f"  {nonlinear['damping']}; link axial forces {low:.3g} ... {high:.3g} N",
            f"  link RMS bending slope max {nonlinear['link_slope_max_rad']:.3g} rad (von Karman "
            f"limit {VON_KARMAN_SLOPE:g}; {nonlinear['beyond_von_karman_samples']} samples "
            'beyond it)']


def add_nonlinear(args, mechanism, options, result):
    """Decide, run and merge the nonlinear estimate into ``result``; return text lines."""
    use, why = choose_nonlinear(args.nonlinear, result['nonlinearity'])
    result['model_choice'] = {'nonlinear': use, 'why': why}
    result['nonlinear'] = None
    if not use:
        return [f'model: linear ({why})']
    nonlinear = run_nonlinear(args, mechanism, options)
    result['nonlinear'] = nonlinear
    result['linear'] = {key: result[key] for key in ('crank_deg', 'lever_tip', 'coupler_mid')}
    for key in ('crank_deg', 'lever_tip', 'coupler_mid'):
        result[key] = nonlinear[key]
    return [f'model: nonlinear ({why})'] + nonlinear_lines(nonlinear)


__all__ = ['CHOICES', 'choose_nonlinear', 'run_nonlinear', 'nonlinear_lines', 'add_nonlinear']
