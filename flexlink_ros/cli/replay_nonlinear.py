"""
``replay --nonlinear auto|on|off``: the reduced nonlinear model on a recording's crank samples.

The same rule and the same ``model: ...`` line as ``estimate --nonlinear``
(:func:`.estimate_nonlinear.choose_nonlinear`): ``auto`` (the default) adds the nonlinear
estimate where the linear replay's validity indicator (the largest per-sample ``nonlinearity``
of ``~/quality``) says the linear estimate is not valid. The JSON's ``model_choice`` is
estimate's; ``nonlinear`` holds the nonlinear run's peak-to-peak deflections, refused samples
and link slopes (None when it did not run). The output file still holds the linear estimate.
"""

import numpy as np

from .estimate_nonlinear import choose_nonlinear
from ..core.estimation.nonlinear_stream import estimate_nonlinear, VON_KARMAN_SLOPE
from ..core.reduction.nonlinear_model import nonlinear_model_for
from ..core.validity import is_valid
from ..io.joint_states import read_input_samples


def increasing(stamps_ns):
    """Mask of the samples whose stamp is above every earlier one (the stepper's input)."""
    stamps = np.asarray(stamps_ns, dtype=np.int64)
    if not stamps.size:
        return np.zeros(0, dtype=bool)
    before = np.maximum.accumulate(np.concatenate([[np.iinfo(np.int64).min], stamps[:-1]]))
    return stamps > before


def run_recording(tables, samples):
    """Step the nonlinear model through a recording's samples; a JSON dict."""
    keep = increasing(samples['stamps_ns'])
    speeds = samples['speeds'][keep]
    out = estimate_nonlinear(tables, samples['stamps_ns'][keep], samples['angles'][keep],
                             None if np.isnan(speeds).all() else speeds)
    rows = out['outputs'][np.all(np.isfinite(out['outputs']), axis=1)]
    span = (1e6 * (rows.max(axis=0) - rows.min(axis=0))).tolist() if rows.size else \
        [float('nan')] * tables.outputs
    slope = out['link_slope'][np.isfinite(out['link_slope'])]
    return {'samples': int(keep.sum()), 'not_increasing': int((~keep).sum()),
            'refused_samples': out['refused'], 'lever_tip_peak_to_peak_um': span[0:2],
            'coupler_mid_peak_to_peak_um': span[2:4], 'outputs': out['outputs'],
            'link_slope_max_rad': float(slope.max()) if slope.size else None,
            'beyond_von_karman_samples': out['beyond_von_karman']}


def add_replay_nonlinear(args, mechanism, options, result):
    """Decide, run and add the nonlinear estimate of a replay to ``result``."""
    verdict = is_valid([np.nan if result['quality']['nonlinearity_max'] is None
                        else result['quality']['nonlinearity_max']])
    use, why = choose_nonlinear(getattr(args, 'nonlinear', None) or 'auto', verdict)
    result['model_choice'] = {'nonlinear': use, 'why': why}
    result['nonlinear'] = None
    if not use:
        return
    tables, damping = nonlinear_model_for(mechanism, options, args.cache_dir,
                                          not args.no_cache)
    _, samples, _ = read_input_samples(args.input, result['topic'], args.joint, [])
    nonlinear = run_recording(tables, samples)
    del nonlinear['outputs']   # the per-sample rows are not part of the summary
    nonlinear.update(damping=damping, size=tables.size, links=tables.links)
    result['nonlinear'] = nonlinear


def model_lines(result):
    """Say the model choice (as estimate) and the nonlinear run in text lines."""
    choice, nonlinear = result['model_choice'], result['nonlinear']
    if nonlinear is None:
        return [f"  model: linear ({choice['why']})"]
    lever, coupler = nonlinear['lever_tip_peak_to_peak_um'], nonlinear[
        'coupler_mid_peak_to_peak_um']
    slope = nonlinear['link_slope_max_rad']
    slope_text = 'n/a' if slope is None else f'{slope:.3g}'
    return [f"  model: nonlinear ({choice['why']})",
            f'  nonlinear lever tip peak-to-peak dx {lever[0]:.1f} um dy {lever[1]:.1f} um, '
            f'coupler mid dx {coupler[0]:.1f} um dy {coupler[1]:.1f} um '
            f"({nonlinear['refused_samples']} samples refused, link slope max {slope_text} "
            f'rad, von Karman limit {VON_KARMAN_SLOPE:g})']


__all__ = ['increasing', 'run_recording', 'add_replay_nonlinear', 'model_lines']
