"""The shipped Fast DDS profile: real rclpy processes, their UDP sockets read from /proc."""

import os
import pathlib
import socket
import struct
import subprocess
import sys
import xml.etree.ElementTree as ElementTree

from flexlink_ros.ros import runtime

READY_TIMEOUT_S = 30.0
RECEIVE_TIMEOUT_S = 20.0   # discovery on loopback takes 0-3 s; a loaded CI machine more
RTPS_PORT_BASE, RTPS_DOMAIN_GAIN, RTPS_DOMAIN_PORTS = 7400, 250, 250   # RTPS 9.6.1.1

# A publisher and a subscriber in one process would talk in-process: use two processes.
TALKER = """
import sys, time, rclpy
from std_msgs.msg import String
rclpy.init()
node = rclpy.create_node('profile_talker')
publisher = node.create_publisher(String, 'profile_check', 10)
print('ready', flush=True)
end = time.monotonic() + float(sys.argv[1])
while time.monotonic() < end:
    publisher.publish(String(data='over loopback'))
    rclpy.spin_once(node, timeout_sec=0.05)
rclpy.shutdown()
"""
LISTENER = """
import sys, time, rclpy
from std_msgs.msg import String
rclpy.init()
node = rclpy.create_node('profile_listener')
received = []
node.create_subscription(String, 'profile_check', lambda m: received.append(m.data), 10)
end = time.monotonic() + float(sys.argv[1])
while time.monotonic() < end and not received:
    rclpy.spin_once(node, timeout_sec=0.05)
print('received', received[:1], flush=True)
rclpy.shutdown()
"""


def _address(hex_text):
    """'0100007F:1F90' (or a 32-digit IPv6 address) from /proc/net/udp* -> (ip, port)."""
    host, port = hex_text.split(':')
    raw = bytes.fromhex(host)
    words = struct.unpack(f'<{len(raw) // 4}I', raw)   # the kernel prints 32-bit words
    packed = struct.pack(f'>{len(words)}I', *words)
    family = socket.AF_INET if len(packed) == 4 else socket.AF_INET6
    return socket.inet_ntop(family, packed), int(port, 16)


def udp_sockets_of(pid):
    """Local (ip, port) of every UDP socket the process holds (its fds mapped to inodes)."""
    inodes = set()
    for fd in pathlib.Path(f'/proc/{pid}/fd').iterdir():
        try:
            target = os.readlink(fd)
        except OSError:
            continue
        if target.startswith('socket:['):
            inodes.add(target[8:-1])
    found = []
    for table in ('udp', 'udp6'):
        lines = pathlib.Path(f'/proc/{pid}/net/{table}').read_text().splitlines()[1:]
        for line in lines:
            fields = line.split()
            if fields[9] in inodes:
                found.append(_address(fields[1]))
    return found


def is_loopback(ip):
    return ip.startswith('127.') or ip in ('::1', '::ffff:127.0.0.1')


def run_pair(env):
    """Talker and listener as processes; the talker's sockets once it is up, and the reply."""
    talker = subprocess.Popen([sys.executable, '-c', TALKER, str(RECEIVE_TIMEOUT_S + 5)],
                              env=env, stdout=subprocess.PIPE, text=True)
    try:
        assert talker.stdout.readline().strip() == 'ready'
        listener = subprocess.run([sys.executable, '-c', LISTENER, str(RECEIVE_TIMEOUT_S)],
                                  env=env, capture_output=True, text=True,
                                  timeout=RECEIVE_TIMEOUT_S + READY_TIMEOUT_S)
        sockets = udp_sockets_of(talker.pid)
    finally:
        talker.terminate()
        talker.wait(timeout=READY_TIMEOUT_S)
    return sockets, listener.stdout


def isolated_env(**changes):
    env = dict(os.environ)
    env.pop('FLEXLINK_LOOPBACK_SOCKETS', None)
    domain = runtime.isolate_ros_environment(env, **changes)
    return env, domain


def rtps_ports(domain):
    """Give the ports RTPS derives from the domain: where a participant listens."""
    first = RTPS_PORT_BASE + RTPS_DOMAIN_GAIN * domain
    return range(first, first + RTPS_DOMAIN_PORTS)


def test_profile_is_found_and_says_loopback_only():
    env, _ = isolated_env()
    profile = pathlib.Path(env['FASTDDS_DEFAULT_PROFILES_FILE'])
    assert profile == runtime.fastdds_profile_path() and profile.is_file()
    assert env['ROS_AUTOMATIC_DISCOVERY_RANGE'] == 'LOCALHOST'
    namespace = {'dds': 'http://www.eprosima.com'}
    root = ElementTree.parse(profile).getroot()
    udp = [d for d in root.iterfind('.//dds:transport_descriptor', namespace)
           if d.findtext('dds:type', namespaces=namespace) == 'UDPv4']
    assert [a.text for d in udp
            for a in d.iterfind('dds:interfaceWhiteList/dds:address', namespace)] == \
        ['127.0.0.1']
    participant = root.find('.//dds:participant', namespace)
    assert participant.get('is_default_profile') == 'true'
    assert participant.findtext('dds:rtps/dds:useBuiltinTransports',
                                namespaces=namespace) == 'false'
    strict, _ = isolated_env(loopback_sockets=True)
    assert strict['ROS_AUTOMATIC_DISCOVERY_RANGE'] == 'SYSTEM_DEFAULT'


def test_with_localhost_range_every_listening_socket_is_on_loopback():
    env, domain = isolated_env()
    sockets, reply = run_pair(env)
    assert "received ['over loopback']" in reply
    listening = [s for s in sockets if s[1] in rtps_ports(domain)]
    assert len(listening) >= 2, sockets
    assert [s for s in listening if not is_loopback(s[0])] == []
    # Without the profile the same process listens on every interface (what item 13 saw).
    del env['FASTDDS_DEFAULT_PROFILES_FILE']
    sockets, _ = run_pair(env)
    assert any(s[1] in rtps_ports(domain) and s[0] == '0.0.0.0' for s in sockets), sockets
