"""bag_index: the intact messages of a bag directory's files and their merged topics."""

from flexlink_ros.io import bag_index
from flexlink_ros.io.bag_files import bag_files
from mcap.reader import make_reader


def test_scans_and_topics_agree_with_the_mcap_summaries(split_bag):
    scans = [bag_index.scan_bag_file(path) for path in bag_files(split_bag, rosbag2_names=True)]
    total = {}
    for scan in scans:
        with open(scan['path'], 'rb') as stream:
            summary = make_reader(stream).get_summary()
        assert scan['complete'] and scan['damaged_count'] == 0
        assert scan['message_count'] == summary.statistics.message_count
        assert scan['first_log_ns'] == summary.statistics.message_start_time
        assert scan['last_log_ns'] == summary.statistics.message_end_time
        for channel_id, count in summary.statistics.channel_message_counts.items():
            topic = summary.channels[channel_id].topic
            total[topic] = total.get(topic, 0) + count
    topics = bag_index.bag_topics(scans)
    assert list(topics) == ['/joint_states', '/deflection']
    assert {name: t.message_count for name, t in topics.items()} == total == \
        {'/joint_states': 125, '/deflection': 125}
    assert topics['/joint_states'].type_name == 'sensor_msgs/msg/JointState'
    assert topics['/joint_states'].type_hash.startswith('RIHS01_')
    assert topics['/deflection'].qos_profiles[0]['reliability'] == 'reliable'
