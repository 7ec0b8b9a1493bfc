"""Test-wide settings: keep every ROS process of this run on loopback, in its own domain."""

import os
import pathlib

from flexlink_ros.ros.runtime import isolate_ros_environment   # imports no rclpy
import pytest

# Before anything imports rclpy: discovery on this machine only, Fast DDS listening on
# 127.0.0.1 only (config/fastdds_localhost.xml; FLEXLINK_LOOPBACK_SOCKETS=1 puts its send
# sockets there too), and a domain id unique to this run (also when the shell has one set),
# inherited by every process a test starts.
isolate_ros_environment()
os.environ.setdefault('MPLBACKEND', 'Agg')

REPO = pathlib.Path(__file__).resolve().parents[1]
CONFIG = REPO / 'config'


@pytest.fixture
def config_dir():
    """Path of the repository's config directory."""
    return CONFIG


@pytest.fixture
def processes():
    """Every process a test starts, killed at the end whatever happens."""
    started = []
    try:
        yield started
    finally:
        for item in started:
            process = getattr(item, 'process', item)
            if process.poll() is None:
                process.kill()
                process.wait()
            if hasattr(item, 'log_file'):
                item.log_file.close()
