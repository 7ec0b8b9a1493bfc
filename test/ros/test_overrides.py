"""
Nodes under a namespace: /** parameter files apply, unknown names are warned about.

Also the managed node's shutdown and re-configure (ros/overrides.py, ros/node.py).
"""

import subprocess
import sys

from flexlink_ros.names import NODE_NAME, READY_MESSAGE
import pytest
import test_node
from test_node import lifecycle_client, NodeProcess, PARAMS_FILE, READY_TIMEOUT_S, spin_until
import yaml

ros = test_node.ros
NAMESPACE = '/robot1'


def _params_file(tmp_path, source, **changes):
    """Copy a /** params file with parameters changed or added (dotted names are nested)."""
    tree = yaml.safe_load(source.read_text())
    assert list(tree) == ['/**']
    for dotted, value in changes.items():
        branch = tree['/**']['ros__parameters']
        *groups, name = dotted.split('.')
        for group in groups:
            branch = branch.setdefault(group, {})
        branch[name] = value
    path = tmp_path / source.name
    path.write_text(yaml.safe_dump(tree))
    return path


def _parameters(test_node, executor, node_name, names):
    """Ask a node's parameter services for its parameter names and the values of ``names``."""
    from rcl_interfaces.srv import GetParameters, ListParameters
    listed = test_node.create_client(ListParameters, f'{node_name}/list_parameters')
    get = test_node.create_client(GetParameters, f'{node_name}/get_parameters')
    spin_until(executor, lambda: listed.service_is_ready() and get.service_is_ready(), 30.0,
               f'parameter services of {node_name}')
    futures = (listed.call_async(ListParameters.Request()),
               get.call_async(GetParameters.Request(names=list(names))))
    spin_until(executor, lambda: all(f.done() for f in futures), 30.0, 'parameter replies')
    return (set(futures[0].result().result.names),
            [value.string_value for value in futures[1].result().values])


def test_namespaced_node_takes_the_wildcard_file_and_warns_about_unknown_names(
        tmp_path, processes, ros):
    params_file = _params_file(tmp_path, PARAMS_FILE, frame_id='robot1_ground',
                               **{'model.mdoes': 3})
    node_process = NodeProcess(tmp_path, 'no_such_parameter:=1.0',
                               ros_args=['-r', f'__ns:={NAMESPACE}'], params_file=params_file)
    processes.append(node_process)
    node_process.wait_for(READY_MESSAGE, READY_TIMEOUT_S)
    test_node, executor = ros
    names, values = _parameters(test_node, executor, f'{NAMESPACE}/{NODE_NAME}', ['frame_id'])
    assert values == ['robot1_ground']          # the /** file reached the namespaced node
    assert 'model.modes' in names and not {'model.mdoes', 'no_such_parameter'} & names
    log = node_process.log().splitlines()
    mdoes = [line for line in log if "'model.mdoes'" in line]
    no_such = [line for line in log if "'no_such_parameter'" in line]
    assert len(mdoes) == 1 and "did you mean 'model.modes'" in mdoes[0], log
    assert len(no_such) == 1 and 'names no parameter' in no_such[0], log
    assert '[WARN]' in mdoes[0] and f'{NAMESPACE[1:]}.{NODE_NAME}' in mdoes[0]
    assert node_process.stop() == 0


def test_namespaced_driver_takes_the_wildcard_file_and_warns_about_unknown_names(
        tmp_path, config_dir):
    # duration_s only in the file: the driver stops by itself only if the file applied.
    params_file = _params_file(tmp_path, config_dir / 'crank_driver.yaml', duration_s=0.3,
                               speed_rmp=5.0)
    result = subprocess.run(
        [sys.executable, '-m', 'flexlink_ros.ros.crank_driver', '--ros-args', '-r',
         f'__ns:={NAMESPACE}', '--params-file', str(params_file)],
        capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    lines = [line for line in result.stderr.splitlines() if "'speed_rmp'" in line]
    assert len(lines) == 1 and "did you mean 'speed_rpm'" in lines[0], result.stderr


@pytest.mark.parametrize('file_name', ['flexlink_node.yaml', 'crank_driver.yaml'])
def test_shipped_parameter_files_are_keyed_for_any_node(config_dir, file_name):
    assert list(yaml.safe_load((config_dir / file_name).read_text())) == ['/**']


def test_managed_node_process_exits_after_the_shutdown_transition(tmp_path, processes, ros):
    from lifecycle_msgs.msg import Transition
    from lifecycle_msgs.srv import ChangeState

    managed = NodeProcess(tmp_path, flags=['--managed'], ros_args=['-r', f'__ns:={NAMESPACE}'])
    processes.append(managed)
    test_node, executor = ros
    change_state = lifecycle_client(test_node, executor, f'{NAMESPACE}/{NODE_NAME}/change_state')
    future = change_state.call_async(ChangeState.Request(
        transition=Transition(id=Transition.TRANSITION_UNCONFIGURED_SHUTDOWN)))
    spin_until(executor, future.done, 30.0, 'the shutdown transition')
    assert future.result().success                  # answered before the process ends
    assert managed.process.wait(timeout=60) == 0, managed.log()


def test_reconfigured_node_records_again_next_to_the_first_take(tmp_path, processes, ros):
    from lifecycle_msgs.msg import Transition
    from lifecycle_msgs.srv import ChangeState

    bag = tmp_path / 'take'
    managed = NodeProcess(tmp_path, 'record.enabled:=true', f'record.path:={bag}',
                          flags=['--managed'])
    processes.append(managed)
    test_node, executor = ros
    change_state = lifecycle_client(test_node, executor, f'/{NODE_NAME}/change_state')
    for transition in ('CONFIGURE', 'CLEANUP', 'CONFIGURE', 'CLEANUP'):
        future = change_state.call_async(ChangeState.Request(
            transition=Transition(id=getattr(Transition, f'TRANSITION_{transition}'))))
        spin_until(executor, future.done, READY_TIMEOUT_S, transition)
        assert future.result().success, managed.log()
    assert bag.is_dir() and (tmp_path / 'take_2').is_dir()
    assert 'recording disabled' not in managed.log()
    assert managed.log().count('recording closed') == 2
    assert managed.stop() == 0
