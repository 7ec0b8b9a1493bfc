"""
One bag of a fleet recomputed: read, estimate, summarise per period, optionally write its MCAP.

:func:`recompute_bag` is the whole job of one bag as a plain function (no distributed engine:
``flexlink fleet`` runs it as one task per bag, a test or a script calls it directly). It
reads the crank samples as ``flexlink replay`` does (:func:`io.recording.scan_recording`,
:func:`io.joint_states.read_crank_samples`), estimates them in one sequential pass
(:func:`core.estimation.offline.estimate_offline`: the state carries from sample to
sample, so a bag is one task, its split files in order), and summarises each revolution or
minute (:mod:`core.estimation.summary`). Which mechanism, model options and model (linear,
or nonlinear where the recording says it was made with it) a bag is recomputed with is
decided in one place, :func:`bag_model`. A bag that cannot be recomputed gives a result with
its reason, never an exception.
"""

import dataclasses
import math
import time

from diagnostic_msgs.msg import DiagnosticStatus
import numpy as np

from .joint_states import parse_crank_states, read_input_samples, skip_reasons
from .provenance import read_provenance
from .replay_writer import write_replay
from ..core.estimation.gate import DEFAULT_RESET_GAP_S
from ..core.estimation.nonlinear_follow import choose_nonlinear, follow_rows, follow_summary, \
    NonlinearFollower
from ..core.estimation.offline import estimate_offline
from ..core.estimation.summary import period_ids, recording_totals, summarize_periods
from ..core.mechanism_file import load_mechanism
from ..core.reduction import mechanism_model
from ..core.reduction.nonlinear_model import nonlinear_model_for
from ..core.validity import is_valid, VALIDITY_THRESHOLD
from ..names import DEFAULT_FRAME_ID, NODE_NAME, output_topics

# Models kept loaded in a worker process (a worker recomputes many bags of one linkage).
_MODELS = {}
_MODELS_KEPT = 4
# The joints' level in the written markers, as replay draws them.
_MARKER_LEVELS = [DiagnosticStatus.OK] * 4


@dataclasses.dataclass(frozen=True)
class FleetSettings:
    """
    What every bag of a fleet run is recomputed with (besides its mechanism and options).

    Parameters
    ----------
    per : str
        'revolution' or 'minute': the table's periods.
    joint, topic : str, str or None
        The crank joint; the input topic (None: the one carrying the joint).
    warm_start : bool
        Start each segment from the periodic state (as replay without ``--no-warm-start``).
    cache_dir : str or None
        The model cache (None: the default one); ``use_cache`` False builds without it.
    validity_threshold : float
        Nonlinearity indicator above which a sample is outside the validity range.
    node_name, frame_id, markers_every_n :
        The written MCAP's output namespace, frame and marker spacing (as replay's flags).
    nonlinear : str or None
        'auto', 'on' or 'off' (replay's ``--nonlinear``); None: the model the recording
        says made it, else 'auto'.

    """

    per: str = 'revolution'
    joint: str = 'crank'
    topic: str = None
    warm_start: bool = True
    cache_dir: str = None
    use_cache: bool = True
    validity_threshold: float = VALIDITY_THRESHOLD
    node_name: str = NODE_NAME
    frame_id: str = DEFAULT_FRAME_ID
    markers_every_n: int = 10
    nonlinear: str = None


def bag_model(bag, fallback):
    """
    Choose the mechanism and model options a bag is recomputed with: the one place to decide.

    Parameters
    ----------
    bag : str
        The bag (its recorded mechanism and options, where it has them, come first).
    fallback : tuple or None
        (mechanism file or name, ModelOptions) of ``--mechanism`` and the model flags, for a
        bag without a recorded mechanism; None if not given.

    Returns
    -------
    mechanism : Mechanism
    options : ModelOptions
    source : str
        Where they came from, for the table ('--mechanism <file>').
    nonlinear : str or None
        'on' or 'off': the model the recording says made it (a recording from before the
        nonlinear model: 'off'); None where it names no model.

    """
    recorded = read_provenance(bag)    # a ProvenanceError fails this bag, saying why
    if recorded is not None and recorded.has_model:
        return (recorded.mechanism(), recorded.options(),
                f'recorded ({recorded.mechanism_file})', recorded.nonlinear or 'off')
    if fallback is None:
        raise ValueError(f'{bag} has no recorded mechanism: give `--mechanism`')
    mechanism_file, options = fallback
    return load_mechanism(mechanism_file), options, f'--mechanism {mechanism_file}', None


def _model(mechanism, options, settings):
    """Load the reduced model once per worker process (from the cache file or built)."""
    key = (mechanism_model.model_key(mechanism, options), settings.cache_dir, settings.use_cache)
    if key not in _MODELS:
        if len(_MODELS) >= _MODELS_KEPT:
            _MODELS.pop(next(iter(_MODELS)))
        _MODELS[key] = mechanism_model.model_for_mechanism(
            mechanism, options, cache_dir=settings.cache_dir, use_cache=settings.use_cache)
    return _MODELS[key]


def _nonlinear_rows(mechanism, options, settings, stamps_ns, estimate):
    """Put the nonlinear model's deflections into ``estimate``; its JSON entry."""
    key = ('nonlinear', mechanism_model.model_key(mechanism, options), settings.cache_dir,
           settings.use_cache)
    if key not in _MODELS:
        if len(_MODELS) >= _MODELS_KEPT:
            _MODELS.pop(next(iter(_MODELS)))
        _MODELS[key] = nonlinear_model_for(mechanism, options, settings.cache_dir,
                                           settings.use_cache)
    tables, damping = _MODELS[key]
    follower = NonlinearFollower(tables, DEFAULT_RESET_GAP_S)
    outputs, accepted = follow_rows(follower, stamps_ns, estimate)
    estimate['lever_tip'], estimate['coupler_mid'] = outputs[:, 0:2], outputs[:, 2:4]
    low = outputs[accepted].min(axis=0) if accepted.any() else np.full(outputs.shape[1], np.inf)
    high = outputs[accepted].max(axis=0) if accepted.any() else -low
    return follow_summary(follower, low, high, damping)


def skipped_per_period(messages, samples, ids, joint_name):
    """
    Count the skipped messages of each period, by reason (as ``flexlink replay`` words them).

    The usable samples are the messages in order with the skipped ones left out; a skipped
    message belongs to the period of the last usable sample logged at or before it.

    Returns
    -------
    list of dict
        {reason: count} per period (``ids.max() + 1`` entries).

    """
    periods = [{} for _ in range(int(ids.max()) + 1 if len(ids) else 0)]
    if len(messages) == len(samples['data']) or not periods:
        return periods
    skipped, used = [], 0
    usable = samples['data']
    for log_ns, _, data in messages:
        if used < len(usable) and data == usable[used]:
            used += 1
        else:
            skipped.append((log_ns, data))
    log_ns = np.array([t for t, _ in skipped], dtype=np.int64)
    owner = ids[np.clip(np.searchsorted(samples['log_ns'], log_ns, side='right') - 1,
                        0, len(ids) - 1)]
    payloads = [data for _, data in skipped]
    valid = parse_crank_states(payloads, joint_name.encode())[3]
    for period in np.unique(owner).tolist():
        chosen = np.flatnonzero(owner == period)
        periods[period] = skip_reasons([payloads[n] for n in chosen], valid[chosen],
                                       np.zeros(chosen.size, dtype=bool), joint_name.encode())
    return periods


def _choose_model(settings, recorded, estimate):
    """Return replay's ``model_choice`` for a bag: (use the nonlinear model, its dict)."""
    choice = settings.nonlinear or recorded or 'auto'
    use, why = choose_nonlinear(choice, is_valid(estimate['nonlinearity'])
                                if choice == 'auto' else None,
                                recorded=settings.nonlinear is None)
    return use, {'nonlinear': use, 'why': why, 'asked': choice}


def _replay_summary(bag, topic, samples, damaged, model, options, estimate, totals,
                    choice, nonlinear=None):
    """Return the keys of ``flexlink replay --json`` (and the bag's path) for one bag."""
    count = len(samples['data'])
    span_s = (samples['log_ns'][-1] - samples['log_ns'][0]) * 1e-9 if count > 1 else 0.0
    summary = {'bag': str(bag), 'input': str(bag), 'topic': topic, 'samples': count,
               'skipped': samples['skipped'], 'skipped_reasons': samples['skipped_reasons'],
               'damaged': [{'file': f, 'offset': o, 'reason': r} for f, o, r in damaged],
               'span_s': span_s,
               'model': {'size': model.size, 'step_size': model.step_size,
                         'soft_basis': model.info.get('soft'), 'grid_size': model.grid_size,
                         'options': str(options)}, 'order': model.order,
               'second_order': options.second_order if model.order == 2 else None,
               'notes': [], 'segments': estimate['segments'],
               'outliers': estimate['outliers'], 'out_of_bound': estimate['out_of_bound'],
               'criteria_available': estimate['criteria_available'],
               'model_choice': choice, 'nonlinear': nonlinear,
               'processes': {'used': 1}}     # one task, one process, per bag
    summary.update(totals)
    return summary


def recompute_bag(bag, fallback, settings, output=None):
    """
    Recompute one bag: its summary (replay's keys) and its table rows; never raises.

    Parameters
    ----------
    bag : str
        ``.mcap`` file or bag directory.
    fallback : tuple or None
        :func:`bag_model`'s fallback (``--mechanism`` and the model flags' options).
    settings : FleetSettings
        The run's settings.
    output : str or None
        Write the bag's replay MCAP here (as ``flexlink replay --out``).

    Returns
    -------
    dict
        'summary' (dict; 'error' is the reason, or None) and 'rows' (list of dict, one per
        period; one row with the reason for a failed bag).

    """
    start = time.perf_counter()
    try:
        return _recompute(bag, fallback, settings, output, start)
    except Exception as exc:    # noqa: B902 - any failure is this bag's row, the fleet goes on
        reason = str(exc) or type(exc).__name__
        return {'summary': {'bag': str(bag), 'input': str(bag), 'error': reason,
                            'seconds': time.perf_counter() - start},
                'rows': [failed_row(bag, reason, settings.per)]}


def failed_row(bag, reason, per):
    """Return the table row of a bag that could not be recomputed."""
    return {'bag': str(bag), 'per': per, 'index': -1, 'error': reason}


def _recompute(bag, fallback, settings, output, start):
    damaged = []
    mechanism, options, source, recorded = bag_model(bag, fallback)
    topic, samples, messages = read_input_samples(bag, settings.topic, settings.joint, damaged)
    read_s = time.perf_counter() - start
    model = _model(mechanism, options, settings)
    began = time.perf_counter()
    estimate = estimate_offline(model, samples['stamps_ns'], samples['angles'],
                                samples['speeds'], warm_start=settings.warm_start)
    use, choice = _choose_model(settings, recorded, estimate)
    nonlinear = (_nonlinear_rows(mechanism, options, settings, samples['stamps_ns'], estimate)
                 if use else None)
    estimate_s = time.perf_counter() - began
    finite = np.isfinite(estimate['lever_tip'][:, 0])
    ids = period_ids(samples['stamps_ns'], samples['angles'], finite, estimate['flags'],
                     settings.per)
    columns = summarize_periods(samples['stamps_ns'], estimate, ids,
                                settings.validity_threshold)
    summary = _replay_summary(bag, topic, samples, damaged, model, options, estimate,
                              recording_totals(columns), choice, nonlinear)
    summary.update(read_s=read_s, estimate_s=estimate_s, mechanism=source, error=None)
    if output is not None:
        status = write_replay(output, [(0, samples, estimate)], topic,
                              output_topics(settings.node_name), settings.frame_id, model,
                              settings.markers_every_n, joint_levels=_MARKER_LEVELS)
        summary.update(output=status['path'], output_files=status['files'],
                       output_topics=status['topics'])
    total = time.perf_counter() - start
    summary['seconds'] = total
    if output is not None:
        summary['write_s'] = total - read_s - estimate_s
    summary['samples_per_s'] = summary['samples'] / total if total > 0 else math.inf
    summary['times_real_time'] = summary['span_s'] / total if total > 0 else math.inf
    skipped = skipped_per_period(messages, samples, ids, settings.joint)
    rows = [dict(bag=str(bag), per=settings.per, mechanism=source, error=None,
                 skipped=sum(reasons.values()), skipped_reasons=reasons,
                 **{name: values[k].item() for name, values in columns.items()})
            for k, reasons in enumerate(skipped)]
    return {'summary': summary, 'rows': rows}
