"""
`flexlink replay`: recompute deflections and joint criteria offline from a recording.

Reads the crank ``sensor_msgs/JointState`` messages of any rosbag2 MCAP (a bare ``.mcap`` file,
a bag directory, or a truncated or damaged file: every intact chunk is used, damaged ones are
skipped and listed, :mod:`mcap_salvage`), runs the estimator over
them in batches (:func:`core.estimator.replay`, the same numbers as the streaming node), and
writes a new MCAP with the input and the node's output topics, each output stamped with its
input's stamp and logged at the input's log time. ``--publish`` republishes the input with its
recorded timing for live subscribers (a running flexlink_node, Foxglove, RViz).

Like the node, a sample whose stamp goes back or jumps by more than the estimator's reset gap
starts a new segment (the state restarts), an exactly repeated sample repeats the previous
output, and messages without the crank joint, with a non-finite value or that are not a
readable JointState are skipped and counted by reason. Samples the estimator's input gate
refuses (core.estimator.InputGate: an implausible speed, speed jump or angle advance) are
counted as outliers, and an estimate beyond the model's deflection bound as out of bound: both
keep their input in the output file but get no output messages, and after an out-of-bound
sample the estimate restarts, as in the node.
"""

import functools
import math
import pathlib
import struct
import sys
import threading
import time

import numpy as np

from ..names import JOINT_STATE, MARKER_ARRAY, VECTOR3_STAMPED, output_topics
from .main import emit
from .estimate import _common, load_model, model_options
from ..io.cdr import parse_joint_state
from ..core.estimation import streaming as core_estimator
from ..core.mechanism import load_mechanism
from ..core.reduction.model import JOINTS
from ..io.recorder import McapRecorder, refuse_existing
from ..io.mcap_reader import (
    MESSAGE_HEAD, MESSAGE_HEAD_SIZE, McapFileError, Salvage, iter_messages, map_file,
    message_fields,
)

PROGRESS_PERIOD_S = 0.5  # seconds between progress-bar updates


# -- reading ---------------------------------------------------------------------------------

def recording_files(path):
    """The MCAP files of a bare file or a bag directory (in split order)."""
    path = pathlib.Path(path)
    if path.is_dir():
        files = sorted(path.glob('*.mcap'),
                       key=lambda p: (len(p.stem.rsplit('_', 1)[-1]), p.stem))
        if not files:
            raise ValueError(f'`input`: no .mcap files in {path}')
        return files
    if not path.exists():
        raise ValueError(f'`input`: no such file or directory: {path}')
    return [path]


def iter_recording(path, topics=None, damaged=None):
    """
    Messages of a recording, file by file in file order, including truncated files.

    Damaged chunks are skipped (:mod:`mcap_salvage`); a file that is not MCAP is skipped.

    Parameters
    ----------
    path : str or os.PathLike
        ``.mcap`` file or bag directory.
    topics : collection of str or None
        Only these topics (None: all).
    damaged : list, optional
        Receives (file, offset, reason) of every skipped file, chunk or record.

    Yields
    ------
    (topic, type_name, log_time_ns, publish_time_ns, data)

    """
    for file in recording_files(path):
        salvage = Salvage()
        buffer = _map_or_report(file, damaged)
        if buffer is None:
            continue
        try:
            for records, body, stop in iter_messages(buffer, salvage):
                channel_id, _, log_time, publish_time, data = message_fields(records, body, stop)
                channel = salvage.channels.get(channel_id)
                if channel is None or channel.message_encoding != 'cdr':
                    continue
                if topics is not None and channel.topic not in topics:
                    continue
                schema = salvage.schemas.get(channel.schema_id)
                yield (channel.topic, schema.name if schema else '', log_time, publish_time,
                       data)
        finally:
            buffer.close()
            _report(file, salvage, damaged)


# A channel of the wanted type is probed for the crank joint in at most this many messages.
JOINT_PROBE_MESSAGES = 1000


def _map_or_report(file, damaged):
    try:
        return map_file(file)
    except McapFileError as exc:
        if damaged is not None:
            damaged.append((str(file), 0, str(exc)))
        return None


def _report(file, salvage, damaged):
    if damaged is not None:
        damaged.extend((str(file), offset, reason) for offset, reason in salvage.damaged)
        hidden = salvage.damaged_count - len(salvage.damaged)
        if hidden:
            damaged.append((str(file), None, f'{hidden} more damaged places'))


def _file_messages(file, wanted, keep_rest=None, damaged=None):
    """
    Intact messages of one (possibly truncated or damaged) MCAP file, read in one pass.

    Reads with :func:`mcap_salvage.iter_messages` (bounded; damaged chunks skipped and
    reported in ``damaged``) and keeps only the payloads replay needs.

    Parameters
    ----------
    file : pathlib.Path
    wanted : callable
        ``wanted(topic, type_name)``: keep the payloads of this channel's messages.
    keep_rest : callable, optional
        ``keep_rest(data)``: the message carries what replay looks for. A wanted channel is
        kept from its start once one of its first ``JOINT_PROBE_MESSAGES`` messages does;
        if none does, only those are kept.
    damaged : list, optional
        Receives (file, offset, reason) of every skipped file, chunk or record.

    Returns
    -------
    counts : dict
        Topic -> [type name, message count] of every CDR channel with messages.
    kept : dict
        Topic -> list of (log_time_ns, publish_time_ns, data) of the wanted channels.

    """
    counts, kept, states = {}, {}, {}
    salvage = Salvage()
    buffer = _map_or_report(file, damaged)
    if buffer is None:
        return counts, kept
    try:
        for records, body, stop in iter_messages(buffer, salvage):
            channel_id, _, log_time, publish_time = MESSAGE_HEAD.unpack_from(records, body)
            channel = salvage.channels.get(channel_id)
            state = states.get(channel_id)
            if state is None or state[0] is not channel:
                state = states[channel_id] = _channel_state(channel, salvage, wanted,
                                                            keep_rest, counts, kept)
            entry, store = state[1], state[2]
            if entry is None:
                continue
            entry[1] += 1
            if store is None:
                continue
            data = records[body + MESSAGE_HEAD_SIZE:stop]
            store.append((log_time, publish_time, data))
            if state[3] is not None:     # still probing for the joint
                if keep_rest(data):
                    state[3] = None
                else:
                    state[3] -= 1
                    if state[3] == 0:
                        state[2] = None
    finally:
        buffer.close()
        _report(file, salvage, damaged)
    return {topic: entry for topic, entry in counts.items() if entry[1]}, kept


def _channel_state(channel, salvage, wanted, keep_rest, counts, kept):
    # [channel, counts entry (None: not CDR), kept list (None: not kept), probes left].
    if channel is None or channel.message_encoding != 'cdr':
        return [channel, None, None, None]
    schema = salvage.schemas.get(channel.schema_id)
    type_name = schema.name if schema else ''
    entry = counts.setdefault(channel.topic, [type_name, 0])
    if not wanted(channel.topic, type_name):
        return [channel, entry, None, None]
    probes = None if keep_rest is None else JOINT_PROBE_MESSAGES
    return [channel, entry, kept.setdefault(channel.topic, []), probes]


def has_joint(data, joint_name):
    """Whether JointState CDR bytes carry a position for ``joint_name`` (False if malformed)."""
    try:
        return parse_joint_state(data, joint_name)[1] is not None
    except (struct.error, IndexError, ValueError, OverflowError):
        return False


def scan_recording(path, keep_type=JOINT_STATE, topic=None, joint_name=None, damaged=None):
    """
    Topics and the messages of one type of a recording, in one pass over its files.

    Parameters
    ----------
    path : str or os.PathLike
    keep_type : str
        Keep the messages of the topics of this type ...
    topic : str, optional
        ... only of this topic ...
    joint_name : str, optional
        ... or (no ``topic``) only of topics with this joint in one of their first
        ``JOINT_PROBE_MESSAGES`` messages (of the others only those).
    damaged : list, optional
        Receives (file, offset, reason) of every skipped file, chunk or record.

    Returns
    -------
    counts : dict
        Topic -> [type name, message count] (CDR channels with messages).
    kept : dict
        Topic -> list of (log_time_ns, publish_time_ns, data) of the kept topics.

    """
    def wanted(name, type_name):
        return type_name == keep_type and (topic is None or name == topic)

    keep_rest = None
    if topic is None and joint_name is not None:
        keep_rest = functools.partial(has_joint, joint_name=joint_name.encode())
    counts, kept = {}, {}
    for file in recording_files(path):
        file_counts, file_kept = _file_messages(file, wanted, keep_rest, damaged)
        for topic_name, (type_name, count) in file_counts.items():
            counts.setdefault(topic_name, [type_name, 0])[1] += count
        for topic_name, messages in file_kept.items():
            kept.setdefault(topic_name, []).extend(messages)
    return counts, kept


# -- estimation --------------------------------------------------------------------------

def criteria_batch(model, angles, speeds, accels,
                   near_zero_fraction=core_estimator.DEFAULT_NEAR_ZERO_FRACTION, blocks=None):
    """
    Joint reactions, direction rates and Earles-Wu criteria at many crank states.

    The same tabulated quantities as StreamingEstimator._criteria, vectorised.

    Parameters
    ----------
    model : ReducedModel
    angles, speeds, accels : ndarray, shape (m,)
        Crank state as the model sees it (speed and acceleration clipped).
    near_zero_fraction : float
    blocks : dict, optional
        'force', 'force_dot' (m, joints, 2) and 'rms2' (m, joints) at these states, if
        already evaluated (core.estimator.replay returns them); else the table is evaluated.

    Returns
    -------
    reaction_n, gamma_dot, criterion : ndarray, shape (m, 4)
    near_zero : ndarray of bool, shape (m, 4)
    available : bool
        False if the model has no joint-reaction data (all zeros then).

    """
    count = len(angles)
    zeros = np.zeros((count, len(JOINTS)))
    if not np.any(model.force_moments):
        return zeros, zeros, zeros, zeros.astype(bool), False
    if blocks is None:
        rows = model.evaluate(angles, speeds, accels)
        blocks = {name: model.layout.block(rows, name)
                  for name in ('force', 'force_dot', 'rms2')}
    force, rate, rms2 = blocks['force'], blocks['force_dot'], blocks['rms2']
    r2 = np.sum(force ** 2, axis=2)
    # Below REACTION_FLOOR_FRACTION of the cycle RMS the reaction is clamped (finite criterion).
    clamped = np.maximum(r2, core_estimator.REACTION_FLOOR_FRACTION ** 2 * rms2)
    positive = clamped > 0.0
    safe = np.where(positive, clamped, 1.0)
    gamma_dot = np.where(positive, (force[..., 0] * rate[..., 1]
                                    - force[..., 1] * rate[..., 0]) / safe, 0.0)
    criterion = np.where(positive, np.abs(gamma_dot) / np.sqrt(safe), 0.0)
    reaction = np.where(positive, np.sqrt(r2), 0.0)
    return reaction, gamma_dot, criterion, r2 < near_zero_fraction ** 2 * rms2, True


def segments(stamps_ns, angles, reset_gap_s=core_estimator.DEFAULT_RESET_GAP_S):
    """
    Split a sample stream where the streaming estimator would restart on its stamps.

    Stamps and angles only, without the input gate's outliers (estimate_offline plans its
    rows with core.estimator.plan_rows, which has both).

    Returns
    -------
    starts : list of int
        First index of each segment.
    repeated : ndarray of bool, shape (m,)
        Exact repeats of the previous sample (same stamp and wrapped angle).

    """
    stamps_ns = np.asarray(stamps_ns, dtype=np.int64)
    steps = np.diff(stamps_ns)
    wrapped = np.mod(angles, 2.0 * math.pi)
    repeated = np.concatenate([[False], (steps == 0) & (np.abs(np.diff(wrapped)) < 1e-12)])
    # Each kept sample against the previous kept one (repeats are skipped, as the node does).
    kept = np.flatnonzero(~repeated)
    dt = np.diff(stamps_ns[kept]) * 1e-9
    starts = [0] + kept[1:][(dt <= 0.0) | (dt > reset_gap_s)].tolist()
    return starts, repeated


def allocate_estimate(model, count):
    """The arrays :func:`estimate_offline` fills (zeros; 'flags' per sample)."""
    result = {key: np.zeros((count, 2)) for key in ('lever_tip', 'coupler_mid')}
    for key in ('reaction_n', 'gamma_dot', 'criterion'):
        result[key] = np.zeros((count, len(JOINTS)))
    result['crank_angle'] = np.zeros(count)
    result['crank_speed'] = np.zeros(count)
    result['modal'] = np.zeros((count, model.size))
    result['flags'] = np.zeros(count, dtype=np.int64)
    return result


_ESTIMATE_KEYS = ('lever_tip', 'coupler_mid', 'crank_angle', 'crank_speed', 'modal',
                  'reaction_n', 'gamma_dot', 'criterion')
_Gate = core_estimator.InputGate
_Flag = core_estimator.SampleFlag
# Rows planned at a time (core.estimator.plan_rows) ahead of the segment being replayed;
# after a restart the window starts small and doubles (little work lost if it stops again).
PLAN_WINDOW = 4096
FIRST_PLAN_WINDOW = 64


def estimate_offline(model, stamps_ns, angles, speeds, warm_start=True, result=None,
                     progress=None):
    """
    Deflections and criteria of every sample, segment by segment as the node would.

    The rows are planned as StreamingEstimator.update decides (core.estimator.plan_rows:
    restarts, repeats, outliers); each segment is replayed in one go. Outlier rows and rows
    whose estimate left the model's deflection bound are NaN (flagged OUTLIER and
    OUT_OF_BOUND); after an out-of-bound row the rest is planned again, as the node restarts.

    Parameters
    ----------
    model : ReducedModel
    stamps_ns : ndarray of int, shape (m,)
    angles : ndarray, shape (m,)
    speeds : ndarray, shape (m,)
        Measured speeds; NaN where a message had none (the segment then differentiates).
    result : dict or None
        The arrays to fill (:func:`allocate_estimate`); new ones if None.
    progress : callable or None
        ``progress(n)`` whenever the first n samples are final (the writer of the outputs
        follows it while the rest is computed).

    Returns
    -------
    dict of ndarray
        'lever_tip', 'coupler_mid' (m, 2) [m]; 'reaction_n', 'gamma_dot', 'criterion' (m, 4);
        'crank_angle', 'crank_speed' (m,); 'modal' (m, r); 'flags' (m,); 'criteria_available'
        (bool); 'segments', 'outliers', 'out_of_bound' (int).

    """
    count = len(stamps_ns)
    if result is None:
        result = allocate_estimate(model, count)
    run = _OfflineRun(model, np.asarray(stamps_ns, dtype=np.int64), np.asarray(angles, float),
                      np.asarray(speeds, float), warm_start, result, progress)
    position = 0
    while position < count:
        position = run.next_segment(position)
    run.finish_until(count)
    flags = result['flags']
    result.update(criteria_available=run.available, segments=run.segments,
                  outliers=int(np.count_nonzero(flags & _Flag.OUTLIER)),
                  out_of_bound=int(np.count_nonzero(flags & _Flag.OUT_OF_BOUND)))
    return result


class _OfflineRun:
    """The state of :func:`estimate_offline`: segments, repeats to copy, rows final so far."""

    def __init__(self, model, stamps_ns, angles, speeds, warm_start, result, progress):
        self.model, self.stamps_ns, self.angles, self.speeds = model, stamps_ns, angles, speeds
        self.warm_start, self.result, self.progress = warm_start, result, progress
        self.count = stamps_ns.size
        self.available = bool(np.any(model.force_moments))
        self.tables = core_estimator.step_tables(model)    # built once, not per segment
        self.orbit = None   # carried across segments, as one streaming estimator carries it
        # Warm starts rate-limited on the recording's clock (its latest stamp so far): the
        # same numbers on any machine, and a storm of restarts costs no more than the node's.
        self.clock_s = -math.inf
        self.limiter = core_estimator.WarmStartLimiter(clock=lambda: self.clock_s)
        self.repeats = []           # (row, row it repeats), in order
        self.copied = 0             # repeats copied so far
        self.kinds = np.zeros(self.count, dtype=np.int8)    # InputGate kinds, as planned
        self.restart_plan(0)
        self.segments = 0
        self.final = 0
        self.chosen = self.stop = self.resume = None
        self.measured = True
        self.done = 0
        self.last_accepted = -1

    def restart_plan(self, position):
        """Plan the rows from ``position`` afresh (the first sample, or after out of bound)."""
        self.gate = _Gate(self.model.speed_max, core_estimator.DEFAULT_ACCEL_LIMIT)
        self.planned = position
        self.window = FIRST_PLAN_WINDOW

    def plan_window(self):
        """Plan a window more rows (core.estimator.plan_rows, the gate carried on)."""
        stop = min(self.planned + min(self.window, PLAN_WINDOW), self.count)
        self.window *= 2
        window = slice(self.planned, stop)
        self.kinds[window], _ = core_estimator.plan_rows(
            self.stamps_ns[window], self.angles[window], self.speeds[window], self.gate)
        self.planned = stop

    def next_start(self, position):
        """The first START row at or after ``position`` in the planned rows, or None."""
        starts = np.flatnonzero(self.kinds[position:self.planned] == _Gate.START)
        return position + int(starts[0]) if starts.size else None

    def next_segment(self, position):
        """
        Replay the segment that starts at or after ``position``; where the next one may start.

        Planned and replayed a window at a time (one replay() call resumed per window): an
        out-of-bound row wastes at most a window of planning and stepping, so a recording
        that goes out of bound often costs time linear in its length.
        """
        first = self.next_start(position)
        while first is None and self.planned < self.count:
            self.plan_window()
            first = self.next_start(position)
        first = self.count if first is None else first
        self.mark(np.arange(position, first), _Flag.OUTLIER)   # no start before: outliers
        if first == self.count:
            return self.count
        while self.planned < min(first + 3, self.count):
            self.plan_window()      # replay()'s first call takes the deferred warm start
        self.segments += 1
        self.result['flags'][first] |= int(_Flag.RESET)
        self.last_accepted, self.resume = first, None
        start, search = first, first + 1
        while True:
            found = self.next_start(search)
            stop = self.planned if found is None else found
            stopped = self.piece(start, stop)
            if stopped is not None:
                # The node restarts at the next sample: plan the rest again from there.
                self.restart_plan(stopped + 1)
                self.result['flags'][stopped + 1:stop] = 0
                del self.repeats[self.copied:]
                return stopped + 1
            if found is not None or stop == self.count:
                return stop
            self.plan_window()
            start = search = stop

    def piece(self, start, stop):
        """Rows start...stop of the current segment: outliers, repeats, steps; None or a stop."""
        rows = np.arange(start, stop)
        kinds = self.kinds[start:stop]
        self.mark(rows[kinds == _Gate.OUTLIER], _Flag.OUTLIER)
        accepted = (kinds == _Gate.STEP) | (kinds == _Gate.START)
        # Each repeat copies the last accepted row before it.
        source = np.maximum.accumulate(np.where(accepted, rows, self.last_accepted))
        repeated = np.flatnonzero(kinds == _Gate.REPEATED)
        self.repeats += zip(rows[repeated].tolist(), source[repeated].tolist())
        chosen = rows[accepted]
        if chosen.size == 0:
            self.finish_until(stop)
            return None
        self.last_accepted = int(chosen[-1])
        return self.segment(chosen, stop)

    def mark(self, rows, flag):
        """Rows with no estimate (NaN), flagged."""
        for key in _ESTIMATE_KEYS:
            self.result[key][rows] = math.nan
        self.result['flags'][rows] = int(flag)

    def segment(self, chosen, stop):
        """Replay (or resume) the segment over rows ``chosen``; the row out of bound, or None."""
        self.chosen, self.stop, self.done = chosen, stop, 0
        seg_speeds = self.speeds[chosen]
        if self.resume is None:
            # Measured speeds if every sample of the segment's first window has one.
            self.measured = not np.any(np.isnan(seg_speeds))
        measured = seg_speeds if self.measured else None
        self.clock_s = max(self.clock_s, self.stamps_ns[chosen[0]] * 1e-9)
        out = core_estimator.replay(self.model, self.stamps_ns[chosen], self.angles[chosen],
                                    measured, warm_start=self.warm_start, orbit=self.orbit,
                                    on_rows=self.on_rows, tables=self.tables,
                                    warm_start_limiter=self.limiter, resume=self.resume)
        self.orbit, self.resume = out['orbit'], out['resume']
        if out['stopped'] is None:
            return None
        row = int(chosen[out['stopped']])
        self.mark([row], _Flag.OUT_OF_BOUND)
        self.finish_until(row + 1)
        return row

    def on_rows(self, out, upto):
        """The rows of the current segment replay() has finished since the last call."""
        if upto <= self.done:
            return
        rows = slice(self.done, upto)
        model = self.model
        model_speed = np.clip(out['crank_speed'][rows], -model.speed_max, model.speed_max)
        model_accel = np.clip(out['crank_accel'][rows], -core_estimator.DEFAULT_ACCEL_LIMIT,
                              core_estimator.DEFAULT_ACCEL_LIMIT)
        blocks = {name: out[name][rows] for name in ('force', 'force_dot', 'rms2')}
        reaction, gamma_dot, criterion, _, self.available = criteria_batch(
            model, out['crank_angle'][rows], model_speed, model_accel, blocks=blocks)
        target = self.chosen[rows]
        for key, values in (('lever_tip', out['lever_tip'][rows]),
                            ('coupler_mid', out['coupler_mid'][rows]),
                            ('crank_angle', out['crank_angle'][rows]),
                            ('crank_speed', out['crank_speed'][rows]),
                            ('modal', out['modal'][rows]),
                            ('reaction_n', reaction),
                            ('gamma_dot', gamma_dot), ('criterion', criterion)):
            self.result[key][target] = values
        self.done = upto
        self.finish_until(self.stop if upto == self.chosen.size else int(self.chosen[upto]))

    def finish_until(self, final):
        """Copy the repeats before ``final`` (as StreamingEstimator.update) and report it."""
        result = self.result
        while self.copied < len(self.repeats) and self.repeats[self.copied][0] < final:
            row, source = self.repeats[self.copied]
            for key in _ESTIMATE_KEYS:
                result[key][row] = result[key][source]
            result['flags'][row] = int(_Flag.REPEATED)
            self.copied += 1
        self.final = max(self.final, final)
        if self.progress is not None:
            self.progress(self.final)


# -- the command -------------------------------------------------------------------------

def choose_input_topic(path, joint_name, topic=None, scan=None):
    """
    The JointState topic carrying the crank joint (``topic`` if given, checked).

    ``scan`` is :func:`scan_recording` of ``path`` if already done (the file is read once).
    """
    counts, kept = scan_recording(path) if scan is None else scan
    topics = {name: tuple(value) for name, value in counts.items()}
    if topic is not None:
        if topic not in topics:
            raise ValueError(f'`--topic` {topic} is not in the recording (topics: '
                             f'{", ".join(sorted(topics))})')
        if topics[topic][0] != JOINT_STATE:
            raise ValueError(f'`--topic` {topic} is {topics[topic][0]}, not {JOINT_STATE}')
        return topic
    candidates = []
    name_bytes = joint_name.encode()
    for name, (type_name, _) in sorted(topics.items()):
        if type_name != JOINT_STATE or not kept.get(name):
            continue
        # The joint may first appear after other messages (bounded probe, as scan_recording).
        if any(has_joint(data, name_bytes) for _, _, data in kept[name][:JOINT_PROBE_MESSAGES]):
            candidates.append(name)
    if not candidates:
        raise ValueError(f'no {JOINT_STATE} topic with joint {joint_name!r} in {path} '
                         f'(topics: {", ".join(sorted(topics)) or "none"})')
    if len(candidates) > 1:
        raise ValueError(f'several JointState topics carry {joint_name!r} '
                         f'({", ".join(candidates)}): choose one with --topic')
    return candidates[0]


def _joint_state_layout(data, joint_name):
    """
    Byte layout of a little-endian JointState CDR message, for reading many like it at once.

    Returns
    -------
    (fixed, position, velocity) or None
        ``fixed``: byte ranges that messages of the same layout share (encapsulation, frame
        id, joint names, array lengths); the rest is the stamp, the values and alignment
        padding, which serialisers need not zero (rclpy's does not). ``position`` /
        ``velocity``: offsets of the joint's values (velocity None if absent). None if the
        message is not little endian or lacks the joint.

    """
    if len(data) < 16 or data[:4] != b'\x00\x01\x00\x00':
        return None
    fixed = [(0, 4)]
    offset = 12
    (length,) = struct.unpack_from('<I', data, offset)
    fixed.append((offset, offset + 4 + length))                 # frame id
    offset = _cdr_align(offset + 4 + length, 4)
    (count,) = struct.unpack_from('<I', data, offset)
    fixed.append((offset, offset + 4))
    offset += 4
    index = None
    for k in range(count):
        offset = _cdr_align(offset, 4)
        (length,) = struct.unpack_from('<I', data, offset)
        fixed.append((offset, offset + 4 + length))             # joint name
        if index is None and data[offset + 4:offset + 4 + max(length - 1, 0)] == joint_name:
            index = k
        offset += 4 + length
    starts, sizes = [], []
    for _ in range(3):   # position, velocity, effort
        offset = _cdr_align(offset, 4)
        (size,) = struct.unpack_from('<I', data, offset)
        fixed.append((offset, offset + 4))
        offset += 4
        if size:
            offset = _cdr_align(offset, 8)
        starts.append(offset)
        sizes.append(size)
        offset += 8 * size
    # What follows the last array is padding to the serialiser's alignment (at most 8).
    if index is None or index >= sizes[0] or not 0 <= len(data) - offset < 8:
        return None
    velocity = starts[1] + 8 * index if index < sizes[1] else None
    return fixed, starts[0] + 8 * index, velocity


def _cdr_align(offset, size):
    return offset + (-(offset - 4)) % size


def _parse_crank_states(payloads, joint_name):
    """
    Stamp [ns], angle and speed (NaN if absent) of the joint in many JointState payloads.

    Messages with the first usable message's byte layout (the usual case: one publisher) are
    read together with numpy; the others one by one (:func:`cdr.parse_joint_state`).

    Returns
    -------
    stamps (int64), angles, speeds : ndarray, shape (m,)
    valid : ndarray of bool
        The joint has a position (else the values are meaningless).
    has_speed : ndarray of bool
        The message has a velocity for the joint.

    """
    count = len(payloads)
    stamps = np.zeros(count, dtype=np.int64)
    angles = np.full(count, math.nan)
    speeds = np.full(count, math.nan)
    valid = np.zeros(count, dtype=bool)
    has_speed = np.zeros(count, dtype=bool)
    fast = np.zeros(count, dtype=bool)
    layout = None
    for n, payload in enumerate(payloads[:16]):
        try:
            layout = _joint_state_layout(payload, joint_name)
        except (struct.error, IndexError, ValueError, OverflowError):
            layout = None     # not a JointState after all: read one by one below
        if layout is not None:
            reference = payloads[n]
            break
    if layout is not None:
        ranges, position, velocity = layout
        size = len(reference)
        same = np.fromiter((len(p) == size for p in payloads), dtype=bool, count=count)
        chosen = np.flatnonzero(same)
        rows = np.frombuffer(b''.join([payloads[n] for n in chosen]),
                             dtype=np.uint8).reshape(chosen.size, size)
        fixed = np.zeros(size, dtype=bool)
        for first, stop in ranges:
            fixed[first:stop] = True
        expected = np.frombuffer(reference, dtype=np.uint8)[fixed]
        match = np.all(rows[:, fixed] == expected, axis=1)
        chosen, rows = chosen[match], rows[match]
        fast[chosen] = True
        valid[chosen] = True
        sec = rows[:, 4:8].copy().view('<i4')[:, 0].astype(np.int64)
        nanosec = rows[:, 8:12].copy().view('<u4')[:, 0].astype(np.int64)
        stamps[chosen] = sec * 1_000_000_000 + nanosec
        angles[chosen] = rows[:, position:position + 8].copy().view('<f8')[:, 0]
        if velocity is not None:
            speeds[chosen] = rows[:, velocity:velocity + 8].copy().view('<f8')[:, 0]
            has_speed[chosen] = True
    for n in np.flatnonzero(~fast).tolist():
        try:
            stamp, angle, speed = parse_joint_state(payloads[n], joint_name)
        except (struct.error, IndexError, ValueError, OverflowError):
            continue
        if angle is None:
            continue
        valid[n] = True
        stamps[n], angles[n] = stamp, angle
        if speed is not None:
            speeds[n], has_speed[n] = speed, True
    return stamps, angles, speeds, valid, has_speed


def read_crank_samples(path, topic, joint_name, scan=None):
    """
    The crank samples of one topic.

    ``scan`` is :func:`scan_recording` of ``path`` if already done (the file is read once).

    Returns
    -------
    dict
        'data' (list of bytes), 'log_ns', 'publish_ns', 'stamps_ns' (int64), 'angles',
        'speeds' (NaN where missing) of the usable messages, and 'skipped' (count).

    """
    if scan is None:
        scan = scan_recording(path, topic=topic)
    messages = scan[1].get(topic, [])
    if not messages:
        empty = np.zeros(0, dtype=np.int64)
        return {'data': [], 'log_ns': empty, 'publish_ns': empty, 'stamps_ns': empty,
                'angles': np.zeros(0), 'speeds': np.zeros(0), 'skipped': 0,
                'skipped_reasons': {}}
    log_ns, publish_ns, payloads = zip(*messages)
    stamps, angles, speeds, valid, has_speed = _parse_crank_states(payloads,
                                                                   joint_name.encode())
    usable = valid & np.isfinite(angles) & (stamps != 0) & (np.isfinite(speeds) | ~has_speed)
    chosen = np.flatnonzero(usable)
    return {'data': [payloads[n] for n in chosen.tolist()],
            'log_ns': np.array(log_ns, dtype=np.int64)[chosen],
            'publish_ns': np.array(publish_ns, dtype=np.int64)[chosen],
            'stamps_ns': stamps[chosen], 'angles': angles[chosen], 'speeds': speeds[chosen],
            'skipped': len(payloads) - chosen.size,
            'skipped_reasons': _skip_reasons(payloads, valid, usable, joint_name.encode())}


def _skip_reasons(payloads, valid, usable, joint_name):
    # Why the unusable messages were skipped, counted: {one-line reason: count}.
    reasons = {}
    for n in np.flatnonzero(~usable).tolist():
        if valid[n]:
            reason = 'zero stamp or non-finite position or velocity'
        else:
            try:
                parse_joint_state(payloads[n], joint_name)
                reason = f'no position for joint {joint_name.decode()!r}'
            except (struct.error, IndexError, ValueError, OverflowError):
                reason = 'not a readable JointState (cut short or malformed)'
        reasons[reason] = reasons.get(reason, 0) + 1
    return reasons


def _damage_note(damaged):
    """' (N damaged places skipped; first: ...)' for an error message, or ''."""
    if not damaged:
        return ''
    file, offset, reason = damaged[0]
    where = '' if offset is None else f' at offset {offset}'
    return f' ({len(damaged)} damaged places skipped; first in {file}{where}: {reason})'


class _Progress:
    """A one-line progress bar on stderr (only on a terminal)."""

    def __init__(self, total, label, stream=sys.stderr):
        self.total, self.label, self.stream = max(total, 1), label, stream
        self.enabled = stream.isatty()
        self.last = 0.0

    def __call__(self, done, force=False):
        now = time.monotonic()
        if not self.enabled or (not force and now - self.last < PROGRESS_PERIOD_S):
            return
        self.last = now
        fraction = min(done / self.total, 1.0)
        bar = '#' * int(30 * fraction)
        self.stream.write(f'\r{self.label} [{bar:<30}] {100 * fraction:5.1f} %')
        if force:
            self.stream.write('\n')
        self.stream.flush()


# Samples per batch of write_replay (the progress bar moves between batches).
WRITE_BATCH = 1024


def write_replay(out_path, samples, estimate, input_topic, topics, frame_id, model,
                 markers_every_n=10, exaggeration=10.0, points_per_link=9, wait_for=None):
    """
    Write the input and the recomputed outputs into a rosbag2 MCAP.

    Per sample: the input, the two deflections and the criteria, and every
    ``markers_every_n``-th sample the markers, each logged at the input's log time (the
    order :meth:`McapRecorder.write` calls would give). The messages are encoded in bulk
    (cdr.py row encoders) and written in batches (:meth:`McapRecorder.write_batch`).

    ``wait_for(n)``, if given, returns once the first n samples of ``estimate`` are final
    (the estimate is then computed while this writes).

    Returns
    -------
    dict
        The recorder's final status.

    """
    from ..io.markers import criteria_rows, rows_to_bytes, vector3_stamped_rows
    recorder = McapRecorder(out_path)
    recorder.open()
    try:
        recorder.add_topic(input_topic, JOINT_STATE)
        recorder.add_topic(topics['lever_tip'], VECTOR3_STAMPED)
        recorder.add_topic(topics['coupler_mid'], VECTOR3_STAMPED)
        recorder.add_topic(topics['criteria'], JOINT_STATE)
        if markers_every_n:
            recorder.add_topic(topics['markers'], MARKER_ARRAY)
            marker_source = _MarkerSource(model, frame_id, exaggeration, points_per_link)
        frame = frame_id.encode()
        count = len(samples['data'])
        progress = _Progress(count, f'writing {out_path}')
        names = (input_topic, topics['lever_tip'], topics['coupler_mid'], topics['criteria'])
        for first in range(0, count, WRITE_BATCH):
            chosen = slice(first, min(first + WRITE_BATCH, count))
            if wait_for is not None:
                wait_for(chosen.stop)
            stamps = samples['stamps_ns'][chosen]
            log_ns = samples['log_ns'][chosen]
            columns = [samples['data'][chosen],
                       rows_to_bytes(vector3_stamped_rows(stamps, frame,
                                                          estimate['lever_tip'][chosen])),
                       rows_to_bytes(vector3_stamped_rows(stamps, frame,
                                                          estimate['coupler_mid'][chosen])),
                       rows_to_bytes(criteria_rows(stamps, frame,
                                                   estimate['criterion'][chosen],
                                                   estimate['gamma_dot'][chosen],
                                                   estimate['reaction_n'][chosen]))]
            # Outlier and out-of-bound samples (NaN) keep their input, with no outputs.
            valid = (np.all(np.isfinite(estimate['lever_tip'][chosen]), axis=1)
                     & np.all(np.isfinite(estimate['coupler_mid'][chosen]), axis=1))
            per_sample = np.where(valid, len(names), 1)
            if markers_every_n:
                marked = np.flatnonzero((np.arange(first, chosen.stop) % markers_every_n == 0)
                                        & valid)
                markers = iter(rows_to_bytes(marker_source.rows(
                    stamps[marked], estimate['crank_angle'][first + marked],
                    estimate['modal'][first + marked])))
                per_sample[marked] += 1
            messages, topic_of = [], []
            with_marker = (per_sample > len(names)).tolist()
            valid = valid.tolist()
            for n, row in enumerate(zip(*columns)):
                if not valid[n]:
                    messages.append(row[0])
                    topic_of.append(names[0])
                    continue
                messages += row
                topic_of += names
                if with_marker[n]:
                    messages.append(next(markers))
                    topic_of.append(topics['markers'])
            log_times = np.repeat(log_ns, per_sample)
            publish_times = log_times.copy()
            # The input keeps its publish time; the outputs are logged and sent at its log time.
            publish_times[np.cumsum(per_sample) - per_sample] = samples['publish_ns'][chosen]
            recorder.write_batch(topic_of, messages, log_times, publish_times)
            progress(chosen.stop)
        progress(count, force=True)
    finally:
        status = recorder.close()
    return status


class _MarkerSource:
    """MarkerArray bytes of the deformed linkage at replayed samples."""

    def __init__(self, model, frame_id, exaggeration, points_per_link):
        from ..io.markers import MarkerEncoder
        from ..ros.messages import OK
        self.model, self.exaggeration = model, exaggeration
        self.encoder = MarkerEncoder(frame_id, points_per_link)
        self.levels = [OK] * 4
        # Resampling the link points (linear interpolation along each link) is linear: apply
        # it to the shape table once.
        table = model.shape_table
        source = np.linspace(0.0, 1.0, table.shape[3])
        target = np.linspace(0.0, 1.0, points_per_link)
        resample = np.stack([np.interp(target, source, unit) for unit in np.eye(source.size)],
                            axis=1)
        self.table = np.einsum('ts,nclsdr->ncltdr', resample, table)

    def rows(self, stamps_ns, angles, modal):
        """
        Marker arrays at many samples.

        Parameters
        ----------
        stamps_ns : ndarray of int, shape (m,)
        angles : ndarray, shape (m,)
            Crank angles [rad].
        modal : ndarray, shape (m, r)
            Reduced coordinates.

        Returns
        -------
        ndarray of uint8, shape (m, length)
            One CDR message per row.

        """
        cells, t = self.model.cell(angles)
        powers = t[:, None] ** np.arange(self.table.shape[1])
        values = np.einsum('mp,mpltdr->mltdr', powers, self.table[cells])
        positions = values[..., -1]
        deflections = np.einsum('mltdr,mr->mltd', values[..., :-1], modal)
        joints = positions[:, (0, 0, 1, 2), (0, -1, -1, 0)]
        return self.encoder.encode_rows(stamps_ns, positions, deflections, self.exaggeration,
                                        joints, self.levels)


def publish_recording(samples, topic, speed=1.0, discovery_timeout_s=10.0):
    """
    Republish recorded JointState bytes with their recorded timing (log time deltas).

    Returns
    -------
    int
        Messages published.

    """
    import rclpy
    from rclpy.executors import ExternalShutdownException
    from sensor_msgs.msg import JointState

    published = 0
    try:
        with rclpy.init():
            node = rclpy.create_node('flexlink_replay')
            publisher = node.create_publisher(JointState, topic, 100)
            deadline = time.monotonic() + discovery_timeout_s
            while publisher.get_subscription_count() == 0 and time.monotonic() < deadline:
                time.sleep(0.05)
            log_ns = samples['log_ns']
            start_wall = time.monotonic()
            progress = _Progress(len(samples['data']), f'publishing {topic}')
            for n, payload in enumerate(samples['data']):
                due = start_wall + (log_ns[n] - log_ns[0]) * 1e-9 / speed
                delay = due - time.monotonic()
                if delay > 0:
                    time.sleep(delay)
                if not rclpy.ok():
                    break
                publisher.publish(payload)
                published += 1
                progress(n)
            progress(len(samples['data']), force=True)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    return published


def load_model_with_fallback(mechanism, options, args, warn):
    """The model of ``options``; without geometric stiffness if that cannot be built."""
    from ..ros.node import build_with_fallback
    return build_with_fallback(lambda o: load_model(mechanism, o, args), options, warn)


class _Background:
    """estimate_offline in a thread, with the number of final samples for a reader to follow."""

    def __init__(self, run_estimate, result):
        self.result = result
        self.seconds = None
        self._done = 0
        self._error = None
        self._condition = threading.Condition()
        self._thread = threading.Thread(target=self._run, args=(run_estimate,),
                                        name='replay-estimate', daemon=True)
        self._thread.start()

    def _run(self, run_estimate):
        start = time.perf_counter()
        try:
            run_estimate(result=self.result, progress=self._progress)
        except BaseException as exc:   # handed to the waiting thread
            with self._condition:
                self._error = exc
                self._condition.notify_all()
        self.seconds = time.perf_counter() - start

    def _progress(self, count):
        with self._condition:
            self._done = count
            self._condition.notify_all()

    def wait_for(self, count):
        """Return once the first ``count`` samples are final; raise the estimate's error."""
        with self._condition:
            while self._done < count and self._error is None:
                self._condition.wait(0.5)
            if self._error is not None:
                raise self._error

    def join(self):
        self._thread.join()
        if self._error is not None:
            raise self._error


def run_replay(args):
    """Read, estimate, write and/or publish; returns the JSON-ready summary."""
    notes = []
    start = time.perf_counter()
    damaged = []     # (file, offset, reason) of what the reader skipped
    scan = scan_recording(args.input, topic=args.topic, joint_name=args.joint,
                          damaged=damaged)
    try:
        topic = choose_input_topic(args.input, args.joint, args.topic, scan)
        samples = read_crank_samples(args.input, topic, args.joint, scan)
        if not samples['data']:
            raise ValueError(f'no usable samples of joint {args.joint!r} on {topic}'
                             + ''.join(f'; {n} {why}'
                                       for why, n in samples['skipped_reasons'].items()))
    except ValueError as exc:
        raise ValueError(f'{exc}{_damage_note(damaged)}') from None
    del scan
    read_s = time.perf_counter() - start
    mechanism = load_mechanism(args.mechanism)
    model, options = load_model_with_fallback(mechanism, model_options(args), args,
                                              notes.append)
    start = time.perf_counter()
    run_estimate = functools.partial(estimate_offline, model, samples['stamps_ns'],
                                     samples['angles'], samples['speeds'],
                                     warm_start=not args.no_warm_start)
    if args.out:
        # The outputs are written while the rest is computed: the compiled step runs without
        # the GIL, so the estimate and the writing share the two cores of a small machine.
        background = _Background(run_estimate, allocate_estimate(model, len(samples['data'])))
        estimate = background.result
    else:
        estimate = run_estimate()
        estimate_s = time.perf_counter() - start
    count = len(samples['data'])
    span_s = (samples['log_ns'][-1] - samples['log_ns'][0]) * 1e-9 if count > 1 else 0.0
    result = {'input': str(args.input), 'topic': topic, 'samples': count,
              'skipped': samples['skipped'], 'skipped_reasons': samples['skipped_reasons'],
              'damaged': [{'file': f, 'offset': o, 'reason': r} for f, o, r in damaged],
              'span_s': span_s, 'read_s': read_s,
              'model': {'size': model.size, 'grid_size': model.grid_size,
                        'options': str(options)}, 'notes': notes}
    if args.out:
        try:
            status = write_replay(args.out, samples, estimate, topic,
                                  output_topics(args.node_name), args.frame_id, model,
                                  args.markers_every_n, wait_for=background.wait_for)
        finally:
            background.join()
        estimate_s = background.seconds
        result['write_s'] = time.perf_counter() - start   # estimate and writing, overlapped
        result['output'] = status['path']
        result['output_files'] = status['files']
        result['output_topics'] = status['topics']
    result.update(estimate_s=estimate_s, segments=estimate['segments'],
                  outliers=estimate['outliers'], out_of_bound=estimate['out_of_bound'],
                  criteria_available=estimate['criteria_available'])
    total = read_s + result.get('write_s', estimate_s)
    result['samples_per_s'] = count / total if total > 0 else math.inf
    result['times_real_time'] = span_s / total if total > 0 else math.inf
    estimated = np.isfinite(estimate['lever_tip'][:, 0])     # not outlier, not out of bound
    for key in ('lever_tip', 'coupler_mid'):
        values = estimate[key][estimated]
        result[f'{key}_peak_to_peak_um'] = ((1e6 * (values.max(axis=0) - values.min(axis=0))
                                             ).tolist() if values.size else [math.nan] * 2)
    if args.publish:
        result['published'] = publish_recording(samples, topic, args.publish_speed)
    return result


def _replay_command(args):
    if not args.out and not args.publish:
        raise ValueError('give `--out` and/or `--publish`')
    if args.out:
        try:    # before the estimate, with the recorder's own test (links not followed)
            refuse_existing(pathlib.Path(args.out))
        except FileExistsError as exc:
            raise ValueError(f'`--out` {exc}') from None
    if not args.publish_speed > 0:
        raise ValueError(f'`--publish-speed` must be positive, got {args.publish_speed}')
    if args.markers_every_n < 0:
        raise ValueError(f'`--markers-every-n` must be >= 0, got {args.markers_every_n}')
    result = run_replay(args)
    lines = [f"{result['input']}: {result['samples']} samples on {result['topic']} "
             f"({result['skipped']} skipped, {result['outliers']} outlier(s), "
             f"{result['out_of_bound']} out of bound, {result['segments']} segment(s), "
             f"{result['span_s']:.2f} s recorded)"]
    lines += [f'  skipped {n} messages: {why}' for why, n in result['skipped_reasons'].items()]
    lines += [f"  skipped damaged data in {d['file']}"
              + ('' if d['offset'] is None else f" at offset {d['offset']}")
              + f": {d['reason']}" for d in result['damaged'][:10]]
    if len(result['damaged']) > 10:
        lines.append(f"  ... and {len(result['damaged']) - 10} more damaged places")
    lines += [f'  note: {note}' for note in result['notes']]
    lines.append(f"  lever tip peak-to-peak   dx {result['lever_tip_peak_to_peak_um'][0]:10.1f} "
                 f"um  dy {result['lever_tip_peak_to_peak_um'][1]:10.1f} um")
    lines.append(f"  coupler mid peak-to-peak dx "
                 f"{result['coupler_mid_peak_to_peak_um'][0]:10.1f} um  dy "
                 f"{result['coupler_mid_peak_to_peak_um'][1]:10.1f} um")
    if not result['criteria_available']:
        lines.append('  criteria unavailable: the model has no joint-reaction data '
                     '(written as zeros)')
    lines.append(f"  {result['samples_per_s']:.0f} samples/s, "
                 f"{result['times_real_time']:.0f}x real time")
    if 'output' in result:
        lines.append(f"  wrote {result['output']}")
    if 'published' in result:
        lines.append(f"  republished {result['published']} messages on {result['topic']}")
    return emit(result, '\n'.join(lines), args.json)


def register(subparsers):
    """Add the replay subcommand."""
    parser = subparsers.add_parser('replay', help='recompute deflections and criteria from '
                                   'the JointState of a recording into a new MCAP')
    parser.add_argument('input', help='rosbag2 MCAP file or bag directory')
    parser.add_argument('--out', help='output .mcap file or bag directory (must not exist)')
    parser.add_argument('--topic', help='input JointState topic (default: the one carrying '
                        'the joint)')
    parser.add_argument('--joint', default='crank', help='crank joint name (default: crank)')
    parser.add_argument('--node-name', default='flexlink_node',
                        help='namespace of the output topics (default: flexlink_node)')
    parser.add_argument('--frame-id', default='linkage_ground', help='frame of the outputs')
    parser.add_argument('--markers-every-n', type=int, default=10,
                        help='markers on every n-th sample (0: none; default 10, as the node)')
    parser.add_argument('--no-warm-start', action='store_true',
                        help='start from the static deflection, not the periodic state')
    parser.add_argument('--publish', action='store_true',
                        help='republish the input with its recorded timing')
    parser.add_argument('--publish-speed', type=float, default=1.0,
                        help='time scale of --publish (2 = twice as fast)')
    _common(parser)
    parser.set_defaults(func=_replay_command)
