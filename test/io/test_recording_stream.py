"""recording_stream: a recording's topics surveyed and one topic read in bounded blocks."""

from flexlink_ros.io import joint_states, recording_stream
from flexlink_ros.io import recording as io_recording
from flexlink_ros.io.recorder import McapRecorder
from flexlink_ros.names import JOINT_STATE
from flexlink_ros.ros import messages as ros_messages
from mcap.reader import make_reader
import numpy as np
from rclpy.serialization import serialize_message
from sensor_msgs.msg import JointState
from test_mcap_reader import chunks_of, damaged_copy

T0_NS = 1_700_000_000_000_000_000


def crank_state(k, joint='crank'):
    message = JointState(name=[joint], position=[0.04 * k], velocity=[40.0])
    message.header.stamp = ros_messages.ns_to_stamp(T0_NS + k * 1_000_000)
    return bytes(serialize_message(message))


def write_bag(path, count, split_s=0.0):
    """/joint_states (crank) interleaved with /other_states (wheel), in split files or one."""
    with McapRecorder(path, chunk_size_bytes=4096, split_duration_s=split_s) as recorder:
        recorder.add_topic('/joint_states', JointState)
        recorder.add_topic('/other_states', JointState)
        for k in range(count):
            log_ns = T0_NS + k * 1_000_000 + 200_000
            recorder.write('/joint_states', crank_state(k), log_ns, log_ns - 7)
            if k % 3 == 0:
                recorder.write('/other_states', crank_state(k, 'wheel'), log_ns + 1)
    return path


def every_message(path, topic):
    """(log, publish, bytes) of a topic's messages, from mcap's own reader."""
    found = []
    for file in sorted(path.glob('*.mcap')) if path.is_dir() else [path]:
        with open(file, 'rb') as stream:
            found += [(m.log_time, m.publish_time, bytes(m.data)) for _, channel, m in
                      make_reader(stream).iter_messages(log_time_order=False)
                      if channel.topic == topic]
    return found


def test_a_topic_is_read_in_blocks_of_at_most_the_given_count(tmp_path):
    bag = write_bag(tmp_path / 'split', 2500, split_s=0.4)
    assert len(list(bag.glob('*.mcap'))) > 3
    blocks = list(recording_stream.iter_topic_messages(bag, '/joint_states', block=333))
    assert [len(data) for _, _, data in blocks] == [333] * 7 + [2500 - 7 * 333]
    read = [(log, publish, data) for block in blocks for log, publish, data in zip(
        block[0].tolist(), block[1].tolist(), block[2])]
    assert read == every_message(bag, '/joint_states')
    assert all(block[0].dtype == np.int64 and block[1].dtype == np.int64 for block in blocks)


def test_the_survey_counts_every_topic_and_keeps_only_the_first_messages(tmp_path):
    bag = write_bag(tmp_path / 'one.mcap', 2500)
    counts, kept = recording_stream.survey_recording(bag)
    assert counts == io_recording.scan_recording(bag)[0] == {
        '/joint_states': [JOINT_STATE, 2500], '/other_states': [JOINT_STATE, 834]}
    probe = io_recording.JOINT_PROBE_MESSAGES
    assert kept['/joint_states'] == every_message(bag, '/joint_states')[:probe]
    assert kept['/other_states'] == every_message(bag, '/other_states')[:probe]
    assert io_recording.choose_input_topic(bag, 'crank', None, (counts, kept)) == '/joint_states'
    assert io_recording.choose_input_topic(bag, 'wheel', None, (counts, kept)) == '/other_states'
    assert recording_stream.survey_recording(bag, topic='/joint_states') == (counts, {})


def test_a_damaged_chunk_is_skipped_and_listed_once_by_each_pass(tmp_path):
    bag = write_bag(tmp_path / 'one.mcap', 2500)
    offset = chunks_of(bag)[3][0]

    def break_crc(data):
        data[offset + 9 + 24] ^= 0xFF       # the chunk's uncompressed CRC
    bad = damaged_copy(bag, tmp_path, break_crc)
    damaged, streamed = [], []
    counts, _ = recording_stream.survey_recording(bad, damaged=damaged)
    reference = []
    assert counts == io_recording.scan_recording(bad, damaged=reference)[0]
    assert damaged == reference and [o for _, o, _ in damaged] == [offset]
    samples = list(joint_states.iter_crank_samples(bad, '/joint_states', 'crank', block=1000,
                                                   damaged=streamed))
    assert streamed == damaged
    stamps = np.concatenate([s['stamps_ns'] for s in samples])
    whole = joint_states.read_crank_samples(bad, '/joint_states', 'crank')
    np.testing.assert_array_equal(stamps, whole['stamps_ns'])
    assert stamps.size == counts['/joint_states'][1] < 2500


def test_the_summaries_survey_as_a_whole_pass_does(tmp_path):
    """One file and a split bag: the same counts and first messages from the summaries."""
    for bag in (write_bag(tmp_path / 'one.mcap', 2500),
                write_bag(tmp_path / 'split', 2500, split_s=0.4)):
        whole = recording_stream.survey_recording(bag)
        assert recording_stream.survey_summaries(bag) == whole
        assert recording_stream.survey_summaries(bag, topic='/other_states') == (whole[0], {})


def test_the_summaries_survey_reads_no_chunk_past_the_first_messages(tmp_path):
    """A damaged late chunk is neither read nor listed (the reading lists it), yet counted."""
    bag = write_bag(tmp_path / 'one.mcap', 5000)
    offset = chunks_of(bag)[-2][0]

    def break_crc(data):
        data[offset + 9 + 24] ^= 0xFF       # the chunk's uncompressed CRC
    bad = damaged_copy(bag, tmp_path, break_crc)
    counts, kept = recording_stream.survey_summaries(bad)
    assert counts == {'/joint_states': [JOINT_STATE, 5000], '/other_states': [JOINT_STATE, 1667]}
    assert kept == recording_stream.survey_recording(bag)[1]
    damaged = []
    assert recording_stream.survey_recording(bad, damaged=damaged)[0] != counts
    assert [o for _, o, _ in damaged] == [offset]


def test_a_file_without_a_summary_is_surveyed_whole(tmp_path):
    """A file cut before its summary, or a bag with one such file: no summaries survey."""
    bag = write_bag(tmp_path / 'split', 2500, split_s=0.4)
    last = sorted(bag.glob('*.mcap'))[-1]
    data = last.read_bytes()
    last.write_bytes(data[:len(data) - 200])
    assert recording_stream.survey_summaries(bag) is None
    assert recording_stream.survey_summaries(last) is None
