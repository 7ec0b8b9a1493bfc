"""
`flexlink replay`: recompute deflections and joint criteria offline from a recording.

Reads the crank ``sensor_msgs/JointState`` messages of any rosbag2 MCAP (a bare ``.mcap`` file,
a bag directory, or a truncated or damaged file: every intact chunk is used, damaged ones are
skipped and listed, :mod:`io.recording`), runs the estimator over them a chunk at a time
(:mod:`cli.replay_offline`: memory does not grow with the recording; the same numbers as the
streaming node, however the chunks fall), and writes a new MCAP with the input and the node's
output topics (deflections, criteria, the per-sample quality ``~/quality`` and markers, the
bytes the node records), each output stamped with its input's stamp and logged at the input's
log time (:mod:`io.replay_writer`). ``--publish``
republishes the input with its recorded timing for live subscribers (a running
flexlink_node, Foxglove, RViz; :mod:`ros.republish`), with the flags of ``ros2 bag play``:
``--rate R``, ``--clock [HZ]`` and ``--clock-topics-all`` (``/clock`` from the recording's
time), ``--loop`` (``--loop-count N`` bounds it), and ROS arguments after ``--ros-args``
(remappings, ``__ns``).

The model is the one the recording says made it (mechanism file, damping ratio, model options,
crank joint, warm start: :mod:`.replay_model`); a flag that differs is used and said in a note,
and a recording that names no model needs ``--mechanism``. ``--out`` records the replay's own.

Like the node, a sample whose stamp goes back or jumps by more than the estimator's reset gap
starts a new segment (the state restarts), an exactly repeated sample repeats the previous
output, and messages without the crank joint, with a non-finite value or that are not a
readable JointState are skipped and counted by reason. Samples the estimator's input gate
refuses (an implausible speed, speed jump or angle advance) are counted as outliers, and an
estimate beyond the model's deflection bound as out of bound: both keep their input in the
output file but get no output messages, and after an out-of-bound sample the estimate
restarts, as in the node.
"""

import functools
import math
import pathlib
import shutil
import sys
import time

import numpy as np

from .main import emit
from .model_args import add_chart_argument, add_estimator_arguments, criterion_thresholds, \
    load_model
from .progress import Progress
from .replay_model import defer_model_defaults, MissingModel, replay_model
from .replay_nonlinear import decide, MAX_THREADS, model_lines, nonlinear_choice, nonlinear_rows
from .replay_offline import CHUNK_SAMPLES, estimate_and_write, MAX_CHUNK_SAMPLES, open_input
from .replay_split import can_fork, Splitter, warm_up_seconds
from ..core.estimation.gate import DEFAULT_RESET_GAP_S
from ..core.estimation.marker_scale import load_quasi_static_peaks, model_exaggeration
from ..core.estimation.nonlinear_follow import CHOICES as NONLINEAR_CHOICES
from ..core.estimation.tables import step_tables
from ..io.joint_states import read_input_samples
from ..io.output_cdr import OK
from ..io.recorder_files import refuse_existing
from ..io.replay_writer import replay_topics, write_replay, write_rows
from ..names import DEFAULT_FRAME_ID, NODE_NAME, output_topics, QUALITY_NAMES
from ..report.cycle_chart import plot_cycle
from ..ros.playback_schedule import DEFAULT_CLOCK_HZ, MAX_CLOCK_HZ
from ..ros.republish import DISCOVERY_TIMEOUT_S, publish_recording

CHART_ROWS = 200_000   # the chart shows the last 200 s at 1 kHz: enough revolutions to read


def _writer(args, model, topic, exaggeration):
    """``write(blocks, progress)`` of the output file (:func:`write_replay`), or None."""
    if not args.out:
        return None
    return functools.partial(_write_blocks, args.out, topic=topic, model=model, args=args,
                             exaggeration=exaggeration)


def _write_blocks(out, blocks, progress, topic, model, args, exaggeration, tail=None):
    return write_replay(out, blocks, topic, output_topics(args.node_name), args.frame_id, model,
                        args.markers_every_n, exaggeration, progress=progress,
                        joint_levels=[OK] * 4, provenance=args.provenance, tail=tail)


def _splitter(args, made, topic, exaggeration):
    """Return the replay's :class:`.replay_split.Splitter` (None: one process)."""
    mechanism, options, model, tables = made
    if not args.out or getattr(args, 'processes', 1) < 2:
        return None
    declared = replay_topics(topic, output_topics(args.node_name), args.markers_every_n)
    rows_writer = functools.partial(write_rows, declared=declared, frame_id=args.frame_id,
                                    model=model, markers_every_n=args.markers_every_n,
                                    exaggeration=exaggeration, joint_levels=[OK] * 4)
    return Splitter(args, model, tables, (declared, rows_writer),
                    warm_up_seconds(model, tables, mechanism, options, args))


class ChartRows:
    """The last ``CHART_ROWS`` estimated rows, kept for ``--chart`` (bounded memory)."""

    def __init__(self):
        self.parts, self.count = [], 0

    def clear(self):
        """Forget the kept rows (the estimate runs again)."""
        self.parts, self.count = [], 0

    def add(self, estimate):
        """Keep a block's crank angle, deflections and criteria."""
        self.parts.append({key: np.array(estimate[key][-CHART_ROWS:]) for key in
                           ('crank_angle', 'lever_tip', 'coupler_mid', 'criterion')})
        self.count += len(self.parts[-1]['crank_angle'])
        while self.count - len(self.parts[0]['crank_angle']) >= CHART_ROWS:
            self.count -= len(self.parts.pop(0)['crank_angle'])

    def draw(self, path, criteria_available, title, thresholds):
        """Draw the kept rows over crank angle (:func:`plot_cycle`); the PNG's path."""
        rows = {key: np.concatenate([part[key] for part in self.parts])[-CHART_ROWS:]
                for key in self.parts[0]} if self.parts else None
        if rows is None:
            raise ValueError('no estimated rows to chart')
        return str(plot_cycle(path, rows['crank_angle'], rows['lever_tip'],
                              rows['coupler_mid'],
                              rows['criterion'] if criteria_available else None,
                              title=title, thresholds=thresholds))


def run_replay(args):
    """
    Read, estimate, write and/or publish.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed flags of ``flexlink replay``.

    Returns
    -------
    dict
        The JSON-ready summary.

    """
    mechanism, options, notes, args.provenance = replay_model(args)
    start = time.perf_counter()
    damaged = []     # (file, offset, reason) of what the reader skipped
    topic, rows, messages = open_input(args, damaged)
    read_s = time.perf_counter() - start
    model = load_model(mechanism, options, args)
    chart = ChartRows() if args.chart else None
    tables = step_tables(model)
    load_quasi_static_peaks(model, tables, mechanism, options, args.cache_dir, not args.no_cache)
    choice, transform, (topic, rows, messages), outcome = _choose_model(
        args, (mechanism, options, model, tables), (topic, rows, messages), chart, damaged)
    if outcome is None:
        outcome = _estimate(args, (mechanism, options, model, tables), (topic, rows, messages),
                            chart, transform)
    estimate, summary, times = outcome
    count, span_s = rows.samples, rows.span_s()
    result = {'input': str(args.input), 'topic': topic, 'samples': count,
              'skipped': rows.skipped, 'skipped_reasons': rows.skipped_reasons,
              'damaged': [{'file': f, 'offset': o, 'reason': r} for f, o, r in damaged],
              'span_s': span_s, 'read_s': read_s,
              'model': {'size': model.size, 'step_size': model.step_size,
                        'soft_basis': model.info.get('soft'), 'grid_size': model.grid_size,
                        'options': str(options)}, 'order': model.order,
              'second_order': options.second_order if model.order == 2 else None,
              'notes': notes}
    if args.out:
        result['write_s'] = times['write_s']
        result['output'] = times['status']['path']
        result['output_files'] = times['status']['files']
        result['output_topics'] = times['status']['topics']
    result.update(estimate_s=times['estimate_s'], processes=times['processes'],
                  segments=estimate['segments'],
                  outliers=estimate['outliers'], out_of_bound=estimate['out_of_bound'],
                  criteria_available=estimate['criteria_available'])
    total = read_s + times['write_s']
    result['samples_per_s'] = count / total if total > 0 else math.inf
    result['times_real_time'] = span_s / total if total > 0 else math.inf
    result.update(summary)
    result['model_choice'] = choice
    result['nonlinear'] = None if transform is None else transform.summary()
    if chart:
        result['chart'] = chart.draw(args.chart, estimate['criteria_available'],
                                     f'{mechanism.name}: {pathlib.Path(args.input).name} '
                                     f'({count} samples, order {model.order}, flexlink replay)',
                                     criterion_thresholds(mechanism))
    if args.publish:
        _, samples, _ = read_input_samples(args.input, args.topic, args.joint, [])
        with Progress(f'publishing {topic}', count, unit='msg') as progress:
            played = publish_recording(samples, topic, playback_options(args),
                                       progress=progress)
        result.update(published=played['published'], playback=played)
        result['notes'] += played['notes']
    return result


def _estimate(args, made, opened, chart, transform=None):
    """Estimate (and write) the input ``opened`` with the model ``made``."""
    mechanism, _, model, tables = made
    topic, rows, messages = opened
    # On the estimator's step tables: the quasi-static peaks of the deflection bound and of
    # the markers (up to the recorded machine's speed) are computed on them once each.
    exaggeration = (model_exaggeration(model, tables, mechanism)
                    if args.out and args.markers_every_n else 1.0)
    splitter = (None if transform is not None or chart
                else _splitter(args, made, topic, exaggeration))
    return estimate_and_write(args, model, rows, messages,
                              _writer(args, model, topic, exaggeration),
                              on_block=chart and chart.add, tables=tables,
                              transform=transform, splitter=splitter)


def _choose_model(args, made, opened, chart, damaged):
    """
    Choose the linear or the nonlinear model (:mod:`.replay_nonlinear`).

    Returns the JSON's ``model_choice``, the :class:`.replay_nonlinear.NonlinearRows` (None:
    linear), the input to estimate from and, where the choice took a linear pass that stays
    the result, its :func:`estimate_and_write` outcome (else None). For ``auto`` with an output
    file, the linear pass writes it, kept where the linear estimate is valid: the recording
    is read once. Else (or where it is not valid) the input is opened again. The output's
    provenance records the choice.
    """
    mechanism, options, model, tables = made
    asked = nonlinear_choice(args, getattr(args, 'recorded_provenance', None))
    recorded = not getattr(args, 'nonlinear', None)
    linear_summary = outcome = None
    if asked == 'auto':     # the linear estimate first: is it valid?
        if args.out:
            _record_choice(args, False)
            outcome = _estimate(args, made, opened, chart)
            linear_summary = outcome[1]
        else:
            _, linear_summary, _ = estimate_and_write(args, model, opened[1], opened[2], None,
                                                      tables=tables)
    use, why = decide(asked, linear_summary, recorded=recorded)
    if asked == 'auto' and (use or not args.out):
        if outcome is not None:
            remove_output(args.out)
            outcome = None
            if chart:
                chart.clear()
        del damaged[:]
        opened = open_input(args, damaged)
    transform = nonlinear_rows(args, mechanism, options, DEFAULT_RESET_GAP_S) if use else None
    _record_choice(args, use)
    return {'nonlinear': use, 'why': why, 'asked': asked}, transform, opened, outcome


def _record_choice(args, use):
    if args.provenance.get('model_options'):
        args.provenance['nonlinear'] = 'on' if use else 'off'


def remove_output(out):
    """Remove the output this replay wrote (a file or a bag directory), to write it again."""
    path = pathlib.Path(out)
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path)
    else:
        path.unlink()


def playback_options(args):
    """Return :func:`ros.republish.publish_recording`'s options from the parsed flags."""
    passes = args.loop_count if args.loop_count is not None else (0 if args.loop else 1)
    return {'rate': args.rate, 'clock_hz': args.clock or 0.0, 'passes': passes,
            'clock_per_message': args.clock_topics_all,
            'subscribers': args.wait_for_subscribers, 'discovery_timeout_s': args.wait_timeout,
            'ros_args': list(getattr(args, 'ros_args', None) or [])}


def _check_arguments(args):
    """Refuse bad flags before any reading (``--out`` with the recorder's own test)."""
    if not args.out and not args.publish and not args.chart:
        raise ValueError('give `--out`, `--publish` and/or `--chart`')
    playback_flags = [flag for flag, given in (
        ('--clock', args.clock is not None), ('--clock-topics-all', args.clock_topics_all),
        ('--loop', args.loop), ('--loop-count', args.loop_count is not None),
        ('--ros-args', bool(getattr(args, 'ros_args', None)))) if given]
    if playback_flags and not args.publish:
        raise ValueError(f"{', '.join(f'`{f}`' for f in playback_flags)} need `--publish`")
    if args.loop_count is not None and args.loop_count < 1:
        raise ValueError(f'`--loop-count` must be >= 1, got {args.loop_count}')
    if args.out:
        try:    # before the estimate, with the recorder's own test (links not followed)
            refuse_existing(pathlib.Path(args.out))
        except FileExistsError as exc:
            raise ValueError(f'`--out` {exc}') from None
    if not args.rate > 0:
        raise ValueError(f'`--rate` must be positive, got {args.rate}')
    if args.clock is not None and not 0 < args.clock <= MAX_CLOCK_HZ:
        raise ValueError(f'`--clock` must be a positive frequency [Hz] up to '
                         f'{MAX_CLOCK_HZ:g}, got {args.clock}')
    if args.wait_for_subscribers < 0 or not args.wait_timeout >= 0:
        raise ValueError('`--wait-for-subscribers` and `--wait-timeout` must be >= 0')
    if args.markers_every_n < 0:
        raise ValueError(f'`--markers-every-n` must be >= 0, got {args.markers_every_n}')
    if not 1 <= args.threads <= MAX_THREADS:
        raise ValueError(f'`--threads` must be in 1..{MAX_THREADS}, got {args.threads}')
    if args.processes not in (1, 2):
        raise ValueError(f'`--processes` must be 1 or 2, got {args.processes}')
    if args.processes == 2 and not can_fork():
        raise ValueError('`--processes 2` needs a system that can fork and 2 or more cores')
    if not 1 <= args.chunk_samples <= MAX_CHUNK_SAMPLES:
        raise ValueError(f'`--chunk-samples` must be in 1..{MAX_CHUNK_SAMPLES}, '
                         f'got {args.chunk_samples}')


def summary_text(result):
    """
    Summarise a replay for people.

    Parameters
    ----------
    result : dict
        :func:`run_replay`'s result.

    Returns
    -------
    str

    """
    lines = [f"{result['input']}: {result['samples']} samples on {result['topic']} "
             f"({result['skipped']} skipped, {result['outliers']} outlier(s), "
             f"{result['out_of_bound']} out of bound, {result['segments']} segment(s), "
             f"{result['span_s']:.2f} s recorded; order {result['order']}"
             + (', dynamic pass' if result.get('second_order') == 'dynamic' else '') + ')']
    lines += [f'  skipped {n} messages: {why}' for why, n in result['skipped_reasons'].items()]
    lines += [f"  skipped damaged data in {d['file']}"
              + ('' if d['offset'] is None else f" at offset {d['offset']}")
              + f": {d['reason']}" for d in result['damaged'][:10]]
    if len(result['damaged']) > 10:
        lines.append(f"  ... and {len(result['damaged']) - 10} more damaged places")
    lines += [f'  note: {note}' for note in result['notes']]
    lines.append(f"  lever tip peak-to-peak   dx {result['lever_tip_peak_to_peak_um'][0]:10.1f} "
                 f"um  dy {result['lever_tip_peak_to_peak_um'][1]:10.1f} um")
    lines.append('  coupler mid peak-to-peak dx '
                 f"{result['coupler_mid_peak_to_peak_um'][0]:10.1f} um  dy "
                 f"{result['coupler_mid_peak_to_peak_um'][1]:10.1f} um")
    lines.append(quality_text(result['quality']))
    lines += model_lines(result)
    if not result['criteria_available']:
        lines.append('  criteria unavailable: the model has no joint-reaction data '
                     '(written as zeros)')
    lines.append(f"  {result['samples_per_s']:.0f} samples/s, "
                 f"{result['times_real_time']:.0f}x real time")
    if 'output' in result:
        lines.append(f"  wrote {result['output']}")
    if 'chart' in result:
        lines.append(f"  chart {result['chart']}")
    if 'playback' in result:
        lines.append(playback_text(result['playback']))
    return '\n'.join(lines)


def quality_text(quality):
    """Summarise the per-sample quality messages in one line."""
    largest = ', '.join(f"{name.replace('_', ' ')} max "
                        + ('n/a' if quality[f'{name}_max'] is None
                           else f"{quality[f'{name}_max']:.3g}") for name in QUALITY_NAMES)
    return f"  quality: {quality['messages']} messages ({largest})"


def playback_text(played):
    """Summarise a ``--publish`` playback in one line."""
    text = (f"  republished {played['published']} messages on {played['topic']} "
            f"({played['passes']} pass(es), {played['publish_s']:.2f} s")
    if played['clock_messages']:
        text += f", {played['clock_messages']} /clock messages"
    text += ', interrupted)' if played['interrupted'] else ')'
    if played['failed']:
        text += (f"\n  {played['failed']} publishes failed (a reliable subscriber that cannot "
                 f"keep up?): {played['last_failure']}")
    return text


def _replay_command(args):
    _check_arguments(args)
    try:
        result = run_replay(args)
    except MissingModel as exc:
        print(f'flexlink replay: error: {exc}', file=sys.stderr)
        return 2
    code = emit(result, summary_text(result), args.json)
    return 1 if result.get('playback', {}).get('failed') else code


def _add_work_arguments(parser):
    """Add the flags of how the work is cut: chunks, threads, processes."""
    parser.add_argument('--chunk-samples', type=int, default=CHUNK_SAMPLES, metavar='N',
                        help='input messages read and estimated at a time: memory grows with '
                        f'it, not with the recording (default {CHUNK_SAMPLES})')
    parser.add_argument('--threads', type=int, default=1, metavar='N',
                        help='with the nonlinear model, follow a long recording in N spans at '
                        'once, each from a warm-up (the same deflections to rounding; memory '
                        f'grows with N, about 32 MB each; 1..{MAX_THREADS}, default 1)')
    parser.add_argument('--processes', type=int, default=1, metavar='N',
                        help='2: with the linear model and --out, estimate and write the '
                        'second part of a recording in a second process, from a warm-up '
                        'before it (the same messages; values to rounding: the deflections '
                        'within 5e-12 of their range; about 1.1x faster on an idle 2-core '
                        'machine, slower on a busy one); a recording shorter than about two '
                        'warm-ups (10 s each for the default model) runs in one process '
                        '(default 1: the bytes of one process on any machine)')


def register(subparsers):
    """Add the replay subcommand."""
    parser = subparsers.add_parser(
        'replay', help='recompute deflections and criteria from the JointState of a '
        'recording into a new MCAP', epilog='With --publish, everything after --ros-args '
        '(up to a lone --) goes to the replay node as ROS arguments, e.g. --ros-args '
        '-r joint_states:=/robot1/joint_states or -r __ns:=/robot1.')
    parser.add_argument('input', help='rosbag2 MCAP file or bag directory')
    parser.add_argument('--out', help='output .mcap file or bag directory (must not exist)')
    parser.add_argument('--topic', help='input JointState topic (default: the one carrying '
                        'the joint)')
    parser.add_argument('--joint', default='crank', help='crank joint name (default: the '
                        "recording's, else crank)")
    parser.add_argument('--node-name', default=NODE_NAME,
                        help=f'namespace of the output topics (default: {NODE_NAME})')
    parser.add_argument('--frame-id', default=DEFAULT_FRAME_ID, help='frame of the outputs')
    parser.add_argument('--markers-every-n', type=int, default=10,
                        help='markers on every n-th sample (0: none; default 10, as the node)')
    _add_work_arguments(parser)
    parser.add_argument('--no-warm-start', action='store_true',
                        help='start from the static deflection, not the periodic state')
    parser.add_argument('--publish', action='store_true',
                        help='republish the input with its recorded timing')
    parser.add_argument('--rate', '--publish-speed', type=float, default=1.0, dest='rate',
                        help='playback speed factor of --publish, > 0 (2: twice as fast; '
                        '--publish-speed is the older name)')
    parser.add_argument('--clock', type=float, nargs='?', const=DEFAULT_CLOCK_HZ,
                        metavar='HZ', help='with --publish, publish /clock from the '
                        f"recording's time at HZ of wall time (default {DEFAULT_CLOCK_HZ:g}, "
                        'as ros2 bag play --clock)')
    parser.add_argument('--clock-topics-all', action='store_true',
                        help='with --publish, publish /clock just before every message')
    parser.add_argument('--loop', action='store_true',
                        help='with --publish, play again from the start until interrupted')
    parser.add_argument('--loop-count', type=int, metavar='N',
                        help='with --publish, play N times in all, then stop')
    parser.add_argument('--wait-for-subscribers', type=int, default=1, metavar='N',
                        help='with --publish, start once N subscriptions matched the topic '
                        '(default 1), or after --wait-timeout')
    parser.add_argument('--wait-timeout', type=float, default=DISCOVERY_TIMEOUT_S,
                        metavar='S', help='with --publish, longest wait for the subscriptions '
                        f'[s] (default {DISCOVERY_TIMEOUT_S:g})')
    parser.add_argument('--nonlinear', choices=NONLINEAR_CHOICES, default=None,
                        help='deflections of the reduced geometrically nonlinear model in the '
                        'output: auto (the default unless the recording names its model: where '
                        "the linear estimate's validity indicator says it is not valid), on or "
                        'off')
    add_estimator_arguments(parser)
    add_chart_argument(parser)
    defer_model_defaults(parser)   # the recording's model unless a flag is given
    parser.set_defaults(func=_replay_command, takes_ros_args=True)
