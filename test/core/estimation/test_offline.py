"""The offline estimate of a stream, segment by segment, against the streaming node."""

import math
import threading

from flexlink_ros.core import options as core_options
from flexlink_ros.core.estimation import offline, segment_replay, streaming, tables
from flexlink_ros.core.estimation.sample import SampleFlag
from flexlink_ros.core.estimation.streaming import StreamingEstimator
from flexlink_ros.core.mechanism_file import load_mechanism
from flexlink_ros.core.reduction import mechanism_model
from flexlink_ros.errors import OutlierSample
from flexlink_ros.ros import parameters as node_params
import numpy as np
import pytest


RPM = 2.0 * math.pi / 60.0


@pytest.fixture(scope='module')
def model():
    """Build (or load) the node's default model without geometric stiffness."""
    options = node_params.default_model_options(geometric_stiffness=False)
    return mechanism_model.model_for_mechanism(load_mechanism('cho1992'), options)


def test_segments_follow_the_streaming_resets():
    stamps = np.array([0, 1, 2, 2, 3, 10**9, 10**9 + 1, 5, 6]) * 1_000_000
    angles = np.array([0.0, 0.1, 0.2, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7])
    starts, repeated = offline.segments(stamps, angles)
    # 3 -> 1000 ms is a 0.997 s gap (> 0.5 s), 1000 -> 5 ms goes back.
    assert starts == [0, 5, 7]
    assert repeated.tolist() == [False, False, False, True] + [False] * 5


def test_estimate_reports_only_final_samples_to_the_writer(model, monkeypatch):
    """progress(n) comes only once the first n samples are final, through gaps and repeats."""
    monkeypatch.setattr(segment_replay, 'REPLAY_CHUNK', 64)     # many chunks per segment
    stamps = np.arange(700) * 1_000_000
    stamps[400:] += 800_000_000                                 # a gap: two segments
    stamps[200] = stamps[199]                                   # a repeated sample
    angles = 391 * RPM * stamps * 1e-9
    angles[200] = angles[199]
    speeds = np.full(stamps.size, 391 * RPM)
    speeds[300:310] = np.nan                                    # no speed in a stretch
    snapshots = []
    result = offline.allocate_estimate(model, stamps.size)

    def progress(count):
        snapshots.append((count, {key: result[key][:count].copy()
                                  for key in ('lever_tip', 'criterion', 'modal')}))
    offline.estimate_offline(model, stamps, angles, speeds, result=result, progress=progress)
    counts = [count for count, _ in snapshots]
    assert counts == sorted(counts) and counts[-1] == stamps.size and len(counts) > 10
    for count, early in snapshots:
        for key, values in early.items():
            np.testing.assert_array_equal(values, result[key][:count])
    assert result['segments'] == 2
    np.testing.assert_array_equal(result['lever_tip'][200], result['lever_tip'][199])


def test_segments_share_one_set_of_step_tables(model, monkeypatch):
    """A recording with many gaps builds the step tables once, not per segment."""
    built = []
    original = tables._StepTables.__init__

    def counted(self, *args, **kwargs):
        built.append(1)
        original(self, *args, **kwargs)
    monkeypatch.setattr(tables._StepTables, '__init__', counted)
    stamps = np.arange(60) * 1_000_000 + np.repeat(np.arange(6), 10) * 700_000_000
    angles = 391 * RPM * stamps * 1e-9
    speeds = np.full(stamps.size, 391 * RPM)
    result = offline.estimate_offline(model, stamps, angles, speeds)
    assert result['segments'] == 6 and len(built) == 1
    with pytest.raises(ValueError, match='do not match the model'):
        small = mechanism_model.model_for_mechanism(
            load_mechanism('cho1992'), core_options.ModelOptions.linear(
                rigid_crank=True, bearings='rigid', geometric_stiffness=False))
        StreamingEstimator(model, step_tables=tables.step_tables(small))


@pytest.mark.parametrize('window', [offline.PLAN_WINDOW, 7])
def test_offline_estimate_equals_streaming_through_outliers_and_out_of_bound(
        model, monkeypatch, window):
    """Outliers, a jump and out-of-bound resets: replay's rows are the node's samples."""
    monkeypatch.setattr(offline, 'PLAN_WINDOW', window)     # planned in windows or not
    stamps = 10**9 + np.arange(1500, dtype=np.int64) * 1_000_000
    speed = np.full(stamps.size, 391.0 * RPM)
    speed[1000:] = -100.0            # a jump: outliers until it is plausible over their dt
    angles = np.cumsum(speed) * 1e-3
    speed[[200, 201, 600]] = (1.7e308, -1.7e308, 1e6)
    stamps[800], angles[800] = stamps[799], angles[799]       # an exact repeat
    reference = StreamingEstimator(model)
    normal = max(max(map(abs, reference.update(int(s), a, w).lever_tip))
                 for s, a, w in zip(stamps[:400].tolist(), angles[:400], speed[:400])
                 if abs(w) < 1e3)
    # A bound below the normal peak: the peaks go out of bound and restart the estimate.
    monkeypatch.setattr(streaming, 'DEFLECTION_SAFETY_FACTOR',
                        streaming.DEFLECTION_SAFETY_FACTOR * 0.9 * normal
                        / reference.deflection_bound_m)
    estimator = StreamingEstimator(model)
    streamed = []
    for stamp, angle, value in zip(stamps.tolist(), angles.tolist(), speed.tolist()):
        try:
            streamed.append(estimator.update(stamp, angle, value))
        except OutlierSample:
            streamed.append(None)
    result = offline.estimate_offline(model, stamps, angles, speed)
    flags = result['flags']
    refused = [n for n, s in enumerate(streamed) if s is None]
    assert refused == np.flatnonzero(flags & SampleFlag.OUTLIER).tolist()
    assert refused[:4] == [200, 201, 600, 1000]
    out = [n for n, s in enumerate(streamed)
           if s is not None and s.flags & SampleFlag.OUT_OF_BOUND]
    assert len(out) > 5 and out == np.flatnonzero(flags & SampleFlag.OUT_OF_BOUND).tolist()
    assert result['outliers'] == len(refused) and result['out_of_bound'] == len(out)
    for n, sample in enumerate(streamed):
        if sample is None or sample.flags & SampleFlag.OUT_OF_BOUND:
            assert np.all(np.isnan(result['lever_tip'][n]))
            continue
        assert bool(flags[n] & SampleFlag.REPEATED) == bool(sample.flags & SampleFlag.REPEATED)
        if not sample.flags & SampleFlag.REPEATED:
            assert bool(flags[n] & SampleFlag.RESET) == bool(sample.flags & SampleFlag.RESET)
        np.testing.assert_allclose(result['lever_tip'][n], sample.lever_tip, rtol=1e-7,
                                   atol=1e-12)
        np.testing.assert_allclose(result['coupler_mid'][n], sample.coupler_mid, rtol=1e-7,
                                   atol=1e-12)
        # the quality the node publishes with each estimate (~/quality)
        assert result['error_indicator'][n] == pytest.approx(sample.error_indicator, rel=1e-6)


def awkward_stream(count):
    """Return a 1 kHz stream with repeats, outliers, a gap, a step back, speedless samples."""
    rng = np.random.default_rng(5)
    stamps = 10**9 + np.cumsum(np.round((1 + 0.3 * rng.uniform(-1, 1, count)) * 1e6)).astype(
        np.int64)
    speed = np.full(count, 391.0 * RPM)
    speed[count * 2 // 3:] = -40.0        # a reversal: outliers until it is plausible
    angles = np.cumsum(speed) * 1e-3
    speed[[200, 201, 999, 1000, 4095, 4096]] = 1e6
    for row in (800, 1024, 4097, 5000):   # exact repeats, some on chunk or plan boundaries
        stamps[row], angles[row] = stamps[row - 1], angles[row - 1]
    stamps[3000:] += 800_000_000          # a gap
    stamps[4500:] -= 2_000_000_000        # back in time
    speed[5500:5550] = np.nan             # no measured speed
    return stamps, angles, speed


def stream_in_chunks(model, signal, chunk, **blocks):
    """estimate_stream over ``signal`` read ``chunk`` rows at a time, gathered in arrays."""
    count = signal[0].size
    result = offline.allocate_estimate(model, count)
    handed = []

    def emit(first, block):
        handed.append((first, len(block['flags'])))
        for key, values in block.items():
            result[key][first:first + len(values)] = values
    chunks = ([column[start:start + chunk] for column in signal]
              for start in range(0, count, chunk))
    result.update(offline.estimate_stream(model, chunks, emit, **blocks))
    assert [first for first, _ in handed] == np.cumsum([0] + [n for _, n in handed])[
        :-1].tolist()
    return result, handed


@pytest.mark.parametrize('chunk, align, block_rows',
                         [(97, 1, 1), (1000, 1024, 3000), (4096, 64, 500)])
def test_a_stream_read_in_chunks_gives_the_whole_estimate_bit_for_bit(
        model, monkeypatch, chunk, align, block_rows):
    """Restarts, repeats and outliers on chunk boundaries: the rows of one whole run."""
    signal = awkward_stream(7000)
    peak = np.nanmax(np.abs(offline.estimate_offline(model, *signal)['lever_tip'][:4000]))
    bound = StreamingEstimator(model).deflection_bound_m
    # A bound below the highest peaks: they go out of bound and restart the estimate.
    monkeypatch.setattr(streaming, 'DEFLECTION_SAFETY_FACTOR',
                        streaming.DEFLECTION_SAFETY_FACTOR * 0.95 * peak / bound)
    whole = offline.estimate_offline(model, *signal)
    assert whole['out_of_bound'] > 3 and whole['segments'] > 5 and whole['outliers'] >= 6
    streamed, handed = stream_in_chunks(model, signal, chunk, align=align,
                                        block_rows=block_rows)
    for key in ('segments', 'outliers', 'out_of_bound', 'criteria_available'):
        assert streamed[key] == whole[key]
    for key, values in whole.items():
        if isinstance(values, np.ndarray):     # bit for bit, NaN where NaN
            assert values.tobytes() == streamed[key].tobytes(), key
    assert all(first % align == 0 for first, _ in handed)
    bound = chunk + 2 * offline.PLAN_WINDOW + block_rows + align
    assert streamed['window_rows'] <= bound


def test_the_rows_held_do_not_grow_with_the_stream(model):
    """A long recording with a long run of outliers is held a window at a time."""
    stamps, angles, speed = awkward_stream(40000)
    speed[10000:30000] = 1e7                     # twenty seconds of implausible speeds
    result, _ = stream_in_chunks(model, (stamps, angles, speed), 500, align=1024,
                                 block_rows=2048)
    assert result['samples'] == 40000 and result['outliers'] >= 20000
    bound = 500 + 2 * offline.PLAN_WINDOW + 2048 + 1024
    assert result['window_rows'] <= bound < 20000


def test_each_chunks_rows_are_taken_while_the_next_chunk_steps(model, monkeypatch):
    """The criteria and indicators of a chunk run beside the next chunk's step, bit for bit."""
    monkeypatch.setattr(segment_replay, 'REPLAY_CHUNK', 256)    # many chunks per piece
    signal = awkward_stream(7000)
    threads = []
    take_rows = offline._OfflineRun.take_rows

    def noted(run):
        if run.taken is not None:
            threads.append(threading.current_thread().name)
        take_rows(run)
    monkeypatch.setattr(offline._OfflineRun, 'take_rows', noted)
    beside, handed = stream_in_chunks(model, signal, 1000, align=64, block_rows=500)
    assert threads.count('estimate-rows_0') > len(threads) // 2, threads

    def in_turn(run, step):         # the order of one thread: take the rows, then step
        run.take_rows()
        return step()
    monkeypatch.setattr(offline._OfflineRun, 'beside_step', in_turn)
    threads.clear()
    alone, handed_alone = stream_in_chunks(model, signal, 1000, align=64, block_rows=500)
    assert set(threads) == {threading.current_thread().name}
    assert handed == handed_alone
    for key, values in alone.items():
        if isinstance(values, np.ndarray):
            assert values.tobytes() == beside[key].tobytes(), key
