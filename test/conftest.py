"""Test-wide settings: keep every ROS process of this run on loopback, in its own domain."""

import os
import pathlib

import pytest

# Before anything imports rclpy: discovery on this machine only, and a domain id unique to
# this run (0-101 is the valid range; the pid spreads concurrent runs apart).
os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
os.environ.setdefault('ROS_DOMAIN_ID', str(1 + os.getpid() % 100))
os.environ.pop('ROS_LOCALHOST_ONLY', None)
os.environ.setdefault('MPLBACKEND', 'Agg')

REPO = pathlib.Path(__file__).resolve().parents[1]
CONFIG = REPO / 'config'


@pytest.fixture
def config_dir():
    """Path of the repository's config directory."""
    return CONFIG
