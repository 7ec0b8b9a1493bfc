"""Fixtures of the io tests."""

import os
import shutil
import subprocess

import pytest


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
