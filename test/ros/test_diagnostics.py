"""/diagnostics of nodes in namespaces: named after each node, distinct, also while inactive."""

from flexlink_ros.names import NODE_NAME, READY_MESSAGE
import test_node
from test_node import NodeProcess, READY_TIMEOUT_S, spin_until

processes = test_node.processes   # fixtures of test_node, used here by name
ros = test_node.ros


def _latest_statuses(messages, node_name):
    """Map status name -> (level, message, hardware_id) of a node's latest /diagnostics."""
    for message in reversed(messages):
        statuses = [s for s in message.status if s.name.startswith(f'{node_name}: ')]
        if statuses:
            return {s.name: (s.level, s.message, s.hardware_id) for s in statuses}
    return {}


def test_two_namespaced_nodes_report_distinct_diagnostics_also_while_inactive(
        tmp_path, processes, ros):
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
    from lifecycle_msgs.msg import Transition
    from lifecycle_msgs.srv import ChangeState

    plain = NodeProcess(tmp_path, 'diagnostics.period_s:=0.2', 'diagnostics.hardware_id:=left',
                        ros_args=['-r', '__ns:=/robot1'])
    managed = NodeProcess(tmp_path, 'diagnostics.period_s:=0.2', flags=['--managed'],
                          ros_args=['-r', '__ns:=/robot2'])
    processes.extend([plain, managed])
    test_node, executor = ros
    messages = []
    test_node.create_subscription(DiagnosticArray, '/diagnostics', messages.append, 100)
    first, second = f'/robot1/{NODE_NAME}', f'/robot2/{NODE_NAME}'

    def estimator_message(node_name):
        return _latest_statuses(messages, node_name).get(f'{node_name}: estimator',
                                                         (None, ''))[1]

    # The managed node reports before its configure transition, under its own name.
    spin_until(executor, lambda: 'unconfigured' in estimator_message(second), READY_TIMEOUT_S,
               'the unconfigured managed node on /diagnostics')
    plain.wait_for(READY_MESSAGE, READY_TIMEOUT_S)
    spin_until(executor, lambda: len(_latest_statuses(messages, first)) == 7, 30.0,
               'the streaming node on /diagnostics')
    change_state = test_node.create_client(ChangeState, f'{second}/change_state')
    spin_until(executor, change_state.service_is_ready, 30.0, 'the lifecycle service')
    future = change_state.call_async(ChangeState.Request(
        transition=Transition(id=Transition.TRANSITION_CONFIGURE)))
    spin_until(executor, future.done, READY_TIMEOUT_S, 'the configure transition')
    assert future.result().success
    spin_until(executor, lambda: 'configured, waiting' in estimator_message(second), 30.0,
               'the inactive managed node on /diagnostics')

    streaming, inactive = _latest_statuses(messages, first), _latest_statuses(messages, second)
    parts = ('input', 'estimator', 'joint O2', 'joint A', 'joint B', 'joint O4', 'recorder')
    assert set(streaming) == {f'{first}: {part}' for part in parts}
    assert set(inactive) == {f'{second}: {part}' for part in ('input', 'estimator',
                                                              'recorder')}
    assert {hardware for _, _, hardware in streaming.values()} == {'left'}
    assert {hardware for _, _, hardware in inactive.values()} == {'flexlink'}
    assert inactive[f'{second}: estimator'][0] == DiagnosticStatus.OK
    assert inactive[f'{second}: input'][:2] == (
        DiagnosticStatus.STALE, 'inactive: not subscribed to /robot2/joint_states')
    assert plain.stop() == 0 and managed.stop() == 0
