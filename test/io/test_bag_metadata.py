"""bag_metadata: a metadata.yaml written from the files' scans, read back by rosbags."""

from flexlink_ros.io import bag_index
from flexlink_ros.io.bag_files import bag_files
from flexlink_ros.io.bag_metadata import write_bag_metadata
from recorder_helpers import STEP_NS, T0_NS
from rosbags.rosbag2 import Reader
import yaml


def test_metadata_yaml_is_read_by_rosbags_with_the_counts_and_times(split_bag, tmp_path):
    bag = tmp_path / 'run'
    bag.mkdir()
    # The files, without the recorder's yaml.
    for path in bag_files(split_bag, rosbag2_names=True):
        (bag / path.name).write_bytes(path.read_bytes())
    files = [bag_index.scan_bag_file(path) for path in bag_files(bag, rosbag2_names=True)]
    write_bag_metadata(bag, files, bag_index.bag_topics(files))
    with Reader(bag) as reader:
        assert reader.message_count == 2 * 125
        assert reader.start_time == T0_NS
        assert reader.end_time == T0_NS + 124 * STEP_NS + 1     # rosbags: end is exclusive
        assert {c.topic: c.msgcount for c in reader.connections} == \
            {'/joint_states': 125, '/deflection': 125}
        assert {c.topic: c.msgtype for c in reader.connections} == \
            {'/joint_states': 'sensor_msgs/msg/JointState',
             '/deflection': 'geometry_msgs/msg/Vector3Stamped'}
        assert sum(1 for _ in reader.messages()) == 2 * 125
    info = yaml.safe_load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    assert info['relative_file_paths'] == [f['path'].name for f in files]
    assert [f['message_count'] for f in info['files']] == [f['message_count'] for f in files]
    # The same bag information as the recorder wrote when it closed the bag.
    assert (bag / 'metadata.yaml').read_text() == (split_bag / 'metadata.yaml').read_text()
