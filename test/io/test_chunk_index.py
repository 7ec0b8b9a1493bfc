"""chunk_index: the summary's chunk indexes do not accumulate in memory."""

import os
import tracemalloc

from flexlink_ros.io import chunk_index
from flexlink_ros.io.recorder import McapRecorder
from geometry_msgs.msg import Vector3Stamped
from mcap.reader import make_reader
import numpy as np
from rclpy.serialization import serialize_message
from recorder_helpers import stamp, STEP_NS, T0_NS


def test_retained_memory_per_chunk_is_bounded(tmp_path):
    topics = ['/a', '/b', '/c', '/d', '/e']   # the node records 4-5 topics
    payload = serialize_message(Vector3Stamped(header=stamp(T0_NS)))
    recorder = McapRecorder(tmp_path / 'long.mcap', chunk_size_bytes=1024, flush_thread=False)
    for topic in topics:
        recorder.add_topic(topic, 'geometry_msgs/msg/Vector3Stamped')
    recorder.open()
    writer = recorder._file.writer

    def record(first, samples):
        for k in range(first, first + samples, 100):
            times = np.repeat(T0_NS + STEP_NS * np.arange(k, k + 100), len(topics))
            recorder.write_batch(topics * 100, [payload] * len(times), times)

    def chunks():
        return writer.chunk_count

    record(0, 1000)    # warm up: allocator pools, numpy caches, first spill of none
    tracemalloc.start()
    try:
        before_chunks, before = chunks(), tracemalloc.get_traced_memory()[0]
        record(1000, 8_000)
        grown, added = tracemalloc.get_traced_memory()[0] - before, chunks() - before_chunks
    finally:
        tracemalloc.stop()
    per_chunk_object = 700   # what mcap's Writer retains per ChunkIndex object (measured ~740)
    # The records in memory are at most INDEX_SPILL_BYTES; the rest is a few fixed buffers.
    bound = chunk_index.INDEX_SPILL_BYTES + 64 * 1024
    assert added * per_chunk_object > 4 * bound    # enough chunks that a leak would show
    assert grown < bound, f'{grown} B retained over {added} chunks'
    status = recorder.close()
    # Every chunk index, spilled or not, is in the summary an independent reader sees.
    with open(status['files'][0], 'rb') as stream:
        summary = make_reader(stream).get_summary()
    assert len(summary.chunk_indexes) == summary.statistics.chunk_count
    assert summary.statistics.chunk_count - 1 == added + before_chunks   # + the last, at close
    assert summary.statistics.message_count == 9_000 * len(topics)
    assert [i.chunk_start_offset for i in summary.chunk_indexes] == sorted(
        i.chunk_start_offset for i in summary.chunk_indexes)
    assert sorted(os.listdir(tmp_path)) == ['long.mcap']   # the temporary file is gone
    with open(status['files'][0], 'rb') as stream:
        assert sum(1 for _ in make_reader(stream).iter_messages()) == 9_000 * len(topics)
