"""The recorder's rosbag2 metadata records and sequence numbers, read back by the mcap library."""

import pathlib

from flexlink_ros.io.bag_metadata import UNSET_NS
from flexlink_ros.io.mcap_writer import McapFileWriter
from flexlink_ros.io.recorder import McapRecorder
from geometry_msgs.msg import Vector3Stamped
from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer
import numpy as np
import pytest
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rosbags.interfaces import QosDurability, QosReliability
from rosbags.rosbag2 import Reader
from sensor_msgs.msg import JointState
import yaml

T0_NS = 1_700_000_000_000_000_000


def read_file(path):
    """(rosbag2 metadata records as dicts, {topic: [sequence, ...]}, summary) of one file."""
    with open(path, 'rb') as stream:
        reader = make_reader(stream)
        records = [(m.name, m.metadata) for m in reader.iter_metadata()]
        summary = reader.get_summary()
        sequences = {}
        for _, channel, message in reader.iter_messages(log_time_order=False):
            sequences.setdefault(channel.topic, []).append(message.sequence)
    assert all(name == 'rosbag2' and list(data) == ['serialized_metadata']
               for name, data in records)
    return [yaml.safe_load(data['serialized_metadata']) for _, data in records], sequences, \
        summary


@pytest.mark.parametrize('batched', [False, True])
def test_metadata_record_at_open_and_close_and_sequences_per_topic(tmp_path, batched):
    bag = tmp_path / 'bag'
    recorder = McapRecorder(bag, split_duration_s=1.0, flush_thread=False)
    recorder.open()
    recorder.add_topic('/a', JointState)
    recorder.add_topic('/b', Vector3Stamped)
    count = 2500
    topics = ['/b' if k % 4 == 0 else '/a' for k in range(count)]
    data = [b'\x00\x01\x00\x00' + bytes(40)] * count
    log = T0_NS + np.arange(count, dtype=np.int64) * 1_000_000
    if batched:
        recorder.write_batch(topics, data, log)
    else:
        for k in range(count):
            recorder.write(topics[k], data[k], int(log[k]))
    status = recorder.close()
    files = [pathlib.Path(f) for f in status['files']]
    assert len(files) == 3
    final = yaml.safe_load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    sequences = {'/a': [], '/b': []}
    for n, path in enumerate(files):
        (opening, closing), numbers, summary = read_file(path)
        assert summary.statistics.metadata_count == 2 and len(summary.metadata_indexes) == 2
        # Each file's records describe that file alone (a split costs the same at any n):
        # at open without messages yet (rosbag2's "unset" start), at close complete.
        assert opening['relative_file_paths'] == closing['relative_file_paths'] == [path.name]
        assert opening['files'] == [{'path': path.name,
                                     'starting_time': {'nanoseconds_since_epoch': UNSET_NS},
                                     'duration': {'nanoseconds': 0}, 'message_count': 0}]
        assert opening['message_count'] == 0
        assert closing['files'][0]['message_count'] == summary.statistics.message_count > 0
        assert closing['message_count'] == summary.statistics.message_count
        assert {t['topic_metadata']['name']: t['message_count']
                for t in closing['topics_with_message_count']} == {
            summary.channels[c].topic: count
            for c, count in summary.statistics.channel_message_counts.items()}
        for topic, values in numbers.items():
            sequences[topic] += values
    assert closing['topics_with_message_count'][0]['topic_metadata'] == final[
        'topics_with_message_count'][0]['topic_metadata']
    assert final['relative_file_paths'] == [f.name for f in files]
    assert list(final) == ['version', 'storage_identifier', 'duration', 'starting_time',
                           'message_count', 'topics_with_message_count', 'compression_format',
                           'compression_mode', 'relative_file_paths', 'files', 'custom_data',
                           'ros_distro']
    # Sequence numbers count each topic's messages over the whole recording, across files.
    assert sequences == {'/a': list(range(1, 1876)), '/b': list(range(1, 626))}


def test_given_sequence_numbers_are_kept_modulo_two_to_the_32(tmp_path):
    path = tmp_path / 'one.mcap'
    with McapRecorder(path) as recorder:
        for k, sequence in enumerate([7, 2**32 + 3, None]):
            recorder.write('/a', JointState(), T0_NS + k, sequence=sequence)
    records, sequences, _ = read_file(path)
    assert sequences == {'/a': [7, 3, 3]}   # None: the topic's own count (third message)
    assert [r['message_count'] for r in records] == [0, 3]


def test_metadata_records_are_written_as_the_mcap_writer_writes_them(tmp_path):
    """Byte for byte what mcap.writer.Writer.add_metadata gives, mid-chunk included."""
    outputs = []
    for kind in ('reference', 'ours'):
        path = tmp_path / f'{kind}.mcap'
        with open(path, 'wb') as stream:
            if kind == 'reference':
                writer = Writer(stream, chunk_size=300, compression=CompressionType.ZSTD,
                                enable_data_crcs=True)
            else:
                writer = McapFileWriter(stream, chunk_size=300, compression='zstd',
                                        spill_directory=tmp_path)
            writer.start(profile='ros2', library='test')
            writer.add_metadata('rosbag2', {'serialized_metadata': 'version: 9\n'})
            schema = writer.register_schema(name='s', encoding='ros2msg', data=b'int8 x')
            channel = writer.register_channel(topic='/t', message_encoding='cdr',
                                              schema_id=schema, metadata={})
            for k in range(40):
                writer.add_message(channel, log_time=k, data=bytes(k), publish_time=k,
                                   sequence=k + 1)
                if k == 17:
                    writer.add_metadata('rosbag2', {'serialized_metadata': f'k: {k}\n'})
            writer.finish()
        outputs.append(path.read_bytes())
    assert outputs[0] == outputs[1]


def test_offered_qos_given_when_the_first_message_comes_reaches_rosbags(tmp_path):
    """A topic declared while recording (the node on its first input) keeps its offered QoS."""
    bag = tmp_path / 'qos'
    offered = [QoSProfile(depth=5, reliability=ReliabilityPolicy.BEST_EFFORT,
                          durability=DurabilityPolicy.TRANSIENT_LOCAL),
               QoSProfile(depth=1000)]
    with McapRecorder(bag) as recorder:
        recorder.write('/out', Vector3Stamped(), T0_NS)
        recorder.add_topic('/in', JointState, qos_profiles=offered)
        recorder.write('/in', JointState(name=['crank']), T0_NS + 1)
    with Reader(bag) as reader:
        profiles = {c.topic: c.ext.offered_qos_profiles for c in reader.connections}
        assert sum(1 for _ in reader.messages()) == 2
    assert [(p.reliability, p.durability, p.depth) for p in profiles['/in']] == [
        (QosReliability.BEST_EFFORT, QosDurability.TRANSIENT_LOCAL, 5),
        (QosReliability.RELIABLE, QosDurability.VOLATILE, 1000)]
    _, _, summary = read_file(bag / 'qos_0.mcap')
    (channel,) = [c for c in summary.channels.values() if c.topic == '/in']
    assert yaml.safe_load(channel.metadata['offered_qos_profiles'])[0]['depth'] == 5


def test_a_split_costs_the_same_whatever_the_number_of_files_before(tmp_path):
    """The rosbag2 records of file 300 are as long as those of file 1: no list of every file."""
    bag = tmp_path / 'many'
    with McapRecorder(bag, split_size_bytes=1, flush_thread=False) as recorder:
        recorder.add_topic('/a', JointState)
        for k in range(300):      # one message per file
            recorder.write('/a', b'\x00\x01\x00\x00' + bytes(40), T0_NS + k * 1_000_000)
    sizes = []
    for n in (1, 299):
        path = bag / f'many_{n}.mcap'
        with open(path, 'rb') as stream:
            records = [m.metadata['serialized_metadata']
                       for m in make_reader(stream).iter_metadata()]
        assert [yaml.safe_load(r)['relative_file_paths'] for r in records] == [[path.name]] * 2
        sizes.append([len(r) for r in records])
    # Only the file's name and times differ (a list of every file would add ~100 B each).
    assert all(abs(late - early) < 20 for early, late in zip(*sizes))
    final = yaml.safe_load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    assert len(final['files']) == 300 and final['message_count'] == 300
