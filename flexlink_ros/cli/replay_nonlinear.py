"""
``replay --nonlinear auto|on|off``: the reduced nonlinear model's deflections in the output.

The same rule and the same ``model: ...`` line as ``estimate --nonlinear``
(:func:`core.estimation.nonlinear_follow.choose_nonlinear`). ``on`` writes the nonlinear
model's lever-tip and coupler-mid deflections in place of the linear ones, as the replay
writes (:class:`NonlinearRows`: memory independent of the recording's length).
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

The nonlinear step costs 10-20 times the linear one: with ``--threads N`` a recording long
enough is cut into spans followed in N threads at once (:class:`SpanFollower`; the compiled
step releases the GIL), each from a warm-up before it as long as the model's slowest decay
needs to fade a start to 1e-12 (:mod:`core.estimation.follow_spans`: about 8 s for the paper's
linkage): the same deflections and counts as one follower, to rounding, for memory that grows
with N but not with the recording (N + 1 spans of up to 32 768 rows, about 1 KB each).
"""

import collections
import concurrent.futures
import math

import numpy as np

from ..core.estimation.follow_spans import follow_span, warm_up_s
from ..core.estimation.nonlinear_follow import accepted_rows, choose_nonlinear, follow_rows, \
    follow_summary, NonlinearFollower
from ..core.estimation.nonlinear_stream import VON_KARMAN_SLOPE
from ..core.reduction.nonlinear_model import nonlinear_model_for
from ..core.validity import is_valid

# The most threads `--threads` accepts (each holds a span), the fewest rows worth a span, the
# most (what a span holds: about 1 KB a row, input and estimate), and the least span length in
# warm-ups (each span's warm-up is stepped twice: 2 warm-ups keep two thirds of the work useful).
MAX_THREADS = 16
MIN_SPAN_ROWS = 4096
MAX_SPAN_ROWS = 1 << 15
SPANS_PER_WARM_UP = 2.0


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

    def __init__(self, tables, reset_gap_s, damping='', speed_max=0.0, threads=1):
        self.tables, self.damping = tables, damping
        self.reset_gap_s, self.speed_max, self.threads = reset_gap_s, speed_max, threads
        self.follower = NonlinearFollower(tables, reset_gap_s)
        self.low = np.full(tables.outputs, np.inf)
        self.high = np.full(tables.outputs, -np.inf)

    def __call__(self, samples, estimate):
        """Return ``estimate`` with the nonlinear 'lever_tip' and 'coupler_mid' rows."""
        outputs, accepted = follow_rows(self.follower, samples['stamps_ns'], estimate)
        return self._replaced(estimate, outputs, accepted)

    def _replaced(self, estimate, outputs, accepted):
        if accepted.any():
            self.low = np.minimum(self.low, outputs[accepted].min(axis=0))
            self.high = np.maximum(self.high, outputs[accepted].max(axis=0))
        replaced = dict(estimate)
        replaced['lever_tip'], replaced['coupler_mid'] = outputs[:, 0:2], outputs[:, 2:4]
        return replaced

    def blocks(self, source, rows, max_span_rows=MAX_SPAN_ROWS):
        """
        Yield the (first, samples, estimate) of ``source`` with the nonlinear deflections.

        With ``threads`` > 1, a recording of ``rows`` rows long enough for that many spans (of
        at most ``max_span_rows``) of at least :data:`SPANS_PER_WARM_UP` warm-ups
        (:func:`core.estimation.follow_spans.warm_up_s`) is followed a span per thread
        (:class:`SpanFollower`: up to ``threads`` + 1 spans held), else block by block here.
        """
        source = iter(source)
        head = next(source, None)
        if head is None:
            return
        span_rows = min(max_span_rows, -(-rows // self.threads))
        stamps = head[1]['stamps_ns']
        lasted_ns = int(stamps[-1]) - int(stamps[0]) if len(stamps) else 0
        rate = (len(stamps) - 1) / (lasted_ns * 1e-9) if lasted_ns > 0 else 0.0   # samples/s
        warm_up = (warm_up_s(self.tables, self.speed_max, self.reset_gap_s)
                   if self.threads > 1 and span_rows >= MIN_SPAN_ROWS and rate > 0
                   else math.inf)
        chained = _chain(head, source)
        if not span_rows >= SPANS_PER_WARM_UP * warm_up * rate:
            for first, samples, estimate in chained:
                yield first, samples, self(samples, estimate)
            return
        yield from SpanFollower(self, warm_up, span_rows).blocks(chained)

    def summary(self):
        """Return the JSON's ``nonlinear`` entry: peak-to-peak deflections [um] and counts."""
        return follow_summary(self.follower, self.low, self.high, self.damping)


def _chain(head, rest):
    yield head
    yield from rest


class SpanFollower:
    """
    Follow spans of blocks in parallel threads, each from a warm-up before it (bounded memory).

    A span is ``span_rows`` rows of whole blocks; its follower (:func:`follow_span`) starts
    ``warm_up`` seconds of accepted samples before it. At most ``rows.threads`` spans are
    followed at once and one more read: what is held is a few spans' rows, however long the
    recording. Counts and extremes go to ``rows`` (the :class:`NonlinearRows`).
    """

    def __init__(self, rows, warm_up, span_rows):
        self.rows, self.warm_up, self.span_rows = rows, warm_up, span_rows
        self.tail = None            # the last warm-up's length of accepted samples
        self.accepted_before = False

    def _inputs(self, span):
        """Return the accepted samples (stamps, angles, speeds) of a span, and its masks."""
        masks = [accepted_rows(estimate) for _, _, estimate in span]
        stamps = np.concatenate([samples['stamps_ns'][mask]
                                 for (_, samples, _), mask in zip(span, masks)])
        angles, speeds = (np.concatenate([estimate[key][mask]
                                          for (_, _, estimate), mask in zip(span, masks)])
                          for key in ('crank_angle', 'crank_speed'))
        return (stamps, angles, speeds), masks

    def _submit(self, pool, span):
        inputs, masks = self._inputs(span)
        warm = None
        if self.tail is not None and len(inputs[0]):
            cut = inputs[0][0] - round(self.warm_up * 1e9)
            keep = self.tail[0] >= cut
            warm = tuple(values[keep] for values in self.tail)
        future = pool.submit(follow_span, self.rows.tables, self.rows.reset_gap_s, warm,
                             inputs, self.accepted_before)
        if len(inputs[0]):
            # The accepted samples of the last warm-up's length, over as many spans as it takes.
            joined = inputs if self.tail is None else tuple(
                np.concatenate([before, now]) for before, now in zip(self.tail, inputs))
            keep = joined[0] >= joined[0][-1] - round(self.warm_up * 1e9)
            self.tail = tuple(values[keep] for values in joined)
            self.accepted_before = True
        return span, masks, future

    def _finish(self, span, masks, future):
        """Yield a followed span's blocks with its outputs; add its counts to ``rows``."""
        outputs, follower = future.result()
        total, rows = self.rows.follower, self.rows
        for key, count in follower.counts.items():
            total.counts[key] += count
        total.slope_max = max(total.slope_max, follower.slope_max)
        if len(outputs):
            total.validity, total.last = follower.validity, follower.last
        start = 0
        for (first, samples, estimate), mask in zip(span, masks):
            block = np.full((mask.size, outputs.shape[1]), np.nan)
            block[mask] = outputs[start:start + np.count_nonzero(mask)]
            start += np.count_nonzero(mask)
            yield first, samples, rows._replaced(estimate, block, mask)

    def blocks(self, source):
        """Yield the blocks of ``source`` in order, followed a span per thread."""
        running = collections.deque()
        span, size = [], 0
        threads = self.rows.threads
        with concurrent.futures.ThreadPoolExecutor(threads) as pool:
            try:
                for block in source:
                    span.append(block)
                    size += len(block[1]['stamps_ns'])
                    if size < self.span_rows:
                        continue
                    running.append(self._submit(pool, span))
                    span, size = [], 0
                    if len(running) == threads:
                        yield from self._finish(*running.popleft())
                if span:
                    running.append(self._submit(pool, span))
                while running:
                    yield from self._finish(*running.popleft())
            finally:
                for _, _, future in running:
                    future.cancel()


def nonlinear_rows(args, mechanism, options, reset_gap_s):
    """Return the :class:`NonlinearRows` of the replay's mechanism and options."""
    tables, damping = nonlinear_model_for(mechanism, options, args.cache_dir,
                                          not args.no_cache)
    return NonlinearRows(tables, reset_gap_s, damping, options.speed_max,
                         getattr(args, 'threads', 1))


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


__all__ = ['nonlinear_choice', 'decide', 'NonlinearRows', 'SpanFollower', 'nonlinear_rows',
           'model_lines']
