"""bag_files: only regular files inside the bag; FIFOs, devices and links out are skipped."""

import os

from flexlink_ros.io.bag_files import bag_files
from flexlink_ros.io.recorder import McapRecorder
from hostile_bag import plant_hostile_entries
from recorder_helpers import sample_messages, STEP_NS, T0_NS


def record(bag, count=50):
    """Record a small bag directory; return its one file."""
    with McapRecorder(bag) as recorder:
        for k in range(count):
            recorder.write('/joint_states', sample_messages(k)['/joint_states'],
                           T0_NS + k * STEP_NS)
    return bag / f'{bag.name}_0.mcap'


def test_only_regular_files_inside_the_bag_are_taken_each_other_entry_said(tmp_path):
    bag = tmp_path / 'bag'
    first = record(bag)
    outside = record(tmp_path / 'elsewhere')
    planted = plant_hostile_entries(bag, outside)
    (bag / 'kept').mkdir()
    os.replace(record(tmp_path / 'second'), bag / 'kept' / 'second.data')
    os.symlink('kept/second.data', bag / 'bag_1.mcap')     # a link that stays inside: taken
    os.symlink('bag_0.mcap', bag / 'bag_2.mcap')           # the same file again: once
    skipped = []
    files = bag_files(bag, skipped)
    assert files == [first, (bag / 'bag_1.mcap').resolve()]
    assert sorted(path.name for path, _ in skipped) == sorted(planted + ['bag_2.mcap'])
    reasons = {path.name: reason for path, reason in skipped}
    assert 'FIFO' in reasons['fifo_2.mcap'] and 'outside the bag' in reasons['out_3.mcap']
    assert 'outside the bag' in reasons['zero_4.mcap'] and 'directory' in reasons['dir_5.mcap']
    assert 'same file' in reasons['bag_2.mcap']
    # reindex takes the rosbag2 names only: bag_<N>.mcap
    assert bag_files(bag, [], rosbag2_names=True) == files


def test_bag_files_are_the_numbered_files_of_the_directory(split_bag, tmp_path):
    files = bag_files(split_bag, rosbag2_names=True)
    assert [f.name for f in files] == [f'run_{n}.mcap' for n in range(len(files))]
    assert len(files) > 10
    # A stray MCAP file, a link out of the bag and a directory named like a bag file are not
    # part of it.
    stray = tmp_path / 'run'
    stray.mkdir()
    (stray / 'other.mcap').write_bytes(files[0].read_bytes())
    (stray / 'run_0.mcap').write_bytes(files[0].read_bytes())
    (stray / 'run_1.mcap').symlink_to(files[1])
    (stray / 'run_2.mcap').mkdir()
    assert bag_files(stray, rosbag2_names=True) == [stray / 'run_0.mcap']
