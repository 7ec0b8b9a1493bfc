"""
Process set-up shared by the node, the driver, the tools and the tests; imports no rclpy.

Keeps ROS 2 traffic on this machine: the LOCALHOST discovery range, the shipped loopback
Fast DDS profile and a ROS domain unique to the run, set before anything initialises rclpy.
Also the executor and the spin that end cleanly on SIGINT/SIGTERM, and the heap trim after a
model build. The functions that need rclpy import it when called, so the tools and tests
that only isolate the environment (and the CLI, which imports this module at start) do not
load rclpy.
"""

import ctypes
import os
import pathlib
import sys
import time

from ament_index_python.packages import get_package_share_directory, PackageNotFoundError

DOMAIN_ID_RANGE = 100      # run-unique ROS_DOMAIN_ID in 1..100 (valid ids: 0-101)
FASTDDS_PROFILE = 'fastdds_localhost.xml'   # config/: every Fast DDS socket on 127.0.0.1


def fastdds_profile_path():
    """
    Find the shipped Fast DDS loopback profile: installed share directory, else source tree.

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


def make_executor():
    """Return an EventsExecutor where this rclpy has it (a 1 kHz timer needs its low overhead)."""
    try:
        from rclpy.experimental.events_executor import EventsExecutor
        return EventsExecutor()
    except ImportError:
        from rclpy.executors import SingleThreadedExecutor
        return SingleThreadedExecutor()


# rcl invalidates a context before rclpy's Context.ok() turns False: an rcl call in between
# fails with one of these (publish; spin_once building its wait set) while ok() says True.
INVALID_CONTEXT_TEXTS = ('context is invalid', 'context is not valid')


def is_shutdown_error(exc, context=None):
    """
    Tell whether ``exc`` is SIGINT/SIGTERM shutting ``context`` (default: rclpy's) down.

    True when the context is no longer ok, or when rcl already refused it as invalid (the
    race above); such an error is the shutdown asked for, not a failure to report.

    Parameters
    ----------
    exc : Exception
        The error an rcl call raised.
    context : rclpy.context.Context or None
        The context the call used (None: rclpy's default context).

    """
    import rclpy
    ok = context.ok() if context is not None else rclpy.ok()
    return not ok or any(text in str(exc) for text in INVALID_CONTEXT_TEXTS)


def spin_until_shutdown(executor, done=None, period_s=0.1):
    """
    Call ``spin_once`` until SIGINT/SIGTERM shuts the executor's context down (or ``done()``).

    A signal landing between the ``ok()`` check and the wait set that ``spin_once`` builds
    makes it raise (RCLError: the context is not valid): that is the shutdown asked for, not a
    failure. Any other error is raised.

    Parameters
    ----------
    executor : rclpy.executors.Executor
        With its nodes added.
    done : callable or None
        Returns True when spinning should end.
    period_s : float
        Longest wait of one ``spin_once`` [s].

    """
    context = executor.context
    while context.ok() and not (done is not None and done()):
        try:
            executor.spin_once(timeout_sec=period_s)
        except Exception as exc:
            if not is_shutdown_error(exc, context):
                raise
            return


def release_free_heap():
    """
    Give the heap freed after the precompute back to the OS (glibc; else nothing).

    Building the model allocates several times its size in temporaries; glibc keeps freed
    heap pages mapped, so without this the node's resident size stays at its build peak.
    """
    try:
        libc = ctypes.CDLL('libc.so.6')
        libc.malloc_trim(0)
    except (OSError, AttributeError):
        pass
