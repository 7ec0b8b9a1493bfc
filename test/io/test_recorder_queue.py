"""recorder_queue: enqueued messages written in order by the thread; a full disk once."""

import time

from flexlink_ros.cli.mcap import recover_mcap
from flexlink_ros.errors import RecorderError
from flexlink_ros.io import recorder_queue
from flexlink_ros.io.msg_schema import serialize_exact
from flexlink_ros.io.recorder import McapRecorder, RecorderState
from mcap.reader import make_reader
import numpy as np
from recorder_helpers import sample_messages, STEP_NS, T0_NS


def test_enqueued_messages_are_written_in_order_by_the_background_thread(
        tmp_path, monkeypatch):
    """enqueue: nothing written in the caller; every message on disk, in order, exact bytes."""
    # The thread first wakes after a second, long after the enqueuing below (a few ms): what
    # is on disk before then was written by enqueue itself, which must be nothing.
    monkeypatch.setattr(recorder_queue, 'QUEUE_PERIOD_S', 1.0)
    path = tmp_path / 'queued.mcap'
    recorder = McapRecorder(path, chunk_size_bytes=4096).open()
    recorder.add_topic('/a', 'sensor_msgs/msg/JointState')
    rng = np.random.default_rng(3)
    sent = []
    for k in range(3000):
        data = bytes([k % 256]) * int(rng.integers(1, 300))
        if k % 500 == 0:        # a message object too (serialised and declared by enqueue)
            topic, data = '/joint_states', sample_messages(k)['/joint_states']
            sent.append((topic, serialize_exact(data), T0_NS + k * STEP_NS))
        else:
            topic = '/a'
            sent.append((topic, data, T0_NS + k * STEP_NS))
        assert recorder.enqueue(topic, data, T0_NS + k * STEP_NS) is True
    assert recorder.status()['message_count'] == 0          # all still queued
    deadline = time.monotonic() + 5.0
    while recorder.status()['message_count'] < len(sent) and time.monotonic() < deadline:
        time.sleep(0.01)
    assert recorder.status()['message_count'] == len(sent)   # the thread wrote them
    recorder.close()
    with open(path, 'rb') as stream:
        read = [(channel.topic, message.data, message.log_time)
                for _, channel, message in make_reader(stream).iter_messages(log_time_order=False)]
    assert read == sent


def test_enqueue_reports_a_full_disk_once_and_estimation_can_go_on(tiny_tmpfs, tmp_path):
    recorder = McapRecorder(tiny_tmpfs / 'bag', chunk_size_bytes=8192).open()
    raised, k = 0, 0
    deadline = time.monotonic() + 20.0
    while recorder.state is not RecorderState.FAILED and time.monotonic() < deadline:
        for topic, msg in sample_messages(k).items():
            try:
                recorder.enqueue(topic, msg, T0_NS + k * STEP_NS)
            except RecorderError as exc:
                raised += 1
                assert 'No space left' in str(exc)
        k += 1
        if k % 200 == 0:
            time.sleep(0.03)    # let the background thread write
    assert recorder.state is RecorderState.FAILED
    for j in range(k, k + 10):   # the failure is raised once, then messages drop quietly
        try:
            assert recorder.enqueue('/joint_states', sample_messages(j)['/joint_states'],
                                    T0_NS + j * STEP_NS) is False
        except RecorderError:
            raised += 1
    try:
        status = recorder.close()
    except RecorderError:
        raised += 1
        status = recorder.status()
    assert raised == 1 and status['state'] == 'failed' and status['dropped_count'] >= 10
    result = recover_mcap(status['files'][0], tmp_path / 'salvaged.mcap')
    assert result['message_count'] > 0


def test_the_queue_is_bounded_in_bytes_and_what_overflows_is_counted(tmp_path):
    """A writer that cannot keep up (its lock held, as by a slow disk) loses counted messages."""
    bag = tmp_path / 'bag'
    recorder = McapRecorder(bag).open()
    recorder.add_topic('/a', 'sensor_msgs/msg/JointState')
    data = bytes(1000)
    bound = recorder_queue.QUEUE_MAX_BYTES
    offered = 3 * bound // len(data)
    with recorder._lock:      # the writing thread waits here, as behind a stalled disk
        accepted = sum(recorder.enqueue('/a', data, T0_NS + k * STEP_NS)
                       for k in range(offered))
        status = recorder.status()
        assert status['queued_bytes'] <= bound
    assert 0 < accepted < offered
    assert status['overflow_count'] == offered - accepted == status['dropped_count']
    status = recorder.close()
    assert status['overflow_count'] == offered - accepted
    with open(bag / 'bag_0.mcap', 'rb') as stream:
        on_disk = sum(1 for _ in make_reader(stream).iter_messages(log_time_order=False))
    assert on_disk == accepted == status['message_count']


def test_the_flush_clock_counts_log_time_per_message_and_wall_time_when_idle():
    clock = recorder_queue.FlushClock(period_ns=200_000_000)
    assert clock.wrote(T0_NS) is False and clock.last_log_ns == T0_NS   # starts the period
    assert clock.wrote(T0_NS + 199_999_999) is False
    assert clock.wrote(T0_NS + 200_000_000) is True and clock.unflushed == 3
    clock.flushed(T0_NS + 200_000_000)
    assert (clock.unflushed, clock.idle_due()) == (0, False)
    clock.wrote_batch(T0_NS + 250_000_000, 5, flushes=[])
    assert clock.unflushed == 5 and not clock.idle_due()
    time.sleep(0.25)                  # no message for a flush period of wall time
    assert clock.idle_due()
    clock.wrote_batch(T0_NS + 300_000_000, 4, flushes=[(1, T0_NS + 420_000_000)])
    assert (clock.unflushed, clock.last_log_ns) == (2, T0_NS + 420_000_000)
    assert not clock.idle_due()
