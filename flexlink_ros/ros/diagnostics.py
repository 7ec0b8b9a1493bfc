"""
The statuses of flexlink_node's ``/diagnostics``: plain functions of the node's counts.

One status for the input, one for the estimator, one per joint (O2, A, B, O4) and one for the
recorder, each from the totals (:class:`message_outcomes.Totals`), the period's counts
(:class:`message_outcomes.PeriodStats`) and the node's parameter values. A managed node that is not
active says so instead (:func:`inactive_statuses`, :func:`unconfigured_statuses`). The names
are relative ('estimator'); :func:`named` prefixes them with the node's fully qualified name,
as diagnostic_updater prefixes its node's name ('/robot1/flexlink_node: estimator').
"""

import math

import numpy as np

from .message_outcomes import OTHER_KINDS, PeriodStats, SKIP_KINDS, WARN_FLAGS
from .messages import ERROR, joint_level, OK, STALE, status, WARN
from ..core.estimation.sample import SampleFlag
from ..core.validity import VALIDITY_THRESHOLD
from ..names import JOINT_NAMES


def input_status(totals, period, values, topic, rate_hz, stale_s, watch=({}, ())):
    """
    Say whether valid input arrives, and what became of every received message.

    Parameters
    ----------
    totals : message_outcomes.Totals
        Counts since the start.
    period : message_outcomes.PeriodStats
        Counts of the period.
    values : dict
        Parameter name -> value.
    topic : str
        The input topic.
    rate_hz : float
        Valid samples per second in the period.
    stale_s : float
        Time since the last valid sample [s] (inf if none yet).
    watch : (dict, list of str)
        :meth:`.input_watch.InputWatch.judge`'s facts (key values) and sentences (WARN).

    Returns
    -------
    diagnostic_msgs.msg.DiagnosticStatus

    """
    level, message = OK, 'receiving'
    if stale_s > values['diagnostics.stale_input_s']:
        level = ERROR
        message = ('no valid input yet' if math.isinf(stale_s)
                   else f'no valid input for {stale_s:.2f} s')
    elif rate_hz < values['diagnostics.min_rate_hz']:
        level, message = WARN, f'input rate {rate_hz:.1f} Hz below ' \
            f'{values["diagnostics.min_rate_hz"]:g} Hz'
    elif period.rejected or period.counts.get('outlier') or period.counts.get('conflicting'):
        level, message = WARN, (f'{period.rejected} input messages skipped, '
                                f'{period.counts.get("outlier", 0)} outliers, '
                                f'{period.counts.get("conflicting", 0)} conflicting')
    facts, sentences = watch
    if sentences:
        message = '; '.join(list(sentences) if level == OK else [message, *sentences])
        level = max(level, WARN)
    return status('input', level, message, input_counts(
        totals, period, {'topic': topic, 'rate_hz': rate_hz, 'stale_s': stale_s, **facts}))


def input_counts(totals, period, values):
    """
    Add to ``values`` the input status's key values: what became of every received message.

    Parameters
    ----------
    totals : message_outcomes.Totals
        Counts since the start.
    period : message_outcomes.PeriodStats
        Counts of the period.
    values : dict
        Key values so far (changed in place and returned).

    """
    values.update({'received': totals.received, 'published': totals.published,
                   'skipped': totals.rejected, 'skipped_in_period': period.rejected,
                   'last_skip_reason': totals.last_rejection,
                   'last_outlier': totals.last_outlier})
    for kind in SKIP_KINDS:
        values[f'skipped_{kind}'] = totals.counts[kind]
    for kind in OTHER_KINDS:
        values[kind] = totals.counts[kind]
        values[f'{kind}_in_period'] = period.counts.get(kind, 0)
    return values


def estimator_level(period, error_indicator_warn, nonlinearity_warn=VALIDITY_THRESHOLD,
                    nonlinear=False):
    """
    Grade the estimates: ERROR if out of bound, WARN if flagged or a large indicator.

    Parameters
    ----------
    period : message_outcomes.PeriodStats
        Counts of the period.
    error_indicator_warn : float
        WARN above this error indicator.
    nonlinearity_warn : float
        WARN above this validity indicator (core/validity.py: near a resonance the
        amplitude-dependent detuning makes the linear estimate untrustworthy).
    nonlinear : bool
        The nonlinear model made the deflections: the indicator is its own
        (core/estimation/nonlinear_follow.py: links bent beyond its strain's reach).

    Returns
    -------
    level : int
    message : str

    """
    if period.counts.get('out_of_bound'):
        return ERROR, (f'{period.counts["out_of_bound"]} estimates not published: '
                       f'{period.last_out_of_bound}')
    reasons = []
    flagged = SampleFlag(period.flags & WARN_FLAGS)
    if flagged:
        reasons.append('flagged ' + ' '.join(f.name for f in SampleFlag if f and f & flagged))
    if period.counts.get('outlier'):
        reasons.append(f'{period.counts["outlier"]} outliers skipped')
    indicator = period.max_error_indicator
    if indicator > error_indicator_warn:
        reasons.append(f'error indicator {indicator:.3g}')
    if period.max_nonlinearity > nonlinearity_warn:
        reasons.append(
            f'nonlinear estimate not valid: validity indicator {period.max_nonlinearity:.3g} '
            f"above {nonlinearity_warn:g} (links bent beyond the slope the model's strain "
            'carries)' if nonlinear else
            f'linear estimate not valid: nonlinearity indicator {period.max_nonlinearity:.3g} '
            f'above {nonlinearity_warn:g} (near resonance, the amplitude detunes the links)')
    return (WARN, ', '.join(reasons)) if reasons else (OK, 'ok')


def estimator_status(period, values, model_facts):
    """
    Report the estimator: update times, flags, error and validity indicators, and its model.

    'nonlinearity_max' is the largest validity indicator of the period (NaN when the model
    has no indicator tables or no sample came), 'nonlinearity_threshold' the WARN threshold
    (``diagnostics.nonlinearity_warn``). Where the nonlinear model makes the deflections
    (``model_nonlinear`` 'on') the indicator is the nonlinear model's.

    Parameters
    ----------
    period : message_outcomes.PeriodStats
        Counts of the period.
    values : dict
        Parameter name -> value.
    model_facts : dict
        Key values describing the model (size, grid, options, criteria source, notes).

    Returns
    -------
    diagnostic_msgs.msg.DiagnosticStatus

    """
    durations = np.array(period.update_ns) / 1e3
    median = float(np.median(durations)) if durations.size else math.nan
    p99 = float(np.percentile(durations, 99)) if durations.size else math.nan
    flags = [flag.name for flag in SampleFlag if flag and period.flags & flag]
    level, message = estimator_level(period, values['diagnostics.error_indicator_warn'],
                                     values['diagnostics.nonlinearity_warn'],
                                     model_facts.get('model_nonlinear') == 'on')
    return status('estimator', level, message, {
        'error_indicator_max': period.max_error_indicator,
        'nonlinearity_max': (period.max_nonlinearity if math.isfinite(period.max_nonlinearity)
                             else math.nan),
        'nonlinearity_threshold': values['diagnostics.nonlinearity_warn'],
        'update_us_median': median,
        'update_us_p99': p99, 'samples_in_period': period.valid, 'flags': ' '.join(flags),
        **model_facts})


def joint_statuses(period, values, criteria_source):
    """
    Grade each joint by the largest criterion of the period.

    Parameters
    ----------
    period : message_outcomes.PeriodStats
        Counts of the period.
    values : dict
        Parameter name -> value.
    criteria_source : str
        Where the model's joint criteria come from (named when they are unavailable).

    Returns
    -------
    list of diagnostic_msgs.msg.DiagnosticStatus
        O2, A, B, O4.

    """
    statuses = []
    no_criteria = period.flags & SampleFlag.NO_CRITERIA
    for j, name in enumerate(JOINT_NAMES):
        ratio = period.max_criterion[j]
        if no_criteria:
            level, message = STALE, f'criteria unavailable: {criteria_source}'
        elif not period.valid:
            level, message = STALE, 'no samples'
        else:
            level = joint_level(ratio, period.near_zero[j], values['diagnostics.criterion_warn'],
                                values['diagnostics.criterion_error'])
            message = f'max |dgamma/dt|/R {ratio:.4g} rad/(s N)' + (
                ', reaction near zero' if period.near_zero[j] else '')
        statuses.append(status(f'joint {name}', level, message,
                               {'criterion_max': ratio, 'near_zero': period.near_zero[j]}))
    return statuses


def recorder_status(state):
    """
    Report the recording: ERROR when it failed or lost messages to a full write queue.

    Parameters
    ----------
    state : dict or None
        ``McapRecorder.status(list_files=False)``; None when not recording.

    Returns
    -------
    diagnostic_msgs.msg.DiagnosticStatus

    """
    if state is None:
        return status('recorder', OK, 'disabled', {})
    failed = state['state'] == 'failed'
    lost = state.get('overflow_count', 0)
    if failed:
        text = f'FAILED: {state["error"]}'
    elif lost:
        text = (f'{state["state"]}; {lost} messages lost: the write queue was full (the disk '
                'did not keep up)')
    else:
        text = state['state']
    return status('recorder', ERROR if failed or lost else OK, text, {
        'path': state['path'], 'messages': state['message_count'],
        'dropped': state['dropped_count'], 'overflow': lost, 'bytes': state['bytes_written'],
        'files': state['file_count']})


def inactive_statuses(totals, topic, model_facts, recorder_state):
    """
    Report a managed node that is configured but not active: model loaded, input not read.

    Parameters
    ----------
    totals : message_outcomes.Totals
        Counts since the configure transition.
    topic : str
        The input topic (not subscribed while inactive).
    model_facts : dict
        Key values describing the model.
    recorder_state : dict or None
        ``McapRecorder.status()``; None when not recording.

    Returns
    -------
    list of diagnostic_msgs.msg.DiagnosticStatus
        input (STALE), estimator (OK, configured), recorder.

    """
    return [status('input', STALE, f'inactive: not subscribed to {topic}',
                   input_counts(totals, PeriodStats(), {'topic': topic})),
            status('estimator', OK, 'configured, waiting for activation', model_facts),
            recorder_status(recorder_state)]


def unconfigured_statuses():
    """Report a managed node before its configure transition (no model, no input)."""
    return [status('estimator', STALE, 'unconfigured: waiting for the configure transition',
                   {})]


def named(statuses, node_name, hardware_id):
    """
    Prefix every status name with the node's name and set its hardware_id (in place).

    Parameters
    ----------
    statuses : list of diagnostic_msgs.msg.DiagnosticStatus
        Statuses with relative names ('estimator').
    node_name : str
        The node's fully qualified name ('/robot1/flexlink_node').
    hardware_id : str
        The ``diagnostics.hardware_id`` parameter.

    Returns
    -------
    list of diagnostic_msgs.msg.DiagnosticStatus
        ``statuses``, named '<node_name>: <name>'.

    """
    for item in statuses:
        item.name = f'{node_name}: {item.name}'
        item.hardware_id = hardware_id
    return statuses
