"""
`flexlink replay --processes 2`: the second part of a long recording in a forked process.

After the model is loaded, the replay forks (:func:`os.fork`: the child shares the mapped model
cache). The parent estimates and writes the rows before the split row; the child reads the
recording from its start (counting rows and skipped messages), estimates from a warm-up before
the split row (:func:`core.estimation.time_split.linear_warm_up_s`: the model's slowest decay;
started cold, at the static deflection) and writes the rows from the split row on as chunks of
their own (:class:`io.replay_writer.PartWriter`) into an unnamed temporary file beside the
output, which the parent then appends to its file (:meth:`McapRecorder.append_part`): one MCAP,
its summary, chunk indexes and statistics those of all its messages. The child's report (counts,
extremes, skipped messages) comes back as JSON over a pipe (nothing is unpickled).

The child's rows equal the sequential estimate's to ``WARM_UP_TOLERANCE`` of the deflection
range where its warm-up holds one segment and its part no restart. Where that does not hold (a
gap, a reset or an out-of-bound row after the warm-up's start: the restart's warm start depends
on what the sequential estimate kept), where its warm-up spans less time than the warm-up needs,
or where the parent's part did not publish every row (outliers: the child numbered its messages
as if it had), the parent discards the child's part and estimates the rest itself from the
recording's start (the sequential numbers, at the sequential cost).
"""

import gc
import json
import math
import os
import pathlib
import tempfile

import numpy as np

from .replay_offline import EstimateSummary, InputRows, pipeline_blocks
from ..core.estimation.gate import DEFAULT_RESET_GAP_S
from ..core.estimation.sample import SampleFlag
from ..core.estimation.time_split import linear_decay_rate, linear_warm_up_s, split_row
from ..core.reduction.mechanism_model import cached_model_values
from ..io.replay_writer import PartWriter

# The warm-up in rows is the warm-up in seconds at the first chunk's sample rate, with this
# margin (the child checks the time its warm-up spans and gives its part up if short) ...
WARM_UP_MARGIN = 1.03
# ... and at most this many rows (a denser recording runs in one process).
MAX_WARM_UP_ROWS = 1 << 17
# The parent's share of the rows (its warm-up included, the child's work is the rest): the
# parent also opens the input, appends the child's chunks and closes the file.
PARENT_SHARE = 0.47
# The most bytes of a child's report read (its damaged list is cut to MAX_DAMAGED entries).
MAX_REPORT_BYTES = 1 << 24
MAX_DAMAGED = 1000
DECAY_CACHE_NAME = 'linear-decay'


def can_fork():
    """Tell whether ``--processes 2`` can run here: the system forks and has 2 or more cores."""
    return hasattr(os, 'fork') and (os.cpu_count() or 1) >= 2


def warm_up_seconds(model, tables, mechanism, options, args):
    """
    Return the second part's warm-up [s]: the model's slowest decay (cached with the model).

    :func:`core.estimation.time_split.linear_warm_up_s`' rule; the decay rate (eigenvalues at
    every grid angle: about 0.3 s) is kept in a file beside the model's cache.
    """
    def build():
        return {'rate': np.array([linear_decay_rate(model, tables, (0.0, model.speed_max))])}
    rate = float(cached_model_values(mechanism, options, args.cache_dir, not args.no_cache,
                                     DECAY_CACHE_NAME, build)['rate'][0])
    return linear_warm_up_s(model, tables, DEFAULT_RESET_GAP_S, decay_rate=rate)


def part_directory(out):
    """
    Return the folder of the child's part: the output's, or its nearest existing parent.

    The recorder makes the missing ones when it opens the output, after the fork.
    """
    directory = pathlib.Path(os.path.abspath(out)).parent
    while not directory.is_dir() and directory != directory.parent:
        directory = directory.parent
    return directory


class Splitter:
    """
    Where to split a replay and the forked child's work (see the module notes).

    Parameters
    ----------
    args : argparse.Namespace
        The replay's flags (``input``, ``joint``, ``chunk_samples``, ``out``, ``processes``).
    model, tables
        The model and its step tables.
    writer : tuple
        (declared topics, ``write_rows(target, blocks)``) of the output.
    warm_up_s : float
        The warm-up [s] (:func:`warm_up_seconds`).

    """

    def __init__(self, args, model, tables, writer, warm_up_s):
        self.args, self.model, self.tables = args, model, tables
        self.declared, self.write_rows = writer
        self.warm_up_s = warm_up_s
        self.split = self.warm_rows = self.pid = self.read_fd = self.part = None
        self.guesses, self.report = {}, None

    def plan(self, rows, messages):
        """Choose the split row from the first chunk's rate; whether the replay splits."""
        if getattr(self.args, 'processes', 1) < 2 or not rows.peeked or not math.isfinite(
                self.warm_up_s):
            return False
        stamps = rows.peeked[0]['stamps_ns']
        lasted_s = (int(stamps[-1]) - int(stamps[0])) * 1e-9 if len(stamps) > 1 else 0.0
        if not lasted_s > 0.0:
            return False
        warm_rows = int(math.ceil(self.warm_up_s * (len(stamps) - 1) / lasted_s
                                  * WARM_UP_MARGIN))
        split = split_row(messages, warm_rows, PARENT_SHARE)
        if warm_rows > MAX_WARM_UP_ROWS or split is None:
            return False
        self.split, self.warm_rows = split, warm_rows
        return True

    def fork(self, rows):
        """Start the child on the rows from the split row; the parent keeps those before it."""
        self.part = tempfile.TemporaryFile(dir=part_directory(self.args.out),
                                           prefix='.replay-part-')
        self.read_fd, write_fd = os.pipe()
        guesses = self._sequences()
        # The child's collector then leaves the objects made so far alone: its passes would
        # otherwise write to every one, copying their pages. The parent takes them back.
        gc.freeze()
        self.pid = os.fork()
        if self.pid == 0:       # the child: never returns
            os.close(self.read_fd)
            self._child(write_fd, guesses, rows.damaged is not None)
        gc.unfreeze()
        os.close(write_fd)
        rows.limit(self.split)
        self.guesses = guesses

    def _sequences(self):
        """Each topic's messages before the split row if every row there was published."""
        count = self.split
        sequences = {name: count for name, _ in self.declared[:5]}
        if len(self.declared) > 5:
            every = self.args.markers_every_n
            sequences[self.declared[5][0]] = -(-count // every)
        return sequences

    def _child(self, write_fd, sequences, damage_listed):
        code = 0
        try:
            payload = json.dumps(self.run_part(self._part_target(sequences),
                                               self.split - self.warm_rows, damage_listed,
                                               warm_start=False))
        except BaseException as exc:   # reported to the parent, which raises it
            payload = json.dumps({'error': f'{type(exc).__name__}: {exc}'})
            code = 1
        try:
            data = payload.encode()
            while data:
                data = data[os.write(write_fd, data):]
        finally:
            os._exit(code)

    def _part_target(self, sequences):
        return PartWriter(self.part, self.declared, sequences, part_directory(self.args.out))

    def run_part(self, target, start, damage_listed, warm_start):
        """
        Estimate from row ``start`` and write the rows from the split row into ``target``.

        Returns the part's report: its rows' counts and extremes, the skipped messages and
        damage of the whole recording, and whether its rows hold (``exact``).
        """
        damaged = [] if damage_listed else None
        args = self.args
        rows = InputRows(args.input, self.declared[0][0], args.joint, args.chunk_samples,
                         damaged, start=start)
        summary, counts = EstimateSummary(), {'outliers': 0, 'out_of_bound': 0, 'segments': 0}
        stamps = {}

        def kept(blocks):
            for first, samples, estimate in blocks:
                first += start
                size = len(samples['data'])
                stamps.setdefault('warm', int(samples['stamps_ns'][0]) if size else 0)
                cut = max(self.split - first, 0)
                if cut < size:
                    stamps.setdefault('split', int(samples['stamps_ns'][cut]))
                if cut:
                    if cut >= size:
                        continue
                    samples = {key: value[cut:] for key, value in samples.items()}
                    estimate = {key: value[cut:] for key, value in estimate.items()}
                    first += cut
                flags = estimate['flags']
                counts['outliers'] += int(np.count_nonzero(flags & SampleFlag.OUTLIER))
                counts['out_of_bound'] += int(np.count_nonzero(flags & SampleFlag.OUT_OF_BOUND))
                counts['segments'] += int(np.count_nonzero(flags & SampleFlag.RESET))
                summary.add(estimate)
                yield first, samples, estimate
        outcome = pipeline_blocks(self.model, rows, warm_start, self.tables,
                                  lambda blocks: self.write_rows(target, kept(blocks)))
        if hasattr(target, 'finish'):
            target.finish()
        spanned_s = (stamps.get('split', 0) - stamps.get('warm', 0)) * 1e-9
        exact = (start == 0 or (outcome['segments'] <= 1 and outcome['out_of_bound'] == 0
                                and spanned_s >= self.warm_up_s))
        return {'exact': bool(exact), 'samples': max(start + rows.samples - self.split, 0),
                'skipped': rows.skipped, 'skipped_reasons': rows.skipped_reasons,
                'last_log_ns': rows.last_log_ns, 'counts': counts,
                'window_rows': outcome['window_rows'],
                'criteria_available': outcome['criteria_available'],
                'summary': summary.state(),
                'damaged': None if damaged is None else [list(d) for d in damaged[:MAX_DAMAGED]]}

    def finish(self, recorder, parent_rows):
        """
        Append the child's part to ``recorder`` (or estimate it here); return its report.

        Called once the parent's rows are written: waits for the child. Returns the rows
        appended; the report is kept as ``report``.
        """
        report = self._report()
        written = recorder.status(list_files=False)['topics']
        # No row from the split on (fewer usable rows than messages): the child only counted.
        exact = not report['samples'] or (
            report['exact'] and parent_rows.samples == self.split
            and all(written[name] == count for name, count in self.guesses.items()))
        if exact:
            self.part.seek(0)
            recorder.append_part(self.part)
            report['second_part'] = 'forked' if report['samples'] else 'empty'
        else:
            # The sequential estimate of the rest, written here.
            report = self.run_part(recorder, 0, report.get('damaged') is not None,
                                   not self.args.no_warm_start)
            report['second_part'] = 'sequential'
        self.part.close()
        self.report = report
        return report['samples']

    def _report(self):
        chunks, size = [], 0
        while True:
            data = os.read(self.read_fd, 1 << 16)
            if not data:
                break
            size += len(data)
            if size > MAX_REPORT_BYTES:
                raise ValueError('the replay part process reported too much')
            chunks.append(data)
        os.close(self.read_fd)
        os.waitpid(self.pid, 0)
        self.pid = None
        report = json.loads(b''.join(chunks) or b'{"error": "the part process ended"}')
        if 'error' in report:
            raise ValueError(f'the replay part process failed: {report["error"]}')
        return report

    def abandon(self):
        """Stop the child (the parent failed or was interrupted)."""
        if self.pid:
            try:
                os.kill(self.pid, 15)
                os.waitpid(self.pid, 0)
            except OSError:
                pass
            self.pid = None


__all__ = ['can_fork', 'warm_up_seconds', 'Splitter']
