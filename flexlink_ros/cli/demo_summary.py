"""
What a flexlink_node recording holds: the summary `flexlink demo` prints.

Read the recording (input, outputs, quality, diagnostics; markers skipped), tally it per
topic and joint, and return one dict: counts, rates, peak-to-peak deflections, criterion peaks,
the largest quality indicators with the validity verdict, latencies and the estimator's update
times.
"""

import pathlib

import numpy as np

from .mcap import mcap_info
from ..core.validity import is_valid
from ..io.msg_schema import message_class
from ..io.recording import iter_recording
from ..names import JOINT_NAMES, JOINT_STATE


def _decode(type_name, data):
    from rclpy.serialization import deserialize_message

    return deserialize_message(data, message_class(type_name))


def summarise_recording(bag):
    """
    Summarise what a flexlink_node recording holds.

    Parameters
    ----------
    bag : str or os.PathLike
        The bag directory the node recorded.

    Returns
    -------
    dict
        path, files, bytes, complete, topics (name -> count), input_rate_hz, input_span_s,
        samples, outputs, peak_to_peak_um {lever_tip, coupler_mid: [dx, dy]},
        criteria_max (joint -> value) or None, criteria_reason, quality {error_indicator_max,
        nonlinearity: core.validity.is_valid of the largest nonlinearity indicator} or None,
        latency_us {median, p99}, update_us {median, p99}.

    """
    info = mcap_info(bag)
    read = _read_recording(bag)
    samples = len(read['input_stamps'])
    stamps = read['input_stamps']
    span = (max(stamps) - min(stamps)) * 1e-9 if samples > 1 else 0.0
    output_log, input_log = read['output_log'], read['input_log']
    latency = np.array([output_log[s] - input_log[s] for s in output_log if s in input_log])
    peak = {key: (1e6 * (np.ptp(np.array(values), axis=0))).tolist() if values else None
            for key, values in read['deflections'].items()}
    source, update = _estimator_diagnostics(read['diagnostics'])
    return {
        'path': str(bag), 'files': [f['path'] for f in info.get('files', [info])],
        'bytes': sum(p.stat().st_size for p in pathlib.Path(bag).glob('*.mcap')),
        'complete': info['complete'],
        'topics': {t['topic']: t['count'] for t in info['topics']}, 'samples': samples,
        'input_span_s': span, 'input_rate_hz': (samples - 1) / span if span > 0 else 0.0,
        'outputs': len(read['deflections']['lever_tip']),
        'peak_to_peak_um': peak,
        **_criteria_summary(np.array(read['criteria']), source),
        'quality': _quality_summary(read['quality']),
        'latency_us': ({'median': float(np.median(latency) / 1e3),
                        'p99': float(np.percentile(latency, 99) / 1e3)}
                       if latency.size else None),
        # Per diagnostics period: the median of the period medians and the worst p99.
        'update_us': ({'median': float(np.median(update['update_us_median'])),
                       'p99': float(np.max(update['update_us_p99']))}
                      if update['update_us_median'] else None),
    }


def _read_recording(bag):
    """
    Read the node's input, outputs and diagnostics from a recording (markers skipped).

    Returns
    -------
    dict
        ``input_log`` and ``output_log`` (header stamp -> log time [ns], first of each),
        ``input_stamps``, ``deflections`` (lever_tip, coupler_mid -> list of (dx, dy)),
        ``criteria`` (rows: criteria of the 4 joints, then their reactions), ``quality``
        (rows: error indicator, nonlinearity indicator) and ``diagnostics`` (messages).

    """
    read = {'input_log': {}, 'output_log': {}, 'input_stamps': [], 'criteria': [],
            'deflections': {'lever_tip': [], 'coupler_mid': []}, 'diagnostics': [],
            'quality': []}
    for topic, type_name, log_ns, _, data in iter_recording(bag):
        if topic.endswith('/markers'):
            continue
        message = _decode(type_name, data)
        if topic.endswith('/quality'):     # a JointState too: not the input
            read['quality'].append(list(message.position))
            continue
        if topic == '/diagnostics':
            read['diagnostics'].append(message)
            continue
        stamp = message.header.stamp.sec * 1_000_000_000 + message.header.stamp.nanosec
        if topic.endswith('/lever_tip/deflection'):
            read['deflections']['lever_tip'].append((message.vector.x, message.vector.y))
            read['output_log'].setdefault(stamp, log_ns)
        elif topic.endswith('/coupler_mid/deflection'):
            read['deflections']['coupler_mid'].append((message.vector.x, message.vector.y))
        elif topic.endswith('/joint_criteria'):
            read['criteria'].append(list(message.position) + list(message.effort))
        elif type_name == JOINT_STATE:
            read['input_stamps'].append(stamp)
            read['input_log'].setdefault(stamp, log_ns)
    return read


def _estimator_diagnostics(diagnostics):
    """Return the estimator's criteria source and its update times [us] per period."""
    estimator = [s for d in diagnostics for s in d.status if s.name.endswith('estimator')]
    source = next((kv.value for s in estimator for kv in s.values
                   if kv.key == 'criteria_source'), 'unknown')
    update = {}
    for key in ('update_us_median', 'update_us_p99'):
        values = [float(kv.value) for s in estimator for kv in s.values
                  if kv.key == key and kv.value != 'nan']
        update[key] = values
    return source, update


def _quality_summary(rows):
    """Return the largest error indicator and the validity verdict of the estimates, or None."""
    if not rows:
        return None
    values = np.array(rows, dtype=float)
    return {'error_indicator_max': float(np.nanmax(values[:, 0])),
            'nonlinearity': is_valid(values[:, 1])}


def _criteria_summary(criteria, source):
    """Return the per-joint criterion peaks and reactions, or why they are unavailable."""
    available = criteria.size > 0 and bool(np.any(criteria[:, :4] != 0.0))
    if not available:
        return {'criteria_max': None, 'reaction_at_max_n': None, 'reaction_median_n': None,
                'criteria_reason': source}
    return {
        'criteria_max': dict(zip(JOINT_NAMES, criteria[:, :4].max(axis=0).tolist())),
        # Reaction at the worst sample and the median reaction per joint [N]: a criterion
        # peak where R nearly vanishes reads differently from one at full load.
        'reaction_at_max_n': dict(zip(JOINT_NAMES, criteria[
            np.argmax(criteria[:, :4], axis=0), 4 + np.arange(4)].tolist())),
        'reaction_median_n': dict(zip(JOINT_NAMES,
                                      np.median(criteria[:, 4:], axis=0).tolist())),
        'criteria_reason': None,
    }
