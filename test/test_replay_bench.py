"""benchmarks/replay_bench.py at a tiny size: the bag it makes and the runs it compares."""

import math
import pathlib
import re
import subprocess
import sys

from rosbags.highlevel import AnyReader

REPO = pathlib.Path(__file__).resolve().parents[1]
BENCH = REPO / 'benchmarks' / 'replay_bench.py'


def test_the_bench_makes_a_crank_bag_and_compares_alternating_runs(tmp_path):
    bag = tmp_path / 'bag.mcap'
    made = subprocess.run([sys.executable, str(BENCH), 'make-bag', str(bag), '--seconds', '0.2'],
                          capture_output=True, text=True, timeout=300, check=True)
    count = int(re.search(r': (\d+) messages', made.stdout).group(1))
    with AnyReader([bag]) as reader:       # read back by an independent reader
        assert [c.msgtype for c in reader.connections] == ['sensor_msgs/msg/JointState']
        stamps, angles = [], []
        for connection, log_ns, data in reader.messages():
            message = reader.deserialize(data, connection.msgtype)
            assert list(message.name) == ['crank'] and message.velocity[0] > 40.0
            stamps.append(message.header.stamp.sec * 10**9 + message.header.stamp.nanosec)
            angles.append(message.position[0])
            assert log_ns == stamps[-1] + 150_000
    assert len(stamps) == count > 150 and stamps == sorted(stamps)
    assert all(-math.pi <= angle < math.pi for angle in angles)
    compared = subprocess.run(
        [sys.executable, str(BENCH), 'compare', str(bag), '--pairs', '1', '--reference-python',
         sys.executable, '--reference-root', str(REPO), '--same-output'],
        capture_output=True, text=True, timeout=600)
    assert compared.returncode == 0, compared.stderr
    lines = compared.stdout.splitlines()
    assert 'same topics, times and sequence numbers: True; messages whose bytes differ: 0' in lines
    assert sum(line.startswith('pair 1 ') for line in lines) == 2
    assert re.search(r'reference / this: \d+\.\d\dx', compared.stdout)
