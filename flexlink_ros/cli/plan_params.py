"""
``flexlink plan --params-out FILE``: the plan's choice as a node parameters file.

The file (``/**: ros__parameters:``, read by ``flexlink_node --ros-args --params-file FILE``
as it is) holds the mechanism file's absolute path, every ``model.*`` choice of the plan
(sizes, grid, elements, crank and bearing models, geometric stiffness, order, soft basis,
stiffness damping and the speed range of ``--rpm-max``), the criterion thresholds of the
mechanism's own cycle (:mod:`core.criteria_thresholds`) and the error indicator's WARN level.

The error indicator is the residual-flexibility correction's share of the deflection. A basis
with few static directions leaves the quasi-static response to that correction, which carries
it exactly, so the outputs are right with an indicator near 1 (a stiff linkage far below its
first frequency: 0.79 with 8 modes and no static direction, 0.15 with 4 static directions).
The plan has measured the chosen model against the full-order reference, so its file sets
``diagnostics.error_indicator_warn`` to :data:`INDICATOR_MARGIN` times the indicator the
chosen model shows at ``--rpm-max`` (at least the node's default): the node warns when the
indicator leaves what the verified model shows, not for ever.
"""

from ..core.criteria_thresholds import suggest_thresholds
from ..core.mechanism_file import find_config
from ..core.numerics import RPM
from ..core.options import ModelOptions
from ..ros import parameters as node_params
from ..studies.synthetic import run_estimate

INDICATOR_MARGIN = 1.5
INDICATOR_SECONDS = 2.0     # signal of the indicator's measurement (warm start, then steady)


def chosen_options(result):
    """Return the plan's chosen ModelOptions; ValueError if none met the tolerance."""
    if not result.get('choice'):
        raise ValueError('no model met the tolerance: nothing to write to --params-out '
                         '(see the table; a larger --tolerance or other fixed choices)')
    return ModelOptions(**result['choice']['options'])


def indicator_warn(model, rpm, rate_hz):
    """Return the error indicator's WARN level for ``model`` (a margin over it at ``rpm``)."""
    measured = run_estimate(model, rpm, INDICATOR_SECONDS, rate_hz)['error_indicator_max']
    default = node_params.SPECS['diagnostics.error_indicator_warn']
    level = max(default.default, INDICATOR_MARGIN * measured)
    return min(level, default.high), measured


def plan_parameters(mechanism, options, model, args):
    """
    Return the node's parameter values for the plan's choice, and what they rest on.

    Parameters
    ----------
    mechanism : Mechanism
        The planned mechanism.
    options : ModelOptions
        The plan's choice.
    model : ReducedModel
        Its reduced model (for the error indicator).
    args : argparse.Namespace
        The plan's flags (``--mechanism``, ``--rpm-max``, ``--rate-hz``).

    Returns
    -------
    values : dict
        Parameter name -> value.
    basis : dict
        'thresholds' (:func:`suggest_thresholds`), 'indicator' (measured at ``--rpm-max``).

    """
    speed = mechanism.crank_speed or args.rpm_max * RPM
    thresholds = suggest_thresholds(mechanism, speed, args.rate_hz)
    warn, measured = indicator_warn(model, args.rpm_max, args.rate_hz)
    values = {'mechanism': str(find_config(args.mechanism).resolve()),
              **node_params.model_parameters(options, mechanism.crank_speed),
              'diagnostics.criterion_warn': thresholds['warn'],
              'diagnostics.criterion_error': thresholds['error'],
              'diagnostics.error_indicator_warn': warn}
    return values, {'thresholds': thresholds, 'indicator': measured}


def params_comment(mechanism, args, basis):
    """Write the file's comment: what made it, how to use it, what its thresholds rest on."""
    thresholds = basis['thresholds']
    return (f'flexlink_node parameters from `flexlink plan` for {mechanism.name} up to '
            f'{args.rpm_max:g} rpm (tolerance {args.tolerance:g})\n'
            'ros2 run flexlink_ros flexlink_node --ros-args --params-file THIS_FILE\n'
            f'criterion thresholds: {thresholds["warn_margin"]:g} and '
            f'{thresholds["error_factor"]:g} times the largest true maximum of the cycle at '
            f'{thresholds["rpm"]:.4g} rpm (docs/criterion-thresholds.md)\n'
            f'error_indicator_warn: {INDICATOR_MARGIN:g} times the indicator of the chosen '
            f'model at {args.rpm_max:g} rpm ({basis["indicator"]:.3g}), outputs verified by the '
            'plan')


def write_params_file(path, mechanism, options, model, args):
    """Write the plan's parameters file; return the values written."""
    values, basis = plan_parameters(mechanism, options, model, args)
    text = node_params.params_file_text(values, params_comment(mechanism, args, basis))
    with open(path, 'w', encoding='utf-8') as stream:
        stream.write(text)
    return values
