"""recording: the files of a bag directory in split order, their messages file by file."""

from flexlink_ros.io import recording
import pytest
from recorder_helpers import STEP_NS, T0_NS
from rosbags.highlevel import AnyReader


def test_bag_directory_files_are_listed_in_split_order(split_bag):
    files = recording.recording_files(split_bag)
    assert len(files) > 10      # run_10 must come after run_9, not after run_1
    assert [f.name for f in files] == [f'run_{n}.mcap' for n in range(len(files))]
    single = files[3]
    assert recording.recording_files(single) == [single]


def test_messages_come_file_by_file_as_rosbags_reads_them(split_bag):
    mine = [(topic, log, data) for topic, _, log, _, data in recording.iter_recording(split_bag)]
    with AnyReader([split_bag]) as reader:
        theirs = [(c.topic, log, data) for c, log, data in reader.messages()]
    assert mine == theirs and len(mine) == 2 * 125
    assert [log for topic, log, _ in mine if topic == '/joint_states'] == \
        [T0_NS + k * STEP_NS for k in range(125)]
    only = list(recording.iter_recording(split_bag, topics={'/deflection'}))
    assert {(topic, type_name) for topic, type_name, *_ in only} == \
        {('/deflection', 'geometry_msgs/msg/Vector3Stamped')}


def test_a_missing_path_or_an_empty_directory_is_refused(tmp_path):
    with pytest.raises(ValueError, match='no such file'):
        recording.recording_files(tmp_path / 'absent.mcap')
    with pytest.raises(ValueError, match='no .mcap files'):
        recording.recording_files(tmp_path)
