"""bag_index: a bag directory's files, their intact messages and merged topics."""

from flexlink_ros.io import bag_index
from mcap.reader import make_reader


def test_bag_files_are_the_numbered_files_of_the_directory(split_bag, tmp_path):
    files = bag_index.bag_files(split_bag)
    assert [f.name for f in files] == [f'run_{n}.mcap' for n in range(len(files))]
    assert len(files) > 10
    # A stray MCAP file, a link and a directory named like a bag file are not part of it.
    stray = tmp_path / 'run'
    stray.mkdir()
    (stray / 'other.mcap').write_bytes(files[0].read_bytes())
    (stray / 'run_0.mcap').write_bytes(files[0].read_bytes())
    (stray / 'run_1.mcap').symlink_to(files[1])
    (stray / 'run_2.mcap').mkdir()
    assert bag_index.bag_files(stray) == [stray / 'run_0.mcap']


def test_scans_and_topics_agree_with_the_mcap_summaries(split_bag):
    scans = [bag_index.scan_bag_file(path) for path in bag_index.bag_files(split_bag)]
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
