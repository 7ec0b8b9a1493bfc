"""
/diagnostics: the estimator's validity WARN; nodes in namespaces named apart, also inactive.

The validity indicator (core/validity.py) graded from a period's counts, and a real node fed
real JointState messages at 269 rpm (valid) and 405 rpm (not valid: WARN with the value).
"""

import inspect
import math
import time

from flexlink_ros.core import validity
from flexlink_ros.core.estimation.sample import Sample
from flexlink_ros.names import NODE_NAME, READY_MESSAGE
from flexlink_ros.ros import diagnostics
from flexlink_ros.ros.message_outcomes import PeriodStats
from flexlink_ros.ros.messages import OK, WARN
import test_node
from test_node import (DISCOVERY_TIMEOUT_S, joint_state, lifecycle_client, NodeProcess,
                       READY_TIMEOUT_S, spin_until)

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
    change_state = lifecycle_client(test_node, executor, f'{second}/change_state', 30.0)
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


def _sample(nonlinearity):
    return Sample(stamp_ns=0, crank_angle=0.0, crank_speed=40.0, crank_accel=0.0,
                  lever_tip=(0.0, 0.0), coupler_mid=(0.0, 0.0), reaction_n=(1.0,) * 4,
                  gamma_dot=(0.0,) * 4, criterion=(0.0,) * 4, near_zero=(False,) * 4,
                  error_indicator=0.0, flags=0, message='', modal=(),
                  nonlinearity=nonlinearity)


def test_estimator_warns_when_the_validity_indicator_passes_the_threshold():
    # the threshold is core.validity's constant, not a copy of it
    default = inspect.signature(diagnostics.estimator_level).parameters['nonlinearity_warn']
    assert default.default is validity.VALIDITY_THRESHOLD
    period = PeriodStats()
    period.add_sample(_sample(math.nan))            # a model without the tables
    assert diagnostics.estimator_level(period, 0.05) == (OK, 'ok')
    values = {'diagnostics.error_indicator_warn': 0.05,
              'diagnostics.nonlinearity_warn': validity.VALIDITY_THRESHOLD}
    keys = {kv.key: kv.value for kv in diagnostics.estimator_status(period, values, {}).values}
    assert keys['nonlinearity_max'] == 'nan'
    assert keys['nonlinearity_threshold'] == f'{validity.VALIDITY_THRESHOLD:.6g}'
    period.add_sample(_sample(0.9 * validity.VALIDITY_THRESHOLD))
    assert diagnostics.estimator_level(period, 0.05) == (OK, 'ok')
    period.add_sample(_sample(1.5 * validity.VALIDITY_THRESHOLD))
    period.add_sample(_sample(math.nan))
    level, message = diagnostics.estimator_level(period, 0.05)
    assert level == WARN and 'linear estimate not valid' in message
    status = diagnostics.estimator_status(period, values, {})
    keys = {kv.key: kv.value for kv in status.values}
    assert float(keys['nonlinearity_max']) == 1.5 * validity.VALIDITY_THRESHOLD
    assert status.level == WARN
    # the parameter diagnostics.nonlinearity_warn sets the threshold
    values['diagnostics.nonlinearity_warn'] = 2.0 * validity.VALIDITY_THRESHOLD
    status = diagnostics.estimator_status(period, values, {})
    keys = {kv.key: kv.value for kv in status.values}
    assert status.level == OK and float(keys['nonlinearity_threshold']) == values[
        'diagnostics.nonlinearity_warn']


def _feed(publisher, executor, rpm, first_ns, count=500):
    """Publish ``count`` crank samples at ``rpm``, 1 kHz stamps, paced at about that rate."""
    speed = rpm * math.pi / 30.0
    start = time.monotonic()
    for n in range(count):
        angle = math.remainder(speed * n * 1e-3, 2.0 * math.pi)
        publisher.publish(joint_state(first_ns + n * 1_000_000, ['crank'], [angle], [speed]))
        delay = start + (n + 1) * 1e-3 - time.monotonic()
        if delay > 0:
            time.sleep(delay)
        if n % 50 == 0:
            executor.spin_once(timeout_sec=0.0)


# A small rigid model (rigid crank and bearings), diagnostics every 0.1 s.
# The linear model's own validity indicator (model.nonlinear off: the nonlinear one's is
# tested with it on).
RIGID_NODE = ('diagnostics.period_s:=0.1', 'model.bearings:=rigid', 'model.rigid_crank:=true',
              'model.grid_size:=64', 'model.nonlinear:=off')


def _watch(ros, facts=None):
    """
    Publish crank input to the node; collect its lever tip outputs and estimator statuses.

    ``facts``: a list given every estimator status's key values.
    """
    from diagnostic_msgs.msg import DiagnosticArray
    from geometry_msgs.msg import Vector3Stamped
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import JointState

    test_node, executor = ros
    qos = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
    publisher = test_node.create_publisher(JointState, 'joint_states', qos)
    outputs, statuses = [], []
    test_node.create_subscription(Vector3Stamped, f'/{NODE_NAME}/lever_tip/deflection',
                                  outputs.append, qos)

    def on_diagnostics(message):
        for item in message.status:
            if item.name == f'/{NODE_NAME}: estimator':
                keys = {kv.key: kv.value for kv in item.values}
                if facts is not None:
                    facts.append(keys)
                statuses.append((int(keys.get('samples_in_period', 0)), item.level,
                                 item.message, float(keys.get('nonlinearity_max', 'nan')),
                                 float(keys.get('nonlinearity_threshold', 'nan'))))

    test_node.create_subscription(DiagnosticArray, '/diagnostics', on_diagnostics, 100)
    spin_until(executor, lambda: publisher.get_subscription_count() > 0, DISCOVERY_TIMEOUT_S,
               'discovery')

    def verdicts(rpm, first_ns):
        """Feed 500 samples at ``rpm``; (level, message, indicator, threshold) per period."""
        before = len(outputs)
        _feed(publisher, executor, rpm, first_ns)
        spin_until(executor, lambda: len(outputs) >= before + 500, 30.0, 'the outputs')
        seen = len(statuses)
        # a period without samples: every sample of this speed has been reported
        spin_until(executor, lambda: any(not entry[0] for entry in statuses[seen:]), 10.0,
                   'a period after the last sample')
        found = [entry[1:] for entry in statuses if entry[0]]
        statuses[:] = []
        return found

    return verdicts


def test_node_estimator_warns_past_the_validity_threshold(tmp_path, processes, ros):
    """OK at 269 rpm, WARN at 405 rpm (the default threshold)."""
    node = NodeProcess(tmp_path, *RIGID_NODE, f'model.cache_dir:={tmp_path}')
    processes.append(node)
    node.wait_for(READY_MESSAGE, READY_TIMEOUT_S)
    verdicts = _watch(ros)
    # The second speed starts 10 s later in stamps: the estimator restarts (warm) there.
    found = {rpm: verdicts(rpm, first_ns)
             for rpm, first_ns in ((269.0, 10**18), (405.0, 10**18 + 10**10))}
    print(found)
    # (a period may WARN for other reasons, never for the validity)
    assert found[269.0] and all('nonlinearity' not in message
                                and value < validity.VALIDITY_THRESHOLD
                                for _, message, value, _ in found[269.0]), found[269.0]
    warned = [(value, message) for level, message, value, _ in found[405.0] if level == WARN]
    assert warned, found[405.0]
    for value, message in warned:
        assert value > validity.VALIDITY_THRESHOLD
        assert 'linear estimate not valid: nonlinearity indicator' in message
    assert node.stop() == 0


def test_the_nonlinear_node_judges_its_own_estimate_through_the_resonance(
        tmp_path, processes, ros):
    """model.nonlinear on: at 405 rpm no validity WARN; the status names the model."""
    node = NodeProcess(tmp_path, *RIGID_NODE[:-1], 'model.nonlinear:=on',
                       f'model.cache_dir:={tmp_path}')
    processes.append(node)
    node.wait_for(READY_MESSAGE, READY_TIMEOUT_S)
    assert 'model: nonlinear (asked for (model.nonlinear on))' in node.log()
    facts = []
    verdicts = _watch(ros, facts)
    found = verdicts(405.0, 10**18)
    print(found, facts[-1])
    # (the first period may hold only the model's start, which is not judged: NaN)
    judged = [value for _, _, value, _ in found if not math.isnan(value)]
    assert len(judged) >= len(found) - 1, found
    assert all('not valid' not in message for _, message, _, _ in found), found
    assert all(0.0 < value < validity.VALIDITY_THRESHOLD for value in judged), found
    last = facts[-1]
    assert last['model_nonlinear'] == 'on' and 'beta' in last['nonlinear_damping']
    assert int(last['nonlinear_samples']) >= 500
    assert int(last['nonlinear_refused_samples']) == 0
    assert node.stop() == 0


def test_node_nonlinearity_warn_parameter_sets_the_threshold_at_run_time(
        tmp_path, processes, ros):
    """At 269 rpm (OK by default): WARN below a low threshold; raised at run time: no WARN."""
    from rclpy.parameter import Parameter
    from rclpy.parameter_client import AsyncParameterClient

    low = 0.02
    node = NodeProcess(tmp_path, *RIGID_NODE, f'diagnostics.nonlinearity_warn:={low}',
                       f'model.cache_dir:={tmp_path}')
    processes.append(node)
    node.wait_for(READY_MESSAGE, READY_TIMEOUT_S)
    verdicts = _watch(ros)
    found = verdicts(269.0, 10**18)
    print(found)
    warned = [entry for entry in found if 'nonlinearity indicator' in entry[1]]
    assert warned and all(level == WARN and low < value < validity.VALIDITY_THRESHOLD
                          and threshold == low for level, _, value, threshold in warned)
    test_node, executor = ros
    client = AsyncParameterClient(test_node, NODE_NAME)
    spin_until(executor, client.services_are_ready, DISCOVERY_TIMEOUT_S, 'parameter services')

    def set_threshold(value):
        future = client.set_parameters([Parameter('diagnostics.nonlinearity_warn',
                                                  value=value)])
        spin_until(executor, future.done, 10.0, 'setting diagnostics.nonlinearity_warn')
        return future.result().results[0]

    assert not set_threshold(0.001).successful            # below the range
    assert set_threshold(100.0).successful
    found = verdicts(269.0, 10**18 + 10**10)
    assert found and all('nonlinearity' not in message and threshold == 100.0
                         for _, message, _, threshold in found), found
    assert node.stop() == 0


def test_recorder_error_when_its_write_queue_overflowed(tmp_path):
    """Messages lost to a full write queue (a writer that cannot keep up): ERROR, counted."""
    from flexlink_ros.io.recorder import McapRecorder
    from flexlink_ros.io.recorder_queue import QUEUE_MAX_BYTES
    from flexlink_ros.ros.messages import ERROR
    recorder = McapRecorder(tmp_path / 'bag').open()
    recorder.add_topic('/a', 'sensor_msgs/msg/JointState')
    assert diagnostics.recorder_status(recorder.status(list_files=False)).level == OK
    with recorder._lock:      # the writing thread waits here, as behind a stalled disk
        for k in range(2 * QUEUE_MAX_BYTES // 10_000):
            recorder.enqueue('/a', bytes(10_000), k)
        report = diagnostics.recorder_status(recorder.status(list_files=False))
    recorder.close()
    values = {v.key: v.value for v in report.values}
    lost = recorder.status()['overflow_count']
    assert report.level == ERROR and lost > 0
    assert f'{lost} messages lost' in report.message and values['overflow'] == str(lost)
    assert values['files'] == '1'
