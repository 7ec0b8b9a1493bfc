"""
Process set-up shared by the node, the driver, the tools and the tests; imports no rclpy.

Keeps ROS 2 traffic on this machine: the LOCALHOST discovery range, the shipped loopback
Fast DDS profile and a ROS domain unique to the run, set before anything initialises rclpy.
"""

import os
import pathlib
import sys
import time

from ament_index_python.packages import get_package_share_directory, PackageNotFoundError

DOMAIN_ID_RANGE = 100      # run-unique ROS_DOMAIN_ID in 1..100 (valid ids: 0-101)
FASTDDS_PROFILE = 'fastdds_localhost.xml'   # config/: every Fast DDS socket on 127.0.0.1


def fastdds_profile_path():
    """
    The shipped Fast DDS loopback profile: installed share directory, else the source tree.

    Returns
    -------
    pathlib.Path or None
        None if neither holds ``config/fastdds_localhost.xml``.

    """
    candidates = [pathlib.Path(sys.prefix) / 'share' / 'flexlink_ros' / 'config',
                  pathlib.Path(__file__).resolve().parents[2] / 'config']
    try:
        candidates.insert(0, pathlib.Path(get_package_share_directory('flexlink_ros'))
                          / 'config')
    except (PackageNotFoundError, ValueError, OSError):   # not installed: prefix, source tree
        pass
    for directory in candidates:
        if (directory / FASTDDS_PROFILE).is_file():
            return directory / FASTDDS_PROFILE
    return None


def isolate_ros_environment(env=None, loopback_sockets=None):
    """
    Keep ROS 2 traffic on this machine, in a domain unique to this run.

    Sets ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``, a run-unique ``ROS_DOMAIN_ID`` and
    ``FASTDDS_DEFAULT_PROFILES_FILE`` to the shipped loopback profile (UDPv4 on 127.0.0.1 and
    shared memory): every socket Fast DDS listens on is then bound to 127.0.0.1. With the
    LOCALHOST range the ROS middleware (rmw_fastrtps) adds a UDP transport of its own whose
    send sockets still bind 0.0.0.0 and the external address (it sends to 127.0.0.1 only).
    ``loopback_sockets`` (or ``FLEXLINK_LOOPBACK_SOCKETS=1``) with the profile found selects
    the ``SYSTEM_DEFAULT`` range instead, so the profile alone configures Fast DDS: discovery
    by unicast to 127.0.0.1 and every socket on loopback. Without the profile the range
    stays LOCALHOST.

    Parameters
    ----------
    env : dict or None
        Environment to change (default ``os.environ``).
    loopback_sockets : bool or None
        Every socket on loopback (see above); None reads ``FLEXLINK_LOOPBACK_SOCKETS``.

    Returns
    -------
    int
        The ROS_DOMAIN_ID chosen.

    """
    env = os.environ if env is None else env
    if loopback_sockets is None:
        loopback_sockets = env.get('FLEXLINK_LOOPBACK_SOCKETS', '') == '1'
    profile = fastdds_profile_path()
    env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    if profile is not None:
        env['FASTDDS_DEFAULT_PROFILES_FILE'] = str(profile)
        if loopback_sockets:
            env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'SYSTEM_DEFAULT'
    env.pop('ROS_LOCALHOST_ONLY', None)   # ignored by kilted; LOCALHOST range is what counts
    domain = 1 + (os.getpid() + time.time_ns() // 1_000_000) % DOMAIN_ID_RANGE
    env['ROS_DOMAIN_ID'] = str(domain)
    return domain
