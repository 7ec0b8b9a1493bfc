"""
``replay --nonlinear auto|on|off``: the reduced nonlinear model's deflections in the output.

The same rule and the same ``model: ...`` line as ``estimate --nonlinear``
(:func:`core.estimation.nonlinear_follow.choose_nonlinear`). ``on`` writes the nonlinear
model's lever-tip and coupler-mid deflections in place of the linear ones, block by block as
the replay writes (:class:`NonlinearRows`: memory independent of the recording's length).
``auto`` (the default) first runs the linear estimate alone over the recording and writes
the nonlinear deflections only where its validity indicator (the largest per-sample
``nonlinearity`` of ``~/quality``) says the linear estimate is not valid. A recording that
names its model is replayed with the model that made it (the nonlinear one if its
provenance says ``nonlinear: on``, else the linear one) unless ``--nonlinear`` is given;
``auto`` is for recordings that name no model.
The output's provenance records the choice (``nonlinear``: ``on`` or ``off``).

The nonlinear model steps through the samples the linear estimator accepted, with the crank
angle and speed of its crank filter (the same crank state the linear estimate used), and starts
again, at its quasi-static deflection, where the linear estimator starts a new segment. The
criteria, the quality topic (the linear model's error and validity indicators) and the markers
(the linear model's modal shape) are the linear estimate's.
"""

import math

import numpy as np

from ..core.estimation.nonlinear_follow import choose_nonlinear, follow_rows, follow_summary, \
    NonlinearFollower
from ..core.estimation.nonlinear_stream import VON_KARMAN_SLOPE
from ..core.reduction.nonlinear_model import nonlinear_model_for
from ..core.validity import is_valid


def nonlinear_choice(args, recorded):
    """
    Return 'auto', 'on' or 'off': the flag if given, else what the recording was made with.

    Parameters
    ----------
    args : argparse.Namespace
        ``nonlinear`` (None when the flag was not given).
    recorded : io.provenance.Provenance or None
        The recording's provenance.

    """
    if getattr(args, 'nonlinear', None):
        return args.nonlinear
    if recorded is not None and recorded.has_model:
        # Recorded before the nonlinear model existed: the linear model made it.
        return recorded.nonlinear or 'off'
    return 'auto'


def decide(choice, summary=None, recorded=False):
    """
    Return (use the nonlinear model, why) for ``choice`` and a linear run's summary.

    ``recorded``: the choice is the recording's own (no ``--nonlinear`` given).
    """
    if choice != 'auto':
        return choose_nonlinear(choice, None, recorded)
    largest = summary['quality'].get('nonlinearity_max') if summary else None
    return choose_nonlinear('auto', is_valid([math.nan if largest is None else largest]))


class NonlinearRows:
    """
    Replace each block's linear deflections with the nonlinear model's (see the module notes).

    Parameters
    ----------
    tables : NonlinearTables
        The reduced nonlinear model.
    reset_gap_s : float
        A gap between accepted samples longer than this starts the model again (as the linear
        estimator's segments).
    damping : str
        How the model is damped (:func:`core.reduction.nonlinear_model.nonlinear_model_for`).

    """

    def __init__(self, tables, reset_gap_s, damping=''):
        self.tables, self.damping = tables, damping
        self.follower = NonlinearFollower(tables, reset_gap_s)
        self.low = np.full(tables.outputs, np.inf)
        self.high = np.full(tables.outputs, -np.inf)

    def __call__(self, samples, estimate):
        """Return ``estimate`` with the nonlinear 'lever_tip' and 'coupler_mid' rows."""
        outputs, accepted = follow_rows(self.follower, samples['stamps_ns'], estimate)
        if accepted.any():
            self.low = np.minimum(self.low, outputs[accepted].min(axis=0))
            self.high = np.maximum(self.high, outputs[accepted].max(axis=0))
        replaced = dict(estimate)
        replaced['lever_tip'], replaced['coupler_mid'] = outputs[:, 0:2], outputs[:, 2:4]
        return replaced

    def summary(self):
        """Return the JSON's ``nonlinear`` entry: peak-to-peak deflections [um] and counts."""
        return follow_summary(self.follower, self.low, self.high, self.damping)


def nonlinear_rows(args, mechanism, options, reset_gap_s):
    """Return the :class:`NonlinearRows` of the replay's mechanism and options."""
    tables, damping = nonlinear_model_for(mechanism, options, args.cache_dir,
                                          not args.no_cache)
    return NonlinearRows(tables, reset_gap_s, damping)


def model_lines(result):
    """Say the model choice (as estimate) and the nonlinear run in text lines."""
    choice, nonlinear = result['model_choice'], result['nonlinear']
    if nonlinear is None:
        return [f"  model: linear ({choice['why']})"]
    return [f"  model: nonlinear ({choice['why']}): the deflections above are its own",
            f"  nonlinear: {nonlinear['samples']} samples, {nonlinear['refused_samples']} "
            f"refused, {nonlinear['restarts']} restarts, link slope max "
            f"{nonlinear['link_slope_max_rad']:.3g} rad (von Karman limit "
            f'{VON_KARMAN_SLOPE:g}: {nonlinear["beyond_von_karman_samples"]} samples beyond)']


__all__ = ['nonlinear_choice', 'decide', 'NonlinearRows', 'nonlinear_rows', 'model_lines']
