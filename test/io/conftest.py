"""Fixtures of the io tests."""

import os
import shutil
import subprocess

from flexlink_ros.io.recorder import McapRecorder
import pytest
from recorder_helpers import sample_messages, STEP_NS, T0_NS


@pytest.fixture
def tiny_tmpfs(tmp_path):
    """Mount a 256 KiB tmpfs (needs mount rights; skipped without them)."""
    mount_point = tmp_path / 'tiny'
    mount_point.mkdir()
    if shutil.which('mount') is None or os.geteuid() != 0:
        pytest.skip('mounting a tmpfs needs root')
    result = subprocess.run(['mount', '-t', 'tmpfs', '-o', 'size=256k', 'tmpfs', str(mount_point)],
                            capture_output=True)
    if result.returncode != 0:
        pytest.skip(f'cannot mount tmpfs: {result.stderr.decode().strip()}')
    yield mount_point
    subprocess.run(['umount', str(mount_point)], check=True)


@pytest.fixture(scope='module')
def split_bag(tmp_path_factory):
    """Record a bag directory split by duration into more than ten files (run_0 ... run_12)."""
    bag = tmp_path_factory.mktemp('split') / 'run'
    with McapRecorder(bag, split_duration_s=0.01) as recorder:
        for k in range(125):
            messages = sample_messages(k)
            for topic in ('/joint_states', '/deflection'):
                recorder.write(topic, messages[topic], T0_NS + k * STEP_NS)
    return bag
