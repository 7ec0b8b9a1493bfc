"""The marker thread: order, bound, errors, drain and stop (real threads, no ROS)."""

import threading

from flexlink_ros.ros import marker_worker
from flexlink_ros.ros.marker_worker import MarkerWorker


def test_samples_are_delivered_in_order_with_their_stamps_and_log_times():
    delivered = []
    worker = MarkerWorker(lambda stamp, sample: f'{stamp}:{sample}'.encode(),
                          lambda data, log_ns: delivered.append((data, log_ns)),
                          lambda exc: delivered.append(exc))
    for k in range(50):
        worker.submit(1000 + k, f's{k}', 2000 + k)
    assert worker.drain()
    assert delivered == [(f'{1000 + k}:s{k}'.encode(), 2000 + k) for k in range(50)]
    worker.stop()
    assert worker.dropped == 0


def test_a_worker_far_behind_drops_the_oldest_and_counts_them():
    release, delivered = threading.Event(), []

    def draw(stamp, sample):
        release.wait(10.0)
        return stamp

    worker = MarkerWorker(draw, lambda data, log_ns: delivered.append(data), None)
    worker.submit(0, None, 0)           # taken by the thread, held in draw
    while worker._pending:
        threading.Event().wait(0.001)
    extra = 5
    for k in range(1, marker_worker.MAX_PENDING + extra + 1):
        worker.submit(k, None, k)
    assert worker.dropped == extra
    release.set()
    worker.stop()
    assert delivered == [0] + list(range(extra + 1, marker_worker.MAX_PENDING + extra + 1))


def test_an_error_is_reported_and_the_next_marker_still_delivered():
    reports, delivered = [], []

    def draw(stamp, sample):
        if stamp == 1:
            raise ValueError('bad shape')
        return stamp

    worker = MarkerWorker(draw, lambda data, log_ns: delivered.append(data), reports.append)
    for k in range(3):
        worker.submit(k, None, k)
    worker.stop()
    assert delivered == [0, 2]
    assert [str(exc) for exc in reports] == ['bad shape']


def test_stop_delivers_what_waits_and_ends_the_thread():
    delivered = []
    worker = MarkerWorker(lambda stamp, sample: stamp,
                          lambda data, log_ns: delivered.append(data), None)
    for k in range(20):
        worker.submit(k, None, k)
    worker.stop()
    worker.stop()       # idempotent
    assert delivered == list(range(20))
    assert not worker._thread.is_alive()
