"""The recorder's MCAP writer: mcap's own layout, public APIs only, long files read by index."""

import ast
import io
import math
import pathlib
import re

import flexlink_ros
from flexlink_ros.io import chunk_index
from flexlink_ros.io.mcap_writer import McapFileWriter
from flexlink_ros.io.recorder import McapRecorder
from flexlink_ros.io.replay_writer import OUTPUT_ZSTD_LEVEL
from geometry_msgs.msg import Vector3Stamped
from mcap.reader import make_reader, NonSeekingReader, SeekingReader
from mcap.records import Chunk
from mcap.stream_reader import StreamReader
from mcap.writer import CompressionType, Writer
import numpy as np
import pytest
from rclpy.serialization import serialize_message
from rosbags.highlevel import AnyReader
import zstandard

T0_NS = 1_700_000_000_000_000_000
PACKAGE = pathlib.Path(flexlink_ros.__file__).parent
MANGLED = re.compile(r'\b_[A-Za-z][A-Za-z0-9]*__[A-Za-z0-9_]+')   # Python's _Class__name


def foreign_private_uses(path):
    """
    `file:line what` for each use of another object's private names.

    Name-mangled attributes (``_Writer__stream``), private names taken from another module
    (``from mcap.writer import _x``) and ``getattr``/``setattr``/``hasattr``/``delattr`` of a
    private name on anything but ``self``/``cls``.
    """
    source = path.read_text()
    found = [f'{path.name}:{source[:m.start()].count(chr(10)) + 1} {m.group()}'
             for m in MANGLED.finditer(source)]
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.ImportFrom) and node.level == 0:
            found += [f'{path.name}:{node.lineno} import {alias.name}' for alias in node.names
                      if alias.name.startswith('_')]
        elif (isinstance(node, ast.Call) and isinstance(node.func, ast.Name)
              and node.func.id in ('getattr', 'setattr', 'hasattr', 'delattr')
              and len(node.args) >= 2):
            owner, name = node.args[0], node.args[1]
            text = (name.value if isinstance(name, ast.Constant) else
                    name.values[0].value if isinstance(name, ast.JoinedStr) and name.values
                    and isinstance(name.values[0], ast.Constant) else '')
            own = isinstance(owner, ast.Name) and owner.id in ('self', 'cls')
            if isinstance(text, str) and text.startswith('_') and not own:
                found.append(f'{path.name}:{node.lineno} {node.func.id}(..., {text!r})')
    return found


def test_no_module_touches_private_state_of_another_library(tmp_path):
    modules = sorted(PACKAGE.rglob('*.py'))
    assert len(modules) > 20 and PACKAGE / 'io' / 'recorder.py' in modules
    found = [use for path in modules for use in foreign_private_uses(path)]
    assert found == []
    # The scan sees what it forbids (the old recorder's uses, in each form).
    sample = tmp_path / 'private_sample.py'
    sample.write_text("state = getattr(writer, f'_Writer__{name}')\n"
                      "setattr(writer, '_Writer__data_section_crc', 0)\n"
                      'stream = writer._Writer__stream\n'
                      'from mcap.writer import _private_helper\n'
                      "crc = getattr(self, '_own_crc')\n")
    lines = {int(use.split(':')[1].split()[0]) for use in foreign_private_uses(sample)}
    assert lines == {1, 2, 3, 4}


def vector_messages(count):
    messages = []
    for k in range(count):
        message = Vector3Stamped()
        message.header.stamp.sec, message.vector.x = k // 1000, k * 1e-3
        messages.append(serialize_message(message))
    return messages


def test_long_spilled_recording_is_read_by_index_and_by_rosbags(tmp_path):
    """3000+ chunks, chunk indexes spilled to disk: the seeking reader and rosbags see all."""
    topics = ['/a', '/b', '/c', '/d', '/e']
    per_topic = 9000
    payloads = vector_messages(per_topic)
    path = tmp_path / 'long.mcap'
    recorder = McapRecorder(path, chunk_size_bytes=1024, flush_thread=False)
    for topic in topics:
        recorder.add_topic(topic, 'geometry_msgs/msg/Vector3Stamped')
    recorder.open()
    for first in range(0, per_topic, 500):
        times = np.repeat(T0_NS + 1_000_000 * np.arange(first, first + 500), len(topics))
        recorder.write_batch(topics * 500, [p for p in payloads[first:first + 500]
                                            for _ in topics], times)
    store = recorder._file.writer.chunk_indexes
    assert len(store) >= 3000
    assert 0 < store.memory_bytes < chunk_index.INDEX_SPILL_BYTES   # the rest was spilled
    assert len(store) * 120 > chunk_index.INDEX_SPILL_BYTES   # 5-channel records: 127 B
    written = len(store)
    recorder.close()
    assert sorted(p.name for p in tmp_path.iterdir()) == ['long.mcap']

    with open(path, 'rb') as stream:
        reader = make_reader(stream, validate_crcs=True)
        assert isinstance(reader, SeekingReader)
        summary = reader.get_summary()
        statistics = summary.statistics
        assert len(summary.chunk_indexes) == statistics.chunk_count == written + 1
        assert statistics.message_count == per_topic * len(topics)
        ids = {channel.topic: channel.id for channel in summary.channels.values()}
        assert statistics.channel_message_counts == {ids[t]: per_topic for t in topics}
        read = {topic: [] for topic in topics}
        for _, channel, message in reader.iter_messages(log_time_order=False):
            read[channel.topic].append(message.data)
        assert read == {topic: payloads for topic in topics}
        # One topic through the per-channel message indexes, in a window of log time.
        window = list(reader.iter_messages(topics=['/c'], starting_at=T0_NS + 1_000_000_000,
                                           ending_before=T0_NS + 2_000_000_000))
        assert [m.data for _, _, m in window] == payloads[1000:2000]
    with open(path, 'rb') as stream:   # the data section CRC (Data End) checks out
        assert sum(1 for _ in NonSeekingReader(stream, validate_crcs=True).iter_messages()) \
            == statistics.message_count

    with AnyReader([path]) as reader:
        assert {c.topic: c.msgcount for c in reader.connections} == {
            topic: per_topic for topic in topics}
        rows = [(c.topic, raw) for c, _, raw in reader.messages()]
    assert len(rows) == statistics.message_count
    assert [raw for topic, raw in rows if topic == '/e'] == payloads


def write_schedule(writer, schedule):
    """Write one schedule of calls through `writer` (ours, or mcap's public Writer)."""
    ours = isinstance(writer, McapFileWriter)
    writer.start(profile='ros2', library='test')
    schema = writer.register_schema(name='geometry_msgs/msg/Vector3Stamped',
                                    encoding='ros2msg', data=b'# definition')
    channels = [writer.register_channel(topic=f'/t{k}', message_encoding='cdr',
                                        schema_id=schema, metadata={'k': str(k)})
                for k in range(3)]
    for kind, (channel, messages, log) in schedule:
        if kind == 'one' or not ours:
            for c, data, t in zip(channel.tolist(), messages, log.tolist()):
                writer.add_message(channels[c], t, data, t - 5, 0)
        else:
            assert writer.add_messages(np.asarray(channels, dtype=np.uint16)[channel],
                                       messages, log, log - 5, 10**18, None) == []
        if kind == 'flush':
            writer.flush()
    writer.finish()


def test_file_equals_mcap_public_writers_byte_for_byte(tmp_path, monkeypatch):
    """Single and bulk messages, spilled chunk indexes, both compressions: mcap's own file."""
    monkeypatch.setattr(chunk_index, 'INDEX_SPILL_BYTES', 4096)
    rng = np.random.default_rng(3)
    schedule = []
    for n in range(30):
        count = int(rng.integers(1, 400))
        log = T0_NS + np.sort(rng.integers(0, 10**9, size=count)) + n * 10**9
        channel = rng.integers(0, 3, size=count)
        messages = [bytes([n]) * int(s) for s in rng.integers(0, 300, size=count)]
        schedule.append((['one', 'many', 'flush'][n % 3], (channel, messages, log)))
    for compression, public in (('zstd', CompressionType.ZSTD), ('none', CompressionType.NONE)):
        expected, written = io.BytesIO(), io.BytesIO()
        write_schedule(Writer(expected, chunk_size=2048, compression=public,
                              enable_data_crcs=True), schedule)
        ours = McapFileWriter(written, chunk_size=2048, compression=compression,
                              spill_directory=tmp_path)
        write_schedule(ours, schedule)
        assert len(ours.chunk_indexes) * 60 > 4 * 4096     # spilled, several times
        assert written.getvalue() == expected.getvalue()
    assert list(tmp_path.iterdir()) == []   # the spill files are gone


@pytest.mark.parametrize('level', [1, OUTPUT_ZSTD_LEVEL])
def test_compression_level_is_the_chunks_zstd_level(tmp_path, level):
    """A recorder at a level writes each chunk as zstd compresses it there; readers read it."""
    path = tmp_path / 'fast.mcap'
    stamps = T0_NS + np.arange(3000) * 1_000_000
    messages = []
    for n, stamp in enumerate(stamps.tolist()):
        message = Vector3Stamped()
        message.header.stamp.sec, message.header.stamp.nanosec = divmod(stamp, 10**9)
        message.vector.x = math.sin(n * 0.01)
        messages.append(bytes(serialize_message(message)))
    with McapRecorder(path, flush_thread=False, compression_level=level) as recorder:
        recorder.add_topic('/v', Vector3Stamped)
        recorder.write_batch('/v', messages, stamps)
    chunks = 0
    with open(path, 'rb') as stream:
        for record in StreamReader(stream, emit_chunks=True).records:
            if isinstance(record, Chunk):
                data = zstandard.ZstdDecompressor().decompress(
                    record.data, max_output_size=record.uncompressed_size)
                assert record.data == zstandard.ZstdCompressor(level=level).compress(data)
                assert record.data != zstandard.ZstdCompressor(level=3).compress(data)
                chunks += 1
    assert chunks > 1
    with open(path, 'rb') as stream:
        read = [bytes(m.data) for _, _, m in make_reader(stream).iter_messages()]
    assert read == messages
    with AnyReader([path]) as reader:
        assert sum(1 for _ in reader.messages()) == len(messages)
