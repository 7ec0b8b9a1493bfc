"""flexlink_node over real rclpy between processes on loopback (conftest sets the domain)."""

import json
import math
import os
import pathlib
import re
import signal
import subprocess
import sys
import time

from flexlink_ros.core.options import DEFAULT_SIZES, ModelOptions
from flexlink_ros.names import FIRST_INPUT_MESSAGE, NODE_NAME, READY_MESSAGE
from flexlink_ros.ros import parameters as node_params
from flexlink_ros.ros.node_model import load_node_model
import numpy as np
import pytest
import yaml

READY_TIMEOUT_S = 240.0     # node start-up incl. a first model build on a loaded machine
DISCOVERY_TIMEOUT_S = 20.0
PARAMS_FILE = pathlib.Path(__file__).resolve().parents[2] / 'config' / 'flexlink_node.yaml'
DATA = pathlib.Path(__file__).resolve().parents[1] / 'data'
OUTPUTS = ('/flexlink_node/lever_tip/deflection', '/flexlink_node/coupler_mid/deflection',
           '/flexlink_node/joint_criteria', '/flexlink_node/markers', '/diagnostics')


# -- helpers without rclpy -----------------------------------------------------------------

def test_model_options_follow_the_parameters():
    values = node_params.defaults()
    options = node_params.model_options(values)
    # 0 modes: the planned default, for the flexible crank of the node's default scene.
    assert options == ModelOptions(rigid_crank=False, elements_per_link=4, order=2)
    assert (options.modes, options.static) == DEFAULT_SIZES['flexible', False]
    values.update({'model.modes': 6, 'model.bearings': 'rigid', 'model.rigid_crank': False,
                   'model.geometric_stiffness': False, 'model.static': 0,
                   'model.grid_size': 256, 'model.elements_per_link': 4})
    options = node_params.model_options(values)
    assert (options.modes, options.bearings, options.rigid_crank,
            options.geometric_stiffness) == (6, 'rigid', False, False)
    assert (options.static, options.grid_size, options.elements_per_link) == (0, 256, 4)


# -- processes ------------------------------------------------------------------------------

class NodeProcess:
    """flexlink_node in a subprocess, its log in a file."""

    def __init__(self, tmp_path, *parameters, flags=(), ros_args=(), params_file=PARAMS_FILE):
        self.log_path = tmp_path / f'node_{time.monotonic_ns()}.log'
        command = [sys.executable, '-m', 'flexlink_ros.ros.node', *flags, '--ros-args',
                   *ros_args, '--params-file', str(params_file)]
        for item in parameters:
            command += ['-p', item]
        env = dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path), PYTHONUNBUFFERED='1',
                   RCUTILS_LOGGING_BUFFERED_STREAM='0')
        self.log_file = open(self.log_path, 'w')
        self.process = subprocess.Popen(command, stdout=self.log_file,
                                        stderr=subprocess.STDOUT, env=env)

    def log(self):
        return self.log_path.read_text()

    def wait_for(self, fragment, timeout_s):
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if fragment in self.log():
                return
            assert self.process.poll() is None, 'node exited:\n' + self.log()
            time.sleep(0.05)
        raise AssertionError(f'{fragment!r} not logged within {timeout_s} s:\n' + self.log())

    def stop(self, sig=signal.SIGTERM, timeout_s=30.0):
        if self.process.poll() is None:
            self.process.send_signal(sig)
            try:
                self.process.wait(timeout=timeout_s)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()
        self.log_file.close()
        return self.process.returncode


@pytest.fixture
def ros():
    """Give an rclpy context, a test node and its executor (shut down at the end)."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor

    context = rclpy.Context()
    rclpy.init(context=context)
    node = rclpy.create_node('flexlink_test', context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    try:
        yield node, executor
    finally:
        executor.shutdown()
        node.destroy_node()
        context.try_shutdown()


def spin_until(executor, condition, timeout_s, what, detail=lambda: ''):
    deadline = time.monotonic() + timeout_s
    while not condition():
        assert time.monotonic() < deadline, f'timed out waiting for {what}{detail()}'
        executor.spin_once(timeout_sec=0.02)


def answering_client(test_node, executor, service_type, service_name, probe,
                     timeout_s=READY_TIMEOUT_S):
    """
    Give a client of a node's service whose answers are sure to reach it.

    The service being ready says only that our requests reach the node. Fast DDS drops an
    answer when the node's response writer has not yet matched our reader ("client will not
    receive response"), which a loaded machine's discovery can delay, and the request is not
    retried. So ``probe``, a request that changes nothing, is sent until one answer comes
    back: from then on every answer arrives.
    """
    client = test_node.create_client(service_type, service_name)
    spin_until(executor, client.service_is_ready, timeout_s, service_name)
    deadline = time.monotonic() + timeout_s
    while True:
        future = client.call_async(probe)
        try:
            spin_until(executor, future.done, 2.0, 'an answer')
            return client
        except AssertionError:
            client.remove_pending_request(future)
            assert time.monotonic() < deadline, f'no answer from {service_name}'


def lifecycle_client(test_node, executor, service_name, timeout_s=READY_TIMEOUT_S):
    """Give an answering ChangeState client; its probe names no transition (nothing done)."""
    from lifecycle_msgs.msg import Transition
    from lifecycle_msgs.srv import ChangeState
    probe = ChangeState.Request(transition=Transition(label='no_such_transition'))
    return answering_client(test_node, executor, ChangeState, service_name, probe, timeout_s)


def joint_state(stamp_ns, names, positions, velocities):
    from flexlink_ros.ros.messages import ns_to_stamp
    from sensor_msgs.msg import JointState
    message = JointState(name=list(names), position=[float(p) for p in positions],
                         velocity=[float(v) for v in velocities])
    message.header.stamp = ns_to_stamp(stamp_ns)
    return message


def node_model():
    """Load the model the node builds with default parameters (same cache)."""
    model, _, _ = load_node_model(node_params.defaults(), lambda note: None)
    return model


def read_with_rosbags(bag):
    from rosbags.highlevel import AnyReader
    counts, stamps = {}, {}
    with AnyReader([bag]) as reader:
        for connection, _, raw in reader.messages():
            message = reader.deserialize(raw, connection.msgtype)
            counts[connection.topic] = counts.get(connection.topic, 0) + 1
            if hasattr(message, 'header') and connection.topic != '/diagnostics':
                stamp = message.header.stamp.sec * 10**9 + message.header.stamp.nanosec
                stamps.setdefault(connection.topic, []).append(stamp)
    return counts, stamps


def read_with_mcap_ros2(bag):
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    counts = {}
    for path in sorted(bag.glob('*.mcap')):
        with open(path, 'rb') as stream:
            reader = make_reader(stream, decoder_factories=[DecoderFactory()])
            for _, channel, _, decoded in reader.iter_decoded_messages():
                assert decoded is not None
                counts[channel.topic] = counts.get(channel.topic, 0) + 1
    return counts


def test_node_end_to_end(tmp_path, processes, ros):
    """Test publisher -> node -> test subscriber, bad input, parameters, SIGTERM recording."""
    from diagnostic_msgs.msg import DiagnosticArray
    from geometry_msgs.msg import Vector3Stamped
    from rclpy.parameter import Parameter
    from rclpy.parameter_client import AsyncParameterClient
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import JointState

    bag = tmp_path / 'bag'
    # The linear estimate's own numbers (the nonlinear model's: test_diagnostics, replay).
    node_process = NodeProcess(tmp_path, 'record.enabled:=true', f'record.path:={bag}',
                               'diagnostics.period_s:=0.2', 'markers.every_n:=25',
                               'model.nonlinear:=off')
    processes.append(node_process)
    model = node_model()              # meanwhile: the reference's model, from the cache
    node_process.wait_for(READY_MESSAGE, READY_TIMEOUT_S)

    test_node, executor = ros
    qos = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
    publisher = test_node.create_publisher(JointState, 'joint_states', qos)
    received = {'lever': [], 'coupler': [], 'criteria': [], 'diagnostics': []}
    test_node.create_subscription(Vector3Stamped, OUTPUTS[0], received['lever'].append, qos)
    test_node.create_subscription(Vector3Stamped, OUTPUTS[1], received['coupler'].append, qos)
    test_node.create_subscription(JointState, OUTPUTS[2], received['criteria'].append, qos)
    test_node.create_subscription(DiagnosticArray, '/diagnostics',
                                  received['diagnostics'].append, 10)
    spin_until(executor, lambda: publisher.get_subscription_count() > 0
               and test_node.count_publishers(OUTPUTS[0]) > 0
               and len(received['diagnostics']) > 0, DISCOVERY_TIMEOUT_S, 'discovery')

    # A crank at 391 rpm sampled with 30 % jitter, with bad messages in between.
    rng = np.random.default_rng(7)
    speed = 391.0 * 2.0 * math.pi / 60.0
    times = np.cumsum((1.0 + 0.3 * rng.uniform(-1.0, 1.0, 600)) * 1e-3)
    stamps = (1_800_000_000 * 10**9 + np.round(times * 1e9)).astype(np.int64).tolist()
    angles = np.mod(speed * times + np.pi, 2.0 * np.pi) - np.pi
    bad = {100: joint_state(stamps[100] + 1, ['crank'], [math.nan], [speed]),
           200: joint_state(stamps[200] + 1, ['lever'], [0.1], [speed]),
           300: joint_state(stamps[300] + 1, [], [], [])}
    # Paced at the stamps' rate (a burst would overflow the node's input queue) once the
    # first sample's warm start is done.
    start = None
    for n, (stamp, angle) in enumerate(zip(stamps, angles)):
        publisher.publish(joint_state(stamp, ['base', 'crank'], [0.0, angle], [0.0, speed]))
        if n in bad:
            publisher.publish(bad[n])
        if n == 0:
            spin_until(executor, lambda: received['lever'], 20.0, 'the first output')
            start = time.monotonic() - times[0]
        delay = start + times[min(n + 1, len(times) - 1)] - time.monotonic()
        if delay > 0:
            time.sleep(delay)    # pacing; the outputs wait in the subscriptions' queues
        if n % 50 == 0:
            executor.spin_once(timeout_sec=0.0)
    spin_until(executor, lambda: len(received['lever']) >= len(stamps)
               and len(received['criteria']) >= len(stamps), 30.0, 'all outputs',
               lambda: f': {({k: len(v) for k, v in received.items()})}\n{node_process.log()}')

    # Outputs carry the input stamps and equal the library's estimate of the same samples.
    from flexlink_ros.core.estimation.streaming import StreamingEstimator
    from flexlink_ros.ros.messages import stamp_to_ns
    estimator = StreamingEstimator(model)
    reference = [estimator.update(s, a, speed) for s, a in zip(stamps, angles)]
    lever = [(stamp_to_ns(m.header.stamp), m.vector.x, m.vector.y) for m in received['lever']]
    assert [entry[0] for entry in lever] == stamps
    assert all(m.header.frame_id == 'linkage_ground' for m in received['lever'])
    got = np.array([entry[1:] for entry in lever])
    expected = np.array([sample.lever_tip for sample in reference])
    assert np.max(np.abs(got - expected)) <= 1e-12 * np.max(np.abs(expected))
    got = np.array([(m.vector.x, m.vector.y) for m in received['coupler']])
    expected = np.array([sample.coupler_mid for sample in reference])
    assert np.max(np.abs(got - expected)) <= 1e-12 * np.max(np.abs(expected))
    criteria = received['criteria'][-1]
    assert list(criteria.name) == ['O2', 'A', 'B', 'O4']
    assert list(criteria.position) == pytest.approx(reference[-1].criterion)

    # The three bad messages were counted, not fatal.
    def skipped():
        values = [kv.value for d in received['diagnostics'] for s in d.status
                  if s.name.endswith('input') for kv in s.values if kv.key == 'skipped']
        return int(values[-1]) if values else 0
    spin_until(executor, lambda: skipped() == 3, 10.0, 'skipped count in /diagnostics')
    assert node_process.process.poll() is None
    assert 'input skipped' in node_process.log()

    # Runtime parameters: invalid values rejected with a reason, read-only ones refused.
    client = AsyncParameterClient(test_node, 'flexlink_node')
    spin_until(executor, lambda: client.services_are_ready(), DISCOVERY_TIMEOUT_S,
               'parameter services')

    def set_parameter(name, value):
        future = client.set_parameters([Parameter(name, value=value)])
        spin_until(executor, future.done, 10.0, f'setting {name}')
        return future.result().results[0]

    result = set_parameter('diagnostics.criterion_warn', 5000.0)
    assert not result.successful and 'must not exceed' in result.reason
    result = set_parameter('markers.exaggeration', -1.0)
    assert not result.successful and result.reason
    assert not set_parameter('mechanism', 'kang1990').successful
    assert set_parameter('frame_id', 'machine_base').successful
    count = len(received['lever'])
    publisher.publish(joint_state(stamps[-1] + 10**6, ['crank'], [angles[-1] + 0.04], [speed]))
    spin_until(executor, lambda: len(received['lever']) > count, 10.0, 'output after change')
    assert received['lever'][-1].header.frame_id == 'machine_base'

    # SIGTERM closes the recording completely; two independent readers agree on it.
    assert node_process.stop(signal.SIGTERM) == 0
    from flexlink_ros.cli.mcap import mcap_info
    info = mcap_info(bag)
    assert info['complete'] and (bag / 'metadata.yaml').exists()
    inputs = len(stamps) + len(bad) + 1
    counts, recorded_stamps = read_with_rosbags(bag)
    assert counts['/joint_states'] == inputs
    for topic in OUTPUTS[:3]:
        assert counts[topic] == len(stamps) + 1
    assert counts[OUTPUTS[3]] == math.ceil((len(stamps) + 1) / 25)
    assert counts['/diagnostics'] >= 2
    assert recorded_stamps[OUTPUTS[0]][:len(stamps)] == stamps
    assert read_with_mcap_ros2(bag) == counts


def test_driver_to_node_and_sigkill_leaves_a_recoverable_file(tmp_path, processes):
    """crank_driver -> node in separate processes; SIGKILL mid-recording loses < 1 s."""
    from flexlink_ros.cli.mcap import mcap_info, recover_mcap

    bag = tmp_path / 'bag'
    node_process = NodeProcess(tmp_path, 'record.enabled:=true', f'record.path:={bag}')
    processes.append(node_process)
    node_process.wait_for(READY_MESSAGE, READY_TIMEOUT_S)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path))
    driver = subprocess.Popen([sys.executable, '-m', 'flexlink_ros.ros.crank_driver', '--ros-args',
                               '-p', 'speed_rpm:=269.0'], env=env,
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    processes.append(driver)
    node_process.wait_for(FIRST_INPUT_MESSAGE, DISCOVERY_TIMEOUT_S)
    time.sleep(2.5)    # recording time, not synchronisation
    killed_ns = time.time_ns()
    node_process.stop(signal.SIGKILL)
    driver.send_signal(signal.SIGINT)
    driver.wait(timeout=20)
    files = sorted(bag.glob('*.mcap'))
    assert len(files) == 1 and not mcap_info(files[0])['complete']
    recovered = tmp_path / 'recovered.mcap'
    result = recover_mcap(files[0], recovered)
    counts = {t['topic']: t['count'] for t in result['topics']}
    assert counts['/joint_states'] > 1000           # about 2.5 s at 1 kHz, less the loss
    assert (killed_ns - result['end_ns']) * 1e-9 < 1.0
    assert abs(counts['/flexlink_node/lever_tip/deflection'] - counts['/joint_states']) <= 2
    info = mcap_info(recovered)
    assert info['complete'] and info['message_count'] == result['message_count']
    rosbags_counts, _ = read_with_rosbags(recovered)
    assert rosbags_counts == {k: v for k, v in counts.items() if v}


@pytest.mark.parametrize('parameter, reason', [
    ('diagnostics.criterion_warn:=5000.0', 'must not exceed'),
    ('damping_ratio:=2.0', 'out of range'),         # refused by the descriptor's range
    ('model.order:=3', 'out of range'),             # 1 (linear KED) or 2 only
    ('qos.depth:=2.5', 'expecting type'),           # refused by the parameter's type
    ('frame_id:=' + 'x' * 300, 'frame_id must be at most 256 bytes, got 300'),
    ("frame_id:=''", 'frame_id must not be empty'),
])
def test_bad_parameters_file_value_stops_the_node_with_a_reason(tmp_path, processes, parameter,
                                                                reason):
    # The bad value in a /** params file of its own: with the shipped file and -p, rcl merges
    # a value of another type than the file's into the file's entry and keeps the file's.
    name, value = parameter.split(':=')
    params_file = tmp_path / 'bad.yaml'
    params_file.write_text(yaml.safe_dump({'/**': {'ros__parameters': {
        name: yaml.safe_load(value)}}}))
    node_process = NodeProcess(tmp_path, params_file=params_file)
    processes.append(node_process)
    assert node_process.process.wait(timeout=READY_TIMEOUT_S) == 1
    log = node_process.log()
    assert reason in log and 'Traceback' not in log
    assert log.strip().startswith(f'{NODE_NAME}: error:')


def test_a_mechanism_file_in_mm_stops_the_node_with_one_line(tmp_path, processes):
    data = yaml.safe_load((DATA / 'soft_aluminium.yaml').read_text())
    for link in data['links'].values():
        link['area_m2'] *= 1e6          # mm^2 and mm^4, the lengths in m
        link['second_moment_m4'] *= 1e12
    mechanism = tmp_path / 'soft_mm4.yaml'
    mechanism.write_text(yaml.safe_dump(data))
    node_process = NodeProcess(tmp_path, f'mechanism:={mechanism}',
                               f'model.cache_dir:={tmp_path}')
    processes.append(node_process)
    assert node_process.process.wait(timeout=READY_TIMEOUT_S) == 1
    log = node_process.log()
    assert 'Traceback' not in log and log.count('\n') == 1
    assert log.startswith(f'{NODE_NAME}: error: links.crank.second_moment_m4 = 5.625: radius '
                          'of gyration'), log
    assert 'mm^2 and mm^4' in log


def test_a_mechanism_name_that_spells_a_path_stops_the_node(tmp_path, processes):
    data = yaml.safe_load((PARAMS_FILE.parent / 'cho1992.yaml').read_text())
    data['name'] = '../../../escape/dir/x'
    mechanism = tmp_path / 'evil.yaml'
    mechanism.write_text(yaml.safe_dump(data))
    cache = tmp_path / 'a' / 'b' / 'c' / 'cache'
    node_process = NodeProcess(tmp_path, f'mechanism:={mechanism}', f'model.cache_dir:={cache}')
    processes.append(node_process)
    assert node_process.process.wait(timeout=READY_TIMEOUT_S) == 1
    log = node_process.log()
    assert log.strip().startswith(f'{NODE_NAME}: error: name:') and 'Traceback' not in log
    assert 'not a plain name' in log
    assert not (tmp_path / 'a' / 'escape').exists() and not cache.exists()


def test_managed_node_streams_only_while_active(tmp_path, processes, ros):
    """Lifecycle: configure loads the model, activate subscribes, deactivate stops, cleanup."""
    from geometry_msgs.msg import Vector3Stamped
    from lifecycle_msgs.msg import State, Transition
    from lifecycle_msgs.srv import ChangeState, GetState
    from sensor_msgs.msg import JointState

    bag = tmp_path / 'managed_bag'
    node_process = NodeProcess(tmp_path, 'record.enabled:=true', f'record.path:={bag}',
                               flags=['--managed'])
    processes.append(node_process)
    test_node, executor = ros
    get_state = answering_client(test_node, executor, GetState, '/flexlink_node/get_state',
                                 GetState.Request())
    change_state = lifecycle_client(test_node, executor, '/flexlink_node/change_state')

    def call(client, request):
        future = client.call_async(request)
        spin_until(executor, future.done, READY_TIMEOUT_S, type(request).__name__)
        return future.result()

    def transition(transition_id):
        return call(change_state, ChangeState.Request(
            transition=Transition(id=transition_id))).success

    def state():
        return call(get_state, GetState.Request()).current_state.id

    assert state() == State.PRIMARY_STATE_UNCONFIGURED
    assert test_node.count_subscribers('/joint_states') == 0 and not bag.exists()
    assert transition(Transition.TRANSITION_CONFIGURE)       # loads the model, opens the bag
    assert state() == State.PRIMARY_STATE_INACTIVE and bag.exists()
    assert test_node.count_subscribers('/joint_states') == 0

    received = []
    test_node.create_subscription(Vector3Stamped, OUTPUTS[0], received.append, 100)
    publisher = test_node.create_publisher(JointState, 'joint_states', 100)
    assert transition(Transition.TRANSITION_ACTIVATE)
    spin_until(executor, lambda: publisher.get_subscription_count() > 0
               and test_node.count_publishers(OUTPUTS[0]) > 0, DISCOVERY_TIMEOUT_S,
               'discovery')
    stamp = 1_900_000_000 * 10**9
    publisher.publish(joint_state(stamp, ['crank'], [0.5], [30.0]))
    spin_until(executor, lambda: received, 30.0, 'an output while active')
    assert received[0].header.stamp.sec * 10**9 + received[0].header.stamp.nanosec == stamp

    assert transition(Transition.TRANSITION_DEACTIVATE)
    spin_until(executor, lambda: publisher.get_subscription_count() == 0, DISCOVERY_TIMEOUT_S,
               'the subscription to go')
    assert transition(Transition.TRANSITION_CLEANUP)          # closes the recording
    assert state() == State.PRIMARY_STATE_UNCONFIGURED
    from flexlink_ros.cli.mcap import mcap_info
    info = mcap_info(bag)
    assert info['complete'] and {t['topic']: t['count'] for t in info['topics']}[
        '/joint_states'] == 1
    assert node_process.stop(signal.SIGTERM) == 0


def test_unwritable_recording_path_is_an_error_diagnostic_and_estimates_go_on(
        tmp_path, processes, ros):
    """record.path under a regular file (unwritable even for root): ERROR, outputs flow."""
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
    from geometry_msgs.msg import Vector3Stamped
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import JointState

    blocker = tmp_path / 'not_a_directory'
    blocker.write_text('a file where the recording directory should go')
    node_process = NodeProcess(tmp_path, 'record.enabled:=true',
                               f'record.path:={blocker / "bag"}', 'diagnostics.period_s:=0.2')
    processes.append(node_process)
    node_process.wait_for(READY_MESSAGE, READY_TIMEOUT_S)
    assert 'recording disabled' in node_process.log()

    test_node, executor = ros
    qos = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
    publisher = test_node.create_publisher(JointState, 'joint_states', qos)
    lever, diagnostics = [], []
    test_node.create_subscription(Vector3Stamped, OUTPUTS[0], lever.append, qos)
    test_node.create_subscription(DiagnosticArray, '/diagnostics', diagnostics.append, 10)
    spin_until(executor, lambda: publisher.get_subscription_count() > 0
               and test_node.count_publishers(OUTPUTS[0]) > 0 and diagnostics,
               DISCOVERY_TIMEOUT_S, 'discovery')
    speed = 30.0
    stamps = [1_800_000_000 * 10**9 + n * 10**6 for n in range(200)]
    for n, stamp in enumerate(stamps):
        publisher.publish(joint_state(stamp, ['crank'], [speed * n * 1e-3], [speed]))
        if n == 0:
            spin_until(executor, lambda: lever, 20.0, 'the first output')
        time.sleep(1e-3)
    spin_until(executor, lambda: len(lever) >= len(stamps), 20.0, 'all outputs')
    assert all(math.isfinite(m.vector.x) and math.isfinite(m.vector.y) for m in lever)

    def recorder_levels():
        return [s.level for d in diagnostics for s in d.status if s.name.endswith('recorder')]
    spin_until(executor, lambda: recorder_levels(), 10.0, 'a recorder status')
    assert recorder_levels()[-1] == DiagnosticStatus.ERROR
    message = [s.message for d in diagnostics for s in d.status
               if s.name.endswith('recorder')][-1]
    assert 'FAILED' in message and 'not_a_directory' in message
    assert node_process.stop(signal.SIGTERM) == 0
    assert blocker.read_text().startswith('a file')


# -- signals at start-up ----------------------------------------------------------------------

def _caught_signals(pid):
    """Signals the process has a handler for (SigCgt of /proc/<pid>/status)."""
    for line in pathlib.Path(f'/proc/{pid}/status').read_text().splitlines():
        if line.startswith('SigCgt:'):
            mask = int(line.split()[1], 16)
            return {signum for signum in range(1, 64) if mask >> (signum - 1) & 1}
    return set()


def _thread_count(pid):
    return len(list(pathlib.Path(f'/proc/{pid}/task').iterdir()))


@pytest.mark.parametrize('stage', ['imports', 'model build'])
@pytest.mark.parametrize('sig', [signal.SIGINT, signal.SIGTERM])
def test_signal_during_start_up_exits_cleanly(tmp_path, processes, stage, sig):
    """SIGINT/SIGTERM while importing or building the model: one line, exit 0, no traceback."""
    # A fresh cache: the model is built (a few seconds) after rclpy has started.
    node_process = NodeProcess(tmp_path, f'model.cache_dir:={tmp_path / "cache"}')
    processes.append(node_process)
    pid = node_process.process.pid
    deadline = time.monotonic() + 60.0
    # imports: the node's handlers are in place (before numpy, scipy and rclpy load);
    # model build: rclpy has started its DDS threads, the model is being built.
    while not (signal.SIGTERM in _caught_signals(pid) if stage == 'imports'
               else _thread_count(pid) > 8):
        assert node_process.process.poll() is None and time.monotonic() < deadline, \
            node_process.log()
        time.sleep(0.002)
    node_process.process.send_signal(sig)
    assert node_process.process.wait(timeout=60) == 0
    log = node_process.log()
    assert 'Traceback' not in log and READY_MESSAGE not in log
    expected = f'{NODE_NAME}: {sig.name} during start-up: exiting'
    assert [line for line in log.splitlines() if not line.startswith('[')] == [expected]


# -- run-time parameters ------------------------------------------------------------------------

def _status_of(diagnostics, suffix, since=0, until=None):
    return [s for d in diagnostics[since:until] for s in d.status if s.name.endswith(suffix)]


def test_run_time_parameters_take_effect(tmp_path, processes, ros):
    """Each parameter that is not read-only, changed on a running node, changes its output."""
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
    from geometry_msgs.msg import Vector3Stamped
    from rclpy.parameter import Parameter
    from rclpy.parameter_client import AsyncParameterClient
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import JointState
    from visualization_msgs.msg import MarkerArray

    node_process = NodeProcess(tmp_path, 'diagnostics.period_s:=0.5')
    processes.append(node_process)
    node_process.wait_for(READY_MESSAGE, READY_TIMEOUT_S)
    test_node, executor = ros
    qos = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
    publisher = test_node.create_publisher(JointState, 'joint_states', qos)
    lever, markers, diagnostics = [], [], []
    test_node.create_subscription(Vector3Stamped, OUTPUTS[0], lever.append, qos)
    test_node.create_subscription(MarkerArray, OUTPUTS[3], markers.append, 1000)
    test_node.create_subscription(DiagnosticArray, '/diagnostics', diagnostics.append, 1000)
    client = AsyncParameterClient(test_node, 'flexlink_node')
    spin_until(executor, lambda: publisher.get_subscription_count() > 0
               and test_node.count_publishers(OUTPUTS[0]) > 0 and diagnostics
               and client.services_are_ready(), DISCOVERY_TIMEOUT_S, 'discovery')

    def set_parameters(**values):
        future = client.set_parameters([Parameter(name.replace('__', '.'), value=value)
                                        for name, value in values.items()])
        spin_until(executor, future.done, 10.0, f'setting {values}')
        return future.result().results

    sample = [0]

    def feed(count, joint='crank', stamp_step_ns=10**6):
        """Publish ``count`` crank samples at 1 kHz; wait for their outputs."""
        expected = len(lever) + (count if joint is not None else 0)
        for _ in range(count):
            n = sample[0] = sample[0] + 1
            publisher.publish(joint_state(1_800_000_000 * 10**9 + n * stamp_step_ns,
                                          [joint or 'nothing'], [30.0 * n * 1e-3], [30.0]))
            time.sleep(1e-3)
            executor.spin_once(timeout_sec=0.0)
        spin_until(executor, lambda: len(lever) >= expected, 30.0, 'outputs')

    feed(50)
    # Strings are bounded: a 1 MB frame_id (once accepted) is refused with the reason.
    result, = set_parameters(frame_id='x' * 10**6)
    assert not result.successful and 'at most 256 bytes' in result.reason
    assert not set_parameters(crank_joint='')[0].successful

    # diagnostics.period_s: the timer is restarted with the new period.
    assert set_parameters(diagnostics__period_s=0.05)[0].successful
    since = len(diagnostics)
    spin_until(executor, lambda: len(diagnostics) >= since + 12, 10.0, 'faster diagnostics')
    stamps = [d.header.stamp.sec + d.header.stamp.nanosec * 1e-9 for d in diagnostics[since + 1:]]
    assert np.median(np.diff(stamps)) < 0.25     # was 0.5 s

    # crank_joint, frame_id: the next messages are read and stamped with the new values.
    assert all(r.successful for r in set_parameters(crank_joint='motor',
                                                    frame_id='machine_base'))
    feed(20, joint='motor')
    assert lever[-1].header.frame_id == 'machine_base'
    skipped = int([kv.value for kv in _status_of(diagnostics, 'input')[-1].values
                   if kv.key == 'skipped'][0])
    feed(5, joint=None)      # 'crank' is no longer the crank: refused and counted
    spin_until(executor, lambda: int([kv.value for kv in _status_of(diagnostics, 'input')[-1]
                                      .values if kv.key == 'skipped'][0]) == skipped + 5,
               10.0, 'five more skipped')
    assert set_parameters(crank_joint='crank')[0].successful

    # markers.*: every sample, five points per link, the exaggeration scales the drawing.
    def drawn_deflection(message):
        rigid, deformed = message.markers[4], message.markers[5]     # the lever
        pairs = zip(rigid.points, deformed.points)
        return max(abs(a.x - b.x) + abs(a.y - b.y) for a, b in pairs)
    assert all(r.successful for r in set_parameters(markers__every_n=1,
                                                    markers__points_per_link=5))
    before = len(markers)
    feed(20)
    spin_until(executor, lambda: len(markers) >= before + 19, 10.0, 'markers on every sample')
    assert len(markers[-1].markers[5].points) == 5
    small = drawn_deflection(markers[-1])
    assert set_parameters(markers__exaggeration=1000.0)[0].successful
    feed(20)
    spin_until(executor, lambda: len(markers) >= before + 39, 10.0, 'markers')
    assert drawn_deflection(markers[-1]) > 10.0 * small

    # diagnostics thresholds: each turns its status to WARN or ERROR. Statuses received
    # before the change was asked for were made with the old thresholds; those received
    # while set_parameters ran may have been made with either (the timer runs at 20 Hz).
    unchanged = len(diagnostics)
    assert all(r.successful for r in set_parameters(
        diagnostics__criterion_warn=0.0, diagnostics__criterion_error=0.0,
        diagnostics__min_rate_hz=1e6, diagnostics__error_indicator_warn=0.0))
    since = len(diagnostics)
    feed(100)
    spin_until(executor, lambda: len(diagnostics) >= since + 3, 10.0, 'diagnostics')
    assert not any(s.level == DiagnosticStatus.ERROR
                   for s in _status_of(diagnostics, 'joint A', 0, unchanged))
    assert any(s.level == DiagnosticStatus.ERROR
               for s in _status_of(diagnostics, 'joint A', since + 1))
    assert any('below' in s.message for s in _status_of(diagnostics, 'input', since + 1))
    assert any('error indicator' in s.message
               for s in _status_of(diagnostics, 'estimator', since + 1))
    assert set_parameters(diagnostics__stale_input_s=0.01)[0].successful
    since = len(diagnostics)
    spin_until(executor, lambda: any('no valid input for' in s.message and
                                     s.level == DiagnosticStatus.ERROR
                                     for s in _status_of(diagnostics, 'input', since)),
               10.0, 'stale input')

    # model.warm_start: after a reset (a 1 s gap) the start is static, not warm.
    def flags_after(since):
        return ' '.join(kv.value for s in _status_of(diagnostics, 'estimator', since)
                        for kv in s.values if kv.key == 'flags')
    assert set_parameters(model__warm_start=False)[0].successful
    since = len(diagnostics)
    feed(30, stamp_step_ns=2 * 10**9)   # every sample after a long gap: resets
    spin_until(executor, lambda: 'RESET' in flags_after(since), 10.0, 'a reset')
    assert 'WARM_START' not in flags_after(since)
    assert set_parameters(model__warm_start=True)[0].successful
    since = len(diagnostics)
    feed(3, stamp_step_ns=2 * 10**9)
    spin_until(executor, lambda: 'WARM_START' in flags_after(since), 10.0, 'a warm start')
    assert node_process.stop() == 0


def test_node_publishes_the_dynamic_pass(tmp_path, processes):
    """model.second_order:=dynamic: the node's recorded deflections are the replay's."""
    from flexlink_ros.core.estimation.offline import estimate_offline
    from rosbags.highlevel import AnyReader

    params = {'model.second_order': 'dynamic', 'model.rigid_crank': True,
              'model.bearings': 'rigid', 'model.elements_per_link': 3, 'model.grid_size': 32,
              'model.cache_dir': str(tmp_path / 'cache'), 'model.nonlinear': 'off'}
    bag = tmp_path / 'bag'
    node_process = NodeProcess(tmp_path, 'record.enabled:=true', f'record.path:={bag}',
                               *(f'{name}:={value}' for name, value in params.items()))
    processes.append(node_process)
    node_process.wait_for(READY_MESSAGE, READY_TIMEOUT_S)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path))
    driver = subprocess.Popen([sys.executable, '-m', 'flexlink_ros.ros.crank_driver', '--ros-args',
                               '-p', 'speed_rpm:=391.0'], env=env,
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    processes.append(driver)
    node_process.wait_for(FIRST_INPUT_MESSAGE, DISCOVERY_TIMEOUT_S)
    time.sleep(1.5)    # recording time, not synchronisation
    driver.send_signal(signal.SIGINT)
    driver.wait(timeout=20)
    assert node_process.stop(signal.SIGINT) == 0, node_process.log()
    inputs, published = [], {}
    with AnyReader([bag]) as reader:
        for connection, _, raw in reader.messages():
            if connection.topic == '/joint_states' or connection.topic.endswith('/deflection'):
                message = reader.deserialize(raw, connection.msgtype)
                stamp = message.header.stamp.sec * 10**9 + message.header.stamp.nanosec
                if connection.topic == '/joint_states':
                    inputs.append((stamp, message.position[0], message.velocity[0]))
                else:
                    published.setdefault(stamp, {})[connection.topic.split('/')[2]] = (
                        message.vector.x, message.vector.y)
    assert len(inputs) > 500
    values = dict(node_params.defaults(), **params)
    model, options, _ = load_node_model(values, lambda note: None)
    assert options.second_order == 'dynamic' and model.dynamic_second_order is not None
    stamps, angles, speeds = (np.array(column) for column in zip(*inputs))
    offline = estimate_offline(model, stamps.astype(np.int64), angles, speeds)
    worst, scale = 0.0, np.abs(offline['coupler_mid']).max()
    for n, stamp in enumerate(stamps.tolist()):
        if stamp in published and len(published[stamp]) == 2:
            for name in ('lever_tip', 'coupler_mid'):
                worst = max(worst, np.abs(np.subtract(published[stamp][name],
                                                      offline[name][n])).max())
    assert sum(len(p) == 2 for p in published.values()) > 500
    assert worst < 1e-6 * scale, worst / scale


def _recorded(bag):
    """Crank angle per input stamp and the published deflections per stamp, from a bag."""
    from rosbags.highlevel import AnyReader

    angles, published = {}, {}
    with AnyReader([bag]) as reader:
        for connection, _, raw in reader.messages():
            if connection.topic == '/joint_states' or connection.topic.endswith('/deflection'):
                message = reader.deserialize(raw, connection.msgtype)
                stamp = message.header.stamp.sec * 10**9 + message.header.stamp.nanosec
                if connection.topic == '/joint_states':
                    angles[stamp] = message.position[0]
                else:
                    published.setdefault(stamp, {})[connection.topic.split('/')[2]] = (
                        message.vector.x, message.vector.y)
    return angles, published


def _drive(tmp_path, processes, rpm, *parameters, seconds=2.0):
    """Run the node on the crank driver at ``rpm`` for ``seconds``, recording; the bag, log."""
    bag = tmp_path / f'bag_{time.monotonic_ns()}'
    node_process = NodeProcess(tmp_path, 'record.enabled:=true', f'record.path:={bag}',
                               *parameters)
    processes.append(node_process)
    node_process.wait_for(READY_MESSAGE, 300.0)     # a model build on a loaded machine
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path))
    driver = subprocess.Popen([sys.executable, '-m', 'flexlink_ros.ros.crank_driver', '--ros-args',
                               '-p', f'speed_rpm:={rpm}'], env=env,
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    processes.append(driver)
    node_process.wait_for(FIRST_INPUT_MESSAGE, DISCOVERY_TIMEOUT_S)
    time.sleep(seconds)    # recording time, not synchronisation
    driver.send_signal(signal.SIGINT)
    driver.wait(timeout=20)
    assert node_process.stop(signal.SIGINT) == 0, node_process.log()
    return bag, node_process.log()


def test_a_stiff_linkage_above_620_rpm_follows_its_files_speed_range(tmp_path, processes):
    """packaging_steel says 600 rpm: the node serves 750 rpm and matches `flexlink estimate`."""
    mechanism = DATA / 'packaging_steel.yaml'
    cache = tmp_path / 'cache'
    bag, log = _drive(tmp_path, processes, 700.0, f'mechanism:={mechanism}',
                      'model.grid_size:=64', f'model.cache_dir:={cache}')
    assert 'beyond the speed range' not in log, log
    assert re.search(r'speed_max=78\.53981', log), log      # 1.25 x 600 rpm
    done = subprocess.run([sys.executable, '-m', 'flexlink_ros.cli', 'estimate', '--mechanism',
                           str(mechanism), '--rpm', '700', '--grid-size', '64', '--cache-dir',
                           str(cache), '--json'], capture_output=True, text=True, timeout=600,
                          env=dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path)))
    assert done.returncode == 0, done.stderr
    assert 'building the model' not in done.stderr      # the node's model: the same key
    estimate = json.loads(done.stdout)
    order = np.argsort(estimate['crank_deg'])
    degrees = np.array(estimate['crank_deg'])[order]
    angles, published = _recorded(bag)
    stamps = sorted(s for s in published if len(published[s]) == 2 and s in angles)
    assert len(stamps) > 1000
    last = stamps[-500:]      # about 6 revolutions, long after the warm start
    crank = np.degrees(np.mod([angles[s] for s in last], 2.0 * np.pi))
    for name in ('lever_tip', 'coupler_mid'):
        node = np.array([published[s][name] for s in last])
        expected = np.column_stack([
            np.interp(crank, degrees, np.array(estimate[name][axis])[order], period=360.0)
            for axis in ('dx_m', 'dy_m')])
        peak = np.abs(expected).max()
        assert 1e-6 < peak < 1e-4      # tens of micrometres
        assert np.abs(node - expected).max() < 0.05 * peak, name


def test_samples_beyond_the_speed_range_are_logged_with_their_count(tmp_path, processes):
    mechanism = DATA / 'packaging_steel.yaml'
    _, log = _drive(tmp_path, processes, 700.0, f'mechanism:={mechanism}',
                    'model.speed_max_rpm:=650.0', 'model.rigid_crank:=true',
                    'model.elements_per_link:=2', 'model.grid_size:=32',
                    f'model.cache_dir:={tmp_path}', seconds=1.5)
    found = re.findall(r'crank at 700 rpm, beyond the speed range of the model of 650 rpm: '
                       r'(\d+) samples so far', log)
    assert found and int(found[0]) >= 1, log
    assert len(found) <= 4       # at most once a second
    assert int(found[-1]) > 500 and 'Traceback' not in log     # counted, every sample


def test_markers_arrive_every_nth_sample_with_its_stamp_and_are_recorded(tmp_path, processes,
                                                                         ros):
    """Markers drawn off the input callback: every 10th published sample, its stamp, recorded."""
    from geometry_msgs.msg import Vector3Stamped
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import JointState
    from visualization_msgs.msg import MarkerArray

    bag = tmp_path / 'markers'
    node_process = NodeProcess(tmp_path, 'record.enabled:=true', f'record.path:={bag}')
    processes.append(node_process)
    node_process.wait_for(READY_MESSAGE, READY_TIMEOUT_S)
    test_node, executor = ros
    qos = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
    publisher = test_node.create_publisher(JointState, 'joint_states', qos)
    lever, markers = [], []
    test_node.create_subscription(Vector3Stamped, OUTPUTS[0], lever.append, qos)
    test_node.create_subscription(MarkerArray, OUTPUTS[3], markers.append, qos)
    spin_until(executor, lambda: publisher.get_subscription_count() > 0
               and test_node.count_publishers(OUTPUTS[3]) > 0, DISCOVERY_TIMEOUT_S, 'discovery')
    speed, count = 391.0 * 2.0 * math.pi / 60.0, 400
    for n in range(count):
        publisher.publish(joint_state(1_800_000_000 * 10**9 + n * 10**6, ['crank'],
                                      [speed * n * 1e-3], [speed]))
        time.sleep(1e-3)
        executor.spin_once(timeout_sec=0.0)
    spin_until(executor, lambda: len(lever) >= count and len(markers) >= count // 10, 30.0,
               'outputs')
    assert node_process.stop(signal.SIGINT) == 0, node_process.log()

    def stamp_of(message):
        return message.header.stamp.sec * 10**9 + message.header.stamp.nanosec
    published = [stamp_of(message) for message in lever]
    assert len(published) == count
    # The markers.every_n default (10): published samples 0, 10, 20, ... each drawn once, in
    # order, with the stamp of its sample on the array and on every marker in it.
    assert [stamp_of(m.markers[0]) for m in markers] == published[::10]
    assert all(stamp_of(marker) == stamp_of(m.markers[0]) for m in markers for marker in m.markers)
    assert all(marker.header.frame_id == 'linkage_ground' for m in markers for marker in m.markers)
    # The recording holds the same arrays (read back by an independent reader), each at the
    # log time of its sample's deflection.
    recorded, log_times = {}, {}
    with open(next(bag.glob('*.mcap')), 'rb') as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        for _, channel, message, decoded in reader.iter_decoded_messages(
                topics=[OUTPUTS[0], OUTPUTS[3]]):
            is_marker = channel.topic == OUTPUTS[3]
            stamp = stamp_of(decoded.markers[0] if is_marker else decoded)
            log_times.setdefault(stamp, {})[channel.topic] = message.log_time
            if is_marker:
                recorded[stamp] = decoded
    assert sorted(recorded) == published[::10]
    assert all(len(log_times[s]) == 2 and len(set(log_times[s].values())) == 1 for s in recorded)
    for message in markers:
        stored = recorded[stamp_of(message.markers[0])]
        assert [[(p.x, p.y) for p in m.points] for m in stored.markers] == \
            [[(p.x, p.y) for p in m.points] for m in message.markers]
