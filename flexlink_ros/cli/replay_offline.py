"""
The offline path of `flexlink replay`: a recording read, estimated and written in chunks.

The input topic is chosen from a survey of the recording (:mod:`io.recording_stream`: topic
counts and the first messages of each JointState topic; from the files' summaries and first
chunks where they have them, so the recording is read once), then its samples are read
``--chunk-samples`` messages at a time in one thread (:class:`ReadAhead`), estimated in
another (:func:`core.estimation.offline.estimate_stream`; the compiled step runs without the
GIL) while this thread encodes and writes the rows already final (:mod:`io.replay_writer`),
so the reading, the estimate and the writing share the two cores of a small machine. What is
held at once does not depend on the recording's length: a chunk of input messages and one
decompressed MCAP chunk, the estimate's window (a chunk, the plan's look-ahead and the rows
not yet handed on), at most two chunks read ahead and at most ``QUEUED_BLOCKS`` + 2 blocks of
``BLOCK_ROWS`` rows on their way to the writer.
"""

import collections
import math
import queue
import threading
import time

import numpy as np

from .progress import Progress
from ..core.estimation.offline import estimate_stream
from ..io.joint_states import iter_crank_samples
from ..io.recording import choose_input_topic, damage_note
from ..io.recording_stream import survey_recording, survey_summaries
from ..io.replay_writer import WRITE_BATCH
from ..names import OUTPUT_POINTS, QUALITY_NAMES

# Rows handed from the estimate to the writer at a time, and blocks waiting for the writer
# (the estimate waits when it is that far ahead). The last block is written after the estimate
# ends: a small one shortens that tail.
BLOCK_ROWS = 2 * WRITE_BATCH
QUEUED_BLOCKS = 8
# Input messages read at a time (the --chunk-samples default): the first chunk is read before
# the estimate starts, the others beside the estimate.
CHUNK_SAMPLES = 8 * WRITE_BATCH
# ... and the most the flag accepts (a bound on what one chunk may hold).
MAX_CHUNK_SAMPLES = 1 << 22
_COLUMNS = ('data', 'log_ns', 'publish_ns', 'stamps_ns', 'angles', 'speeds')


class ReadAhead:
    """
    The items of an iterator made in a thread of their own, at most ``depth`` ahead.

    The input's chunks are read (decompressed, walked, parsed) beside the estimate, which then
    only takes them. Its errors are raised where the items are taken; :meth:`close` stops it.
    With ``begin`` (an Event), nothing is read before it is set: the estimate's start (the
    warm start, numpy calls that each give the GIL up and wait to get it back) runs alone.
    """

    def __init__(self, items, depth=2, begin=None):
        self.items, self.ready = items, queue.Queue(depth)
        self.stop, self.ended = threading.Event(), False
        self.begin = begin
        self.thread = threading.Thread(target=self._run, name='replay-read', daemon=True)
        self.thread.start()

    def __iter__(self):
        return self

    def __next__(self):
        if self.ended:
            raise StopIteration
        kind, value = self.ready.get()
        if kind == 'item':
            return value
        self.ended = True
        if kind == 'error':
            raise value
        raise StopIteration

    def _run(self):
        try:
            if self.begin is not None:
                while not self.begin.wait(0.1):
                    if self.stop.is_set():
                        raise _Stopped()
            last = ('end', None)
            try:
                for item in self.items:
                    _put(self.ready, ('item', item), self.stop)
            except _Stopped:
                raise
            except BaseException as exc:   # raised where the items are taken
                last = ('error', exc)
            _put(self.ready, last, self.stop)
        except _Stopped:
            pass

    def close(self):
        """Stop reading ahead (the estimate ended or failed) and wait for the thread."""
        self.stop.set()
        self.thread.join()


class InputRows:
    """
    The crank samples of the input topic, read a chunk at a time, and counted.

    Parameters
    ----------
    path : str or os.PathLike
        The recording.
    topic, joint_name : str
        The input topic and the crank joint.
    chunk : int
        Messages read at a time.
    damaged : list, optional
        Receives (file, offset, reason) of what the reading skips (when no survey listed it).

    """

    def __init__(self, path, topic, joint_name, chunk, damaged=None, start=0):
        self.topic, self.joint_name = topic, joint_name
        self.chunks = iter_crank_samples(path, topic, joint_name, block=chunk, damaged=damaged)
        # Usable rows start...stop (stop None: to the end) are given to the estimate.
        self.start, self.stop, self.seen = start, None, 0
        self.damaged = damaged
        self.damage_mark = None if damaged is None else len(damaged)   # the survey's
        self.samples = self.skipped = 0
        self.skipped_reasons = {}
        self.first_log_ns = self.last_log_ns = None
        self.peeked = collections.deque()
        self.pending = collections.deque()      # read, given to the estimate, not yet written
        self.estimate_started = threading.Event()

    def _next(self):
        """Return the next chunk with a usable sample (counting the rest), or None."""
        while self.stop is None or self.seen < self.stop:
            chunk = next(self.chunks, None)
            if chunk is None:
                return None
            self.skipped += chunk['skipped']
            for why, count in chunk['skipped_reasons'].items():
                self.skipped_reasons[why] = self.skipped_reasons.get(why, 0) + count
            chunk = self._in_range(chunk)
            if chunk['data']:
                self.samples += len(chunk['data'])
                if self.first_log_ns is None:
                    self.first_log_ns = int(chunk['log_ns'][0])
                self.last_log_ns = int(chunk['log_ns'][-1])
                return chunk
        return None

    def _in_range(self, chunk):
        """Return the chunk's usable rows within start...stop."""
        first, self.seen = self.seen, self.seen + len(chunk['data'])
        low = max(self.start - first, 0)
        high = len(chunk['data']) if self.stop is None else max(min(self.stop - first, len(
            chunk['data'])), low)
        if low == 0 and high == len(chunk['data']):
            return chunk
        return {**chunk, **{key: chunk[key][low:high] for key in _COLUMNS}}

    def limit(self, stop):
        """Give the estimate rows before ``stop`` only (the rest is another part's)."""
        self.stop = stop
        kept = collections.deque()
        first = 0
        for chunk in self.peeked:
            size = len(chunk['data'])
            if first < stop:
                kept.append({key: chunk[key][:stop - first] for key in _COLUMNS}
                            if first + size > stop else chunk)
            first += size
        self.samples = min(self.samples, stop)
        self.peeked = kept

    def find_first(self):
        """Read up to the first usable sample; ValueError naming why there is none."""
        chunk = self._next()
        if chunk is None:
            raise ValueError(f'no usable samples of joint {self.joint_name!r} on {self.topic}'
                             + ''.join(f'; {n} {why}'
                                       for why, n in self.skipped_reasons.items()))
        self.peeked.append(chunk)

    def estimate_input(self):
        """
        Yield (stamps, angles, speeds) of each chunk, keeping its rows for :meth:`take`.

        The chunks after those already read are read ahead in a thread (:class:`ReadAhead`),
        started here: in the estimate's thread, after any fork (:mod:`.replay_split`).
        """
        if not isinstance(self.chunks, ReadAhead):
            self.chunks = ReadAhead(self.chunks, begin=self.estimate_started)
        while True:
            if not self.peeked:
                self.estimate_started.set()     # it needs what is read ahead
            chunk = self.peeked.popleft() if self.peeked else self._next()
            if chunk is None:
                return
            self.pending.append(chunk)
            yield chunk['stamps_ns'], chunk['angles'], chunk['speeds']

    def take(self, count):
        """Remove and return the next ``count`` rows given to the estimate, as one dict."""
        parts = []
        while count:
            chunk = self.pending[0]
            size = len(chunk['data'])
            if size <= count:
                parts.append(self.pending.popleft())
                count -= size
                continue
            parts.append({key: chunk[key][:count] for key in _COLUMNS})
            self.pending[0] = {key: chunk[key][count:] for key in _COLUMNS}
            count = 0
        if len(parts) == 1:
            return parts[0]
        rows = {key: np.concatenate([part[key] for part in parts]) for key in _COLUMNS[1:]}
        rows['data'] = [data for part in parts for data in part['data']]
        return rows

    def close(self):
        """Stop the reading ahead, if started."""
        if isinstance(self.chunks, ReadAhead):
            self.chunks.close()

    def span_s(self):
        """Log time from the first to the last usable sample [s]."""
        return ((self.last_log_ns - self.first_log_ns) * 1e-9 if self.samples > 1 else 0.0)


def open_input(args, damaged):
    """
    Choose the input topic from a survey of the recording and find its first usable sample.

    Parameters
    ----------
    args : argparse.Namespace
        ``input``, ``topic``, ``joint``, ``chunk_samples``.
    damaged : list
        Receives (file, offset, reason) of what the reader skipped.

    Returns
    -------
    (str, InputRows, int)
        The topic, its samples (the first read) and its message count.

    """
    # The summaries name the topics without a pass over the chunks; the reading then lists
    # what is damaged. Without summaries, or when they name no usable topic, a whole survey.
    surveyed = survey_summaries(args.input, topic=args.topic)
    if surveyed is not None:
        try:
            topic = choose_input_topic(args.input, args.joint, args.topic, surveyed)
        except ValueError:
            surveyed = None
    read_damage = damaged if surveyed else None
    try:
        if surveyed is None:
            surveyed = survey_recording(args.input, topic=args.topic, damaged=damaged)
            topic = choose_input_topic(args.input, args.joint, args.topic, surveyed)
        rows = InputRows(args.input, topic, args.joint, args.chunk_samples, read_damage)
        rows.find_first()
    except ValueError as exc:
        raise ValueError(f'{exc}{damage_note(damaged)}') from None
    return topic, rows, surveyed[0][topic][1]


class EstimateSummary:
    """The peak-to-peak deflections and the quality of the estimated rows, block by block."""

    def __init__(self):
        self.low = {key: np.full(2, math.inf) for key in OUTPUT_POINTS}
        self.high = {key: np.full(2, -math.inf) for key in OUTPUT_POINTS}
        self.seen = dict.fromkeys(OUTPUT_POINTS, False)
        self.messages = 0
        self.largest = dict.fromkeys(QUALITY_NAMES)

    def add(self, estimate):
        """Take a block of estimated rows (NaN: outlier or out of bound)."""
        estimated = np.isfinite(estimate['lever_tip'][:, 0])
        for key in OUTPUT_POINTS:
            values = estimate[key][estimated]
            if values.size:
                self.seen[key] = True
                self.low[key] = np.minimum(self.low[key], values.min(axis=0))
                self.high[key] = np.maximum(self.high[key], values.max(axis=0))
        published = (np.all(np.isfinite(estimate['lever_tip']), axis=1)
                     & np.all(np.isfinite(estimate['coupler_mid']), axis=1))
        self.messages += int(np.count_nonzero(published))
        for key in QUALITY_NAMES:
            values = estimate[key][published]
            values = values[np.isfinite(values)]
            if values.size:
                largest = float(values.max())
                known = self.largest[key]
                self.largest[key] = largest if known is None else max(known, largest)

    def state(self):
        """Return what :meth:`merge` takes (plain JSON values)."""
        return {'low': {key: self.low[key].tolist() for key in OUTPUT_POINTS},
                'high': {key: self.high[key].tolist() for key in OUTPUT_POINTS},
                'seen': self.seen, 'messages': self.messages, 'largest': self.largest}

    def merge(self, state):
        """Take in another summary's :meth:`state` (rows estimated elsewhere)."""
        for key in OUTPUT_POINTS:
            if state['seen'][key]:
                self.seen[key] = True
                self.low[key] = np.minimum(self.low[key], state['low'][key])
                self.high[key] = np.maximum(self.high[key], state['high'][key])
        self.messages += state['messages']
        for key, largest in state['largest'].items():
            known = self.largest[key]
            if largest is not None:
                self.largest[key] = largest if known is None else max(known, largest)

    def result(self):
        """Each output point's peak-to-peak deflection [um] and the 'quality' summary."""
        result = {f'{key}_peak_to_peak_um': ((1e6 * (self.high[key] - self.low[key])).tolist()
                                             if self.seen[key] else [math.nan] * 2)
                  for key in OUTPUT_POINTS}
        result['quality'] = {'messages': self.messages,
                             **{f'{key}_max': self.largest[key] for key in QUALITY_NAMES}}
        return result


class _Stopped(Exception):
    """The writer stopped: the estimate ends too."""


def _put(blocks, item, stop):
    """Queue ``item`` for the writer, waiting while the queue is full; _Stopped if it ends."""
    while not stop.is_set():
        try:
            blocks.put(item, timeout=0.1)
            return
        except queue.Full:
            continue
    raise _Stopped()


class _Pipeline:
    """The estimate in a thread, handing blocks of final rows to the writing thread."""

    def __init__(self, model, rows, warm_start, tables):
        self.rows, self.stop, self.tables = rows, threading.Event(), tables
        self.blocks = queue.Queue(QUEUED_BLOCKS)
        self.outcome, self.seconds = None, None
        self.thread = threading.Thread(target=self._run, args=(model, warm_start),
                                       name='replay-estimate', daemon=True)
        self.thread.start()

    def _run(self, model, warm_start):
        start = time.perf_counter()
        try:
            outcome = ('done', estimate_stream(model, self.rows.estimate_input(), self._emit,
                                               warm_start=warm_start, align=WRITE_BATCH,
                                               block_rows=BLOCK_ROWS, tables=self.tables))
        except _Stopped:
            return
        except BaseException as exc:   # handed to the writing thread
            outcome = ('error', exc)
        self.seconds = time.perf_counter() - start
        try:
            _put(self.blocks, outcome, self.stop)
        except _Stopped:
            pass

    def _emit(self, first, estimate):
        self.rows.estimate_started.set()
        _put(self.blocks, (first, self.rows.take(len(estimate['flags'])), estimate), self.stop)

    def __iter__(self):
        """Yield (first, samples, estimate) of each block; the estimate's counts at the end."""
        while True:
            item = self.blocks.get()
            if item[0] == 'error':
                raise item[1]
            if item[0] == 'done':
                self.outcome = item[1]
                return
            yield item

    def close(self):
        """Stop the estimate if it still runs (the writer failed or was interrupted)."""
        self.stop.set()
        self.thread.join()
        self.rows.close()


def pipeline_blocks(model, rows, warm_start, tables, consume):
    """
    Estimate ``rows`` in a thread while ``consume(blocks)`` takes its blocks here.

    Returns :func:`estimate_stream`'s counts.
    """
    pipeline = _Pipeline(model, rows, warm_start, tables)
    try:
        consume(iter(pipeline))
    finally:
        pipeline.close()
    return pipeline.outcome


def estimate_and_write(args, model, rows, messages, write, on_block=None, tables=None,
                       transform=None, splitter=None):
    """
    Estimate every sample and, with ``write``, write the output file meanwhile.

    Parameters
    ----------
    args : argparse.Namespace
        ``no_warm_start``, ``out``.
    model : ReducedModel
        The model.
    rows : InputRows
        The input (its first chunk read).
    messages : int
        Messages of the input topic (the progress total).
    write : callable or None
        ``write(blocks, progress, tail=None)``: :func:`io.replay_writer.write_replay` of the
        blocks (None: estimate only).
    on_block : callable, optional
        ``on_block(estimate)`` with each block of estimated rows (the chart's rows).
    tables : object, optional
        The model's step tables (:func:`core.estimation.tables.step_tables`), when built.
    transform : NonlinearRows, optional
        Its ``blocks(blocks, messages)`` gives each block's estimate to sum up and write in
        place of the linear one (:class:`.replay_nonlinear.NonlinearRows`).
    splitter : replay_split.Splitter, optional
        Estimates and writes the rows from its split row in a forked process, when the
        recording is long enough (linear model, output file, no chart).

    Returns
    -------
    counts : dict
        :func:`estimate_stream`'s counts.
    summary : dict
        :meth:`EstimateSummary.result`.
    times : dict
        'estimate_s' (the estimate's thread), 'write_s' (reading, estimate and writing,
        overlapped) and with ``write`` the recorder's final status as 'status'.

    """
    start = time.perf_counter()
    summary = EstimateSummary()
    split = (splitter is not None and write is not None and transform is None
             and on_block is None and splitter.plan(rows, messages))
    if split:
        splitter.fork(rows)
    try:
        pipeline = _Pipeline(model, rows, not args.no_warm_start, tables)
    except BaseException:
        if split:
            splitter.abandon()
        raise

    def blocks():
        # The nonlinear deflections replace the linear ones (a span of blocks per thread).
        source = pipeline if transform is None else transform.blocks(pipeline, messages)
        for first, samples, estimate in source:
            summary.add(estimate)
            if on_block is not None:
                on_block(estimate)
            yield first, samples, estimate
    status = None
    try:
        if write is None:
            collections.deque(blocks(), maxlen=0)
        else:
            with Progress(f'writing {args.out}', messages, unit='sample') as shown:
                status = write(blocks(), lambda done, force=False: shown(done + rows.skipped,
                                                                         force=force),
                               tail=(lambda recorder: splitter.finish(recorder, rows))
                               if split else None)
    finally:
        pipeline.close()
        if split:
            splitter.abandon()
    outcome = pipeline.outcome
    if split:
        outcome = _merge_part(rows, outcome, summary, splitter.report)
    times = {'estimate_s': pipeline.seconds, 'write_s': time.perf_counter() - start,
             'processes': ({'used': 2, 'split_row': splitter.split,
                            'second_part': splitter.report['second_part']}
                           if split else {'used': 1})}
    if status is not None:
        times['status'] = status
    return outcome, summary.result(), times


def _merge_part(rows, outcome, summary, report):
    """Add the rows another part estimated (``report``: :meth:`Splitter.run_part`)."""
    rows.samples += report['samples']
    rows.skipped, rows.skipped_reasons = report['skipped'], report['skipped_reasons']
    if report['last_log_ns'] is not None and report['samples']:
        rows.last_log_ns = report['last_log_ns']
    if rows.damaged is not None and report['damaged'] is not None:
        del rows.damaged[rows.damage_mark:]
        rows.damaged.extend(tuple(entry) for entry in report['damaged'])
    summary.merge(report['summary'])
    merged = dict(outcome)
    merged['samples'] += report['samples']
    for key, count in report['counts'].items():
        merged[key] += count
    merged['window_rows'] = max(merged['window_rows'], report['window_rows'])
    return merged
