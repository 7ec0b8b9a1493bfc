"""packed_messages: a batch's records laid out in one buffer, as the messages one by one."""

import io

from flexlink_ros.io.mcap_writer import McapFileWriter
from flexlink_ros.io.packed_messages import FixedColumn, PackedMessages, VariableColumn
from flexlink_ros.io.recorder import McapRecorder
from mcap.reader import make_reader
import numpy as np
import pytest

T0_NS = 1_700_000_000_000_000_000


def random_batch(rng, samples, widths, variable_lengths, density=0.7):
    """
    Make a batch of columns (one variable column, then fixed ``widths``) and its messages.

    Returns the PackedMessages and, built without it, its messages in order: a list of bytes,
    per sample each column present in column order (the variable column first).
    """
    present = rng.uniform(size=(samples, 1 + len(widths))) < density
    messages, columns = [], []
    per_column = []
    for c in range(1 + len(widths)):
        count = int(present[:, c].sum())
        if c == 0:
            lengths = rng.choice(variable_lengths, size=count)
            data = [rng.integers(0, 256, n, dtype=np.uint8).tobytes() for n in lengths]
            columns.append(VariableColumn.from_sequence(data))
        else:
            rows = rng.integers(0, 256, (count, widths[c - 1]), dtype=np.uint8)
            data = [row.tobytes() for row in rows]
            columns.append(FixedColumn(rows))
        per_column.append(iter(data))
    for sample in range(samples):
        messages += [next(per_column[c]) for c in np.flatnonzero(present[sample])]
    return PackedMessages(columns, present), messages


@pytest.mark.parametrize('samples, variable_lengths, density', [
    (1, [5], 1.0),                 # one sample, every column
    (300, [40], 1.0),              # one kind: the buffer is one array's rows
    (300, [40], 0.6),              # kinds interleaved, inputs of one length
    (300, [0, 3, 40, 41], 0.6),    # inputs of several lengths, empty ones among them
    (50, [7], 0.0),                # no message at all
    (200, [7, 9], 0.05),           # mostly samples without messages
])
def test_records_are_each_header_then_its_message_in_order(samples, variable_lengths,
                                                           density):
    rng = np.random.default_rng(samples + len(variable_lengths))
    packed, messages = random_batch(rng, samples, [31, 8, 200], variable_lengths, density)
    assert len(packed) == len(messages)
    assert packed.lengths().tolist() == [len(m) for m in messages]
    assert packed.message_list() == messages
    assert [packed[k] for k in range(len(packed))] == messages
    headers = rng.integers(0, 256, (len(messages), 13), dtype=np.uint8)
    expected = b''.join(header.tobytes() + message
                        for header, message in zip(headers, messages))
    records = packed.records(headers)
    assert records.dtype == np.uint8 and records.tobytes() == expected


def test_one_message_is_its_header_then_its_bytes():
    packed = PackedMessages([FixedColumn(np.zeros((0, 4), dtype=np.uint8)),
                             VariableColumn.from_sequence([b'abc'])], [[False, True]])
    headers = np.array([[7, 8]], dtype=np.uint8)
    assert len(packed) == 1 and packed.records(headers).tobytes() == b'\x07\x08abc'
    assert packed.message_list() == [b'abc'] and packed.lengths().tolist() == [3]


def test_a_column_that_does_not_match_its_samples_is_refused():
    with pytest.raises(ValueError, match='column 1 holds 2 messages for 1 samples'):
        PackedMessages([VariableColumn.from_sequence([b'a', b'b']),
                        FixedColumn(np.zeros((2, 4), dtype=np.uint8))],
                       np.array([[True, True], [True, False]]))
    with pytest.raises(ValueError, match='sum to 3 bytes'):
        VariableColumn(np.zeros(4, dtype=np.uint8), [1, 2])


@pytest.mark.parametrize('chunk_size, flush_period_ns', [
    (1024, 10**12),          # chunks close inside each batch, after the message past the size
    (1 << 20, 40_000),       # flushes by log time inside each batch
    (1 << 20, 10**12),       # one chunk
])
def test_a_file_from_packed_messages_is_the_file_from_their_bytes(chunk_size, flush_period_ns):
    rng = np.random.default_rng(3)
    samples = 400
    packed, messages = random_batch(rng, samples, [31, 8, 200], [20, 24], 0.8)
    count = len(messages)
    channels = (packed.column_of + 1).astype(np.uint16)
    log = T0_NS + 1000 * np.repeat(np.arange(samples), packed.present.sum(axis=1))
    sequences = np.arange(1, count + 1, dtype=np.uint64)
    # The same messages as two PackedMessages of the samples before and after a cut.
    cut = samples // 2
    halves = {0: PackedMessages([column_part(column, packed.present[:cut, c], True)
                                 for c, column in enumerate(packed.columns)],
                                packed.present[:cut])}
    split = len(halves[0])
    halves[split] = PackedMessages([column_part(column, packed.present[:cut, c], False)
                                    for c, column in enumerate(packed.columns)],
                                   packed.present[cut:])

    def pieces(part):
        return halves[part.start]

    expected, expected_flushes = write_split(messages, channels, log, sequences, chunk_size,
                                             flush_period_ns, split)
    written, flushes = write_split(pieces, channels, log, sequences, chunk_size,
                                   flush_period_ns, split)
    assert written == expected and flushes == expected_flushes
    with io.BytesIO(written) as stream:
        read = [(channel.topic, m.log_time, m.publish_time, m.sequence, bytes(m.data))
                for _, channel, m in make_reader(stream).iter_messages(log_time_order=False)]
    topics = ['/a', '/b', '/c', '/d']
    assert read == [(topics[c], int(t), int(t) + 7, int(s), m) for c, t, s, m in zip(
        packed.column_of.tolist(), log.tolist(), sequences.tolist(), messages)]
    if chunk_size == 1024:
        assert written.count(b'zstd') > 10


def column_part(column, present, head):
    """Cut ``column`` at a sample: its messages before (``head``) or after the cut."""
    before = int(present.sum())
    if isinstance(column, FixedColumn):
        return FixedColumn(column.rows[:before] if head else column.rows[before:])
    chosen = range(before) if head else range(before, len(column))
    return VariableColumn.from_sequence([column.message(k) for k in chosen])


def write_split(messages, channels, log, sequences, chunk_size, flush_period_ns, split):
    """Write a file in two add_messages calls, the second from message ``split``."""
    stream = io.BytesIO()
    writer = McapFileWriter(stream, chunk_size=chunk_size, compression='zstd',
                            spill_directory='.')
    writer.start('ros2', 'test')
    for topic in ('/a', '/b', '/c', '/d'):
        writer.register_channel(topic, 'cdr', 0, {})
    flushes, last = [], None
    for part in (slice(0, split), slice(split, len(log))):
        batch = messages[part] if isinstance(messages, list) else messages(part)
        done = writer.add_messages(channels[part], batch, log[part], log[part] + 7,
                                   flush_period_ns, last, sequences[part])
        last = done[-1][1] if done else int(log[0])   # the first message starts the period
        flushes.append(done)
    writer.finish()
    return stream.getvalue(), flushes


def recorded(path):
    """(topic, log, publish, sequence, bytes) of every message of a recording, in order."""
    files = sorted(path.glob('*.mcap')) if path.is_dir() else [path]
    found = []
    for name in files:
        with open(name, 'rb') as stream:
            found += [(channel.topic, m.log_time, m.publish_time, m.sequence, bytes(m.data))
                      for _, channel, m in make_reader(stream).iter_messages(
                          log_time_order=False)]
    return found


@pytest.mark.parametrize('splits', [{}, {'split_duration_s': 0.1}])
def test_a_recorder_writes_packed_messages_as_their_bytes(tmp_path, splits):
    """In bulk, and one by one where a file split may fall inside the batch."""
    rng = np.random.default_rng(8)
    packed, messages = random_batch(rng, 300, [31, 200], [20, 24], 0.8)
    columns = ['/variable', '/fixed_a', '/fixed_b']
    per_sample = packed.present.sum(axis=1)
    log = T0_NS + 1_000_000 * np.repeat(np.arange(300), per_sample)
    written = {}
    for kind, batch, topics in (('packed', packed, columns),
                                ('bytes', messages, [columns[c] for c in packed.column_of])):
        path = tmp_path / kind if splits else tmp_path / f'{kind}.mcap'
        with McapRecorder(path, flush_thread=False, **splits) as recorder:
            for topic in columns:
                recorder.add_topic(topic, 'std_msgs/msg/String')
            assert recorder.write_batch(topics, batch, log, log - 5) == len(messages)
        written[kind] = recorded(path)
    assert written['packed'] == written['bytes']
    sequences = dict.fromkeys(columns, 0)
    expected = []
    for c, time, message in zip(packed.column_of.tolist(), log.tolist(), messages):
        sequences[columns[c]] += 1
        expected.append((columns[c], time, time - 5, sequences[columns[c]], message))
    assert written['packed'] == expected
    if splits:
        assert len(list((tmp_path / 'packed').glob('*.mcap'))) == 3
    with pytest.raises(ValueError, match='`topics` has 2 entries for 3 columns'):
        McapRecorder(tmp_path / 'refused.mcap').write_batch(columns[:2], packed, log)
