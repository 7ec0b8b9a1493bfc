"""flexlink_node's lifecycle under concurrent transitions while input streams (real processes)."""

import os
import signal
import subprocess
import sys
import time

from test_node import NodeProcess

HAMMER_S = 30.0
# A lifecycle client: random transitions (not shutdown) as fast as the node answers.
CLIENT = r"""
import random, sys, time
import rclpy
from lifecycle_msgs.msg import Transition
from lifecycle_msgs.srv import ChangeState
rclpy.init()
node = rclpy.create_node(f'hammer_{sys.argv[2]}')
client = node.create_client(ChangeState, '/flexlink_node/change_state')
deadline = time.monotonic() + float(sys.argv[1])
rng = random.Random(int(sys.argv[2]))
ids = [Transition.TRANSITION_CONFIGURE, Transition.TRANSITION_ACTIVATE,
       Transition.TRANSITION_DEACTIVATE, Transition.TRANSITION_CLEANUP]
while not client.wait_for_service(timeout_sec=1.0):
    pass
calls = accepted = 0
while time.monotonic() < deadline:
    future = client.call_async(ChangeState.Request(transition=Transition(id=rng.choice(ids))))
    rclpy.spin_until_future_complete(node, future, timeout_sec=30.0)
    calls += 1
    accepted += bool(future.done() and future.result() and future.result().success)
print(f'calls {calls} accepted {accepted}', flush=True)
"""


def test_concurrent_transitions_while_input_streams_never_reach_the_last_resort(
        tmp_path, processes):  # noqa: F811
    node = NodeProcess(tmp_path, flags=['--managed'])
    processes.append(node)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path))
    driver = subprocess.Popen([sys.executable, '-m', 'flexlink_ros.ros.crank_driver',
                               '--ros-args', '-p', 'speed_rpm:=300.0'], env=env,
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    processes.append(driver)
    script = tmp_path / 'client.py'
    script.write_text(CLIENT)
    clients = [subprocess.Popen([sys.executable, str(script), str(HAMMER_S), str(seed)],
                                env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                text=True) for seed in (1, 2)]
    processes.extend(clients)
    outputs = [c.communicate(timeout=HAMMER_S + 300)[0] for c in clients]
    for output in outputs:
        assert 'calls' in output, output
    accepted = sum(int(o.split('accepted')[1]) for o in outputs)
    assert accepted > 20, outputs       # the node went through many transitions
    time.sleep(1.0)
    assert node.process.poll() is None, node.log()
    assert node.stop(signal.SIGTERM) == 0
    log = node.log()
    assert 'unexpected' not in log and 'Traceback' not in log, log[-3000:]
    print(outputs, log.count('input skipped'), log.count('model:'))
