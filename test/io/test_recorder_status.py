"""recorder_status: counts and sizes without a look at every file, the paths when asked."""

import os

from flexlink_ros.io.recorder import McapRecorder
from recorder_helpers import T0_NS


def test_status_counts_files_and_bytes_and_lists_paths_only_when_asked(tmp_path):
    bag = tmp_path / 'bag'
    with McapRecorder(bag, split_size_bytes=1, flush_thread=False) as recorder:
        recorder.add_topic('/a', 'sensor_msgs/msg/JointState')
        for k in range(5):      # one message per file
            recorder.write('/a', b'\x00\x01\x00\x00' + bytes(40), T0_NS + k)
        light = recorder.status(list_files=False)
        assert 'files' not in light and light['file_count'] == 5
        assert light['message_count'] == 5 and light['dropped_count'] == 0
    status = recorder.status()
    assert status['files'] == [str(bag / f'bag_{n}.mcap') for n in range(5)]
    assert status['bytes_written'] == sum(os.stat(p).st_size for p in status['files'])
    assert status['state'] == 'closed' and status['queued_bytes'] == 0
