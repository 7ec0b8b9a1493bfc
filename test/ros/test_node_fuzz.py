"""Hostile input to flexlink_node: mutated CDR in process and through a running node."""

import collections
import math
import struct
import time

from flexlink_ros.errors import InputRejected
from flexlink_ros.io import cdr
from flexlink_ros.names import READY_MESSAGE
from flexlink_ros.ros.message_outcomes import crank_sample, SKIP_KINDS
from flexlink_ros.ros.messages import ns_to_stamp
import numpy as np
import pytest
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import JointState
import test_node
from test_node import DISCOVERY_TIMEOUT_S, NodeProcess, OUTPUTS, READY_TIMEOUT_S, spin_until

ros = test_node.ros

STAMP0_NS = 1_800_000_000 * 10**9
SPEED = 30.0     # rad/s, about 290 rpm
SPECIAL_DOUBLES = (math.nan, math.inf, -math.inf, 1.7e308, -1.7e308, 1e6, 5e-324, 0.0)
HUGE_COUNTS = (0xFFFFFFFF, 0x80000000, cdr.MAX_JOINTS + 1, 10**6, 65536)


def valid_message(n, joints=('base', 'crank'), speed=SPEED):
    """CDR of the n-th sample of a crank at SPEED, 1 ms apart."""
    t = n * 1e-3
    message = JointState(name=list(joints), position=[0.0] * (len(joints) - 1) + [SPEED * t],
                         velocity=[0.0] * (len(joints) - 1) + [speed],
                         effort=[0.0] * len(joints))
    message.header.stamp = ns_to_stamp(STAMP0_NS + n * 10**6)
    message.header.frame_id = 'encoder'
    return serialize_message(message)


def mutate(data, rng):
    """One mutation of CDR bytes, and the name of its class."""
    data = bytearray(data)
    kind = int(rng.integers(10))
    if kind == 0:                                       # bit flips
        for _ in range(int(rng.integers(1, 9))):
            bit = int(rng.integers(8 * len(data)))
            data[bit // 8] ^= 1 << (bit % 8)
        return bytes(data), 'bit flips'
    if kind == 1:                                       # truncation
        # Not to 0 bytes: Fast DDS's reliable writer never delivers an empty payload and
        # holds every later sample of that writer behind it (the publisher's stream stalls).
        return bytes(data[:int(rng.integers(1, len(data)))]), 'truncated'
    if kind == 2:                                       # extension
        return bytes(data) + rng.bytes(int(rng.integers(1, 65))), 'extended'
    if kind == 3:                                       # a random length field
        offset = 4 * int(rng.integers(1, len(data) // 4))
        data[offset:offset + 4] = struct.pack('<I', int(rng.integers(2**32)))
        return bytes(data), 'random length field'
    if kind == 4:                                       # a huge count
        offset = 4 * int(rng.integers(1, len(data) // 4))
        data[offset:offset + 4] = struct.pack('<I', HUGE_COUNTS[rng.integers(len(HUGE_COUNTS))])
        return bytes(data), 'huge count'
    if kind == 5:                                       # NaN, inf, huge in the doubles
        offsets = list(range(len(data) - 8, 12, -8))[:6]
        for offset in rng.choice(offsets, size=int(rng.integers(1, 3)), replace=False):
            value = SPECIAL_DOUBLES[rng.integers(len(SPECIAL_DOUBLES))]
            data[offset:offset + 8] = struct.pack('<d', value)
        return bytes(data), 'special doubles'
    if kind == 6:                                       # zero stamp
        data[4:12] = bytes(8)
        return bytes(data), 'zero stamp'
    if kind == 7:                                       # random bytes
        return rng.bytes(int(rng.integers(1, 200))), 'random bytes'
    if kind == 8:                                       # another encapsulation
        data[0:2] = rng.bytes(2)
        return bytes(data), 'encapsulation'
    return bytes(data), 'unchanged'


def fuzzed_messages(count, seed):
    """``count`` (CDR, mutation class) pairs from valid samples with increasing stamps."""
    rng = np.random.default_rng(seed)
    bases = [valid_message(n, joints=('crank',) if n % 3 else ('base', 'crank'))
             for n in range(count)]
    return [mutate(data, rng) for data in bases]


def classify(data):
    """Classify CDR as the node's parse path does: 'ok' or the refusal's kind."""
    try:
        crank_sample(data, 'crank', lambda b: deserialize_message(b, JointState))
    except InputRejected as exc:
        return exc.kind
    return 'ok'


# -- in process ----------------------------------------------------------------------------------

def test_parse_path_refuses_every_mutation_with_a_reason():
    """100 000 mutations through the callback's parse function: refusals only, no escapes."""
    outcomes = collections.Counter()
    reasons = set()
    for data, mutation in fuzzed_messages(100_000, seed=12):
        try:
            crank_sample(data, 'crank', lambda b: deserialize_message(b, JointState))
            outcomes['ok', mutation] += 1
        except InputRejected as exc:
            outcomes[exc.kind, mutation] += 1
            assert '\n' not in str(exc) and len(str(exc)) < 300
            reasons.add(' '.join(str(exc).split(':')[0].split()[:2]))
    kinds = collections.Counter()
    for (kind, _), n in outcomes.items():
        kinds[kind] += n
    print('\nin-process fuzz, 100000 mutations:', dict(kinds), sorted(reasons))
    assert sum(kinds.values()) == 100_000
    assert kinds['malformed'] > 10_000 and kinds['content'] > 1_000 and kinds['ok'] > 10_000
    assert outcomes['ok', 'unchanged'] > 0 and not outcomes['ok', 'random bytes']


def test_truncated_effort_is_refused_not_raised():
    # The message that once killed the node: a NaN position and the effort array 8 bytes short.
    data = bytearray(valid_message(1))
    data[-40:-32] = struct.pack('<d', math.nan)
    data = bytes(data[:-8])
    from rclpy._rclpy_pybind11 import RMWError
    with pytest.raises(RMWError):
        deserialize_message(data, JointState)
    with pytest.raises(InputRejected, match='effort') as caught:
        crank_sample(data, 'crank', lambda b: deserialize_message(b, JointState))
    assert caught.value.kind == 'malformed'


def test_rclpy_deserialisation_error_is_a_refusal():
    # A parser that lets something through rclpy refuses: RMWError becomes a malformed refusal.
    def deserialize(data):
        return deserialize_message(data[:20], JointState)
    data = valid_message(1, joints=('base',))    # no crank: the slow path names why
    with pytest.raises(InputRejected, match='RMWError') as caught:
        crank_sample(data, 'crank', deserialize)
    assert caught.value.kind == 'malformed'


@pytest.mark.parametrize('offset_name, value, fragment', [
    ('names', cdr.MAX_JOINTS + 1, 'beyond the bound'),
    ('names', 0xFFFFFFFF, 'beyond the bound'),
    ('frame', cdr.MAX_NAME_BYTES + 2, 'beyond the bound'),
    ('frame', 200, 'bytes declared'),
])
def test_declared_lengths_are_checked_before_allocation(offset_name, value, fragment):
    data = bytearray(valid_message(1))
    offset = {'frame': 12, 'names': 12 + 4 + 8}[offset_name]   # frame 'encoder\0'
    data[offset:offset + 4] = struct.pack('<I', value)
    with pytest.raises(cdr.MalformedCdr, match=fragment):
        cdr.parse_joint_state(bytes(data), b'crank')


def test_oversized_message_is_refused():
    big = valid_message(1) + bytes(cdr.MAX_MESSAGE_BYTES)
    with pytest.raises(cdr.MalformedCdr, match='beyond the bound'):
        cdr.parse_joint_state(big, b'crank')


# -- through a running node ------------------------------------------------------------------

FUZZ_COUNT = 10_000
BATCH = 250


def latest_input_status(diagnostics):
    for message in reversed(diagnostics):
        for status in message.status:
            if status.name.endswith(': input'):
                return {kv.key: kv.value for kv in status.values}
    return {}


def lever_values(data):
    """x, y of a Vector3Stamped's CDR (the last 24 bytes are x, y, z)."""
    return struct.unpack_from('<3d', data, len(data) - 24)[:2]


def listen_to_node(ros, lever_depth):
    """
    Create a reliable JointState publisher, listen to the node's lever outputs, /diagnostics.

    Returns (publisher, lever CDR list, diagnostics list, executor) once discovery has matched
    both ways and a first /diagnostics message has arrived.
    """
    from diagnostic_msgs.msg import DiagnosticArray
    from geometry_msgs.msg import Vector3Stamped
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    test_node, executor = ros
    qos = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
    publisher = test_node.create_publisher(JointState, 'joint_states', qos)
    lever, diagnostics = [], []
    test_node.create_subscription(
        Vector3Stamped, OUTPUTS[0], lever.append,
        QoSProfile(depth=lever_depth, reliability=ReliabilityPolicy.RELIABLE), raw=True)
    test_node.create_subscription(DiagnosticArray, '/diagnostics', diagnostics.append, 100)
    spin_until(executor, lambda: publisher.get_subscription_count() > 0
               and test_node.count_publishers(OUTPUTS[0]) > 0 and diagnostics,
               DISCOVERY_TIMEOUT_S, 'discovery')
    return publisher, lever, diagnostics, executor


def test_fuzz_through_a_running_node(tmp_path, processes, ros):  # noqa: F811
    """10 000 mutated messages published raw to a node: it survives and counts each one."""
    # Warm starts off: the resets the mutated stamps cause are the estimator's business
    # (item 4); here every message must reach the parse path quickly.
    node_process = NodeProcess(tmp_path, 'diagnostics.period_s:=0.1', 'model.warm_start:=false',
                               'markers.every_n:=1000')
    processes.append(node_process)
    messages = fuzzed_messages(FUZZ_COUNT, seed=2026)
    expected = collections.Counter(classify(data) for data, _ in messages)
    node_process.wait_for(READY_MESSAGE, READY_TIMEOUT_S)

    publisher, lever, diagnostics, executor = listen_to_node(ros, lever_depth=20_000)

    def received():
        return int(latest_input_status(diagnostics).get('received', -1))

    # Reliable, at about 2 kHz, in batches; the next batch goes out once /diagnostics says
    # the node has taken the last one.
    for start in range(0, FUZZ_COUNT, BATCH):
        for n, (data, _) in enumerate(messages[start:start + BATCH]):
            publisher.publish(data)
            if n % 10 == 9:
                time.sleep(0.004)     # about 2 kHz: a raw burst overflows the transport
        spin_until(executor, lambda: received() >= start + BATCH
                   or node_process.process.poll() is not None, 60.0, 'the node to keep up',
                   lambda: f': {latest_input_status(diagnostics)}\n{node_process.log()[-3000:]}')
        assert node_process.process.poll() is None, node_process.log()[-3000:]

    # Valid messages after the fuzz are still answered.
    after = [valid_message(FUZZ_COUNT + 1000 + n) for n in range(20)]
    for data in after:
        publisher.publish(data)
    stamps = {STAMP0_NS + (FUZZ_COUNT + 1000 + n) * 10**6 for n in range(20)}

    def answered():
        return {struct.unpack_from('<iI', m, 4)[0] * 10**9 + struct.unpack_from('<iI', m, 4)[1]
                for m in lever[-40:]} >= stamps
    spin_until(executor, answered, 30.0, 'outputs for the valid messages after the fuzz')
    sent = FUZZ_COUNT + len(after)
    spin_until(executor, lambda: received() == sent, 10.0, 'the final counts')
    status = latest_input_status(diagnostics)
    counts = {key: int(status[key]) for key in (
        'received', 'published', 'skipped', 'skipped_malformed', 'skipped_content',
        'skipped_estimator', 'skipped_internal', 'outlier', 'repeated', 'out_of_bound')}
    print(f'\nnode fuzz: {FUZZ_COUNT} mutated + {len(after)} valid sent; expected from the '
          f'parse path {dict(expected)}; node counted {counts}')
    assert node_process.process.poll() is None
    assert counts['received'] == sent
    # Every message is accounted for once, and nothing reached the last resort.
    assert counts['published'] + counts['skipped_malformed'] + counts['skipped_content'] \
        + counts['skipped_estimator'] + counts['outlier'] + counts['repeated'] \
        + counts['out_of_bound'] == sent
    assert counts['skipped_internal'] == 0
    # The state-free refusals are the parse path's, to within the few messages the transport
    # changes (Fast DDS pads a payload to a multiple of 4 bytes and notes it in the
    # encapsulation options: a cut message can become whole or the reverse).
    for kind in ('malformed', 'content'):
        assert abs(counts[f'skipped_{kind}'] - expected[kind]) <= 0.01 * FUZZ_COUNT
    assert counts['skipped'] == sum(counts[f'skipped_{k}'] for k in SKIP_KINDS)
    spin_until(executor, lambda: len(lever) >= counts['published'], 10.0, 'every output')
    assert len(lever) == counts['published']
    assert all(math.isfinite(v) for m in lever for v in lever_values(m))
    assert 'Traceback' not in node_process.log()
    assert node_process.stop() == 0


def estimator_statuses(diagnostics):
    return [status for message in diagnostics for status in message.status
            if status.name.endswith(': estimator')]


def test_repeats_are_not_published_and_a_poison_speed_is_not_ok(
        tmp_path, processes, ros):  # noqa: F811
    """
    Exact repeats are counted, not published; 1e6 rad/s never passes as OK or as a number.

    One message beyond the 1 MiB bound goes in too: refused as malformed, unrecorded.
    """
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
    from flexlink_ros.core.estimation.streaming import StreamingEstimator
    from geometry_msgs.msg import Vector3Stamped
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from test_node import node_model

    node_process = NodeProcess(tmp_path, 'diagnostics.period_s:=0.2')
    processes.append(node_process)
    bound_m = getattr(StreamingEstimator(node_model()), 'deflection_bound_m', None)
    node_process.wait_for(READY_MESSAGE, READY_TIMEOUT_S)
    test_node, executor = ros
    qos = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
    publisher = test_node.create_publisher(JointState, 'joint_states', qos)
    lever, diagnostics = [], []
    test_node.create_subscription(Vector3Stamped, OUTPUTS[0], lever.append, qos, raw=True)
    test_node.create_subscription(DiagnosticArray, '/diagnostics', diagnostics.append, 100)
    spin_until(executor, lambda: publisher.get_subscription_count() > 0
               and test_node.count_publishers(OUTPUTS[0]) > 0 and diagnostics,
               DISCOVERY_TIMEOUT_S, 'discovery')

    count, repeated, poison, oversized = 400, range(50, 60), 200, 100
    sent = 0
    for n in range(count):
        data = valid_message(n, speed=1e6 if n == poison else SPEED)
        publisher.publish(data)
        sent += 1
        if n in repeated:
            publisher.publish(data)     # the same bytes again: an exact repeat
            sent += 1
        if n == oversized:
            publisher.publish(data + bytes(cdr.MAX_MESSAGE_BYTES))
            sent += 1
        if n == 0:
            spin_until(executor, lambda: lever, 30.0, 'the first output (warm start)')
        if n == poison:
            poison_wall = time.monotonic()
        time.sleep(1e-3)
        executor.spin_once(timeout_sec=0.0)
    spin_until(executor, lambda: int(latest_input_status(diagnostics).get('received', 0))
               == sent, 20.0, 'the counts', lambda: f': {latest_input_status(diagnostics)}')
    spin_until(executor, lambda: time.monotonic() > poison_wall + 0.5, 5.0, 'a period more')
    status = latest_input_status(diagnostics)
    spin_until(executor, lambda: len(lever) >= int(status['published']), 10.0, 'outputs')

    stamps = [struct.unpack_from('<iI', m, 4) for m in lever]
    assert int(status['repeated']) == len(repeated)
    assert int(status['skipped_malformed']) == 1 and 'beyond the bound' in status[
        'last_skip_reason']
    assert len(stamps) == len(set(stamps)) == int(status['published'])   # none twice
    values = np.array([lever_values(m) for m in lever])
    assert np.all(np.isfinite(values))
    if bound_m is not None:
        assert np.max(np.abs(values)) <= bound_m
    statuses = estimator_statuses(diagnostics)
    not_ok = [s for s in statuses if s.level != DiagnosticStatus.OK]
    assert not_ok, 'the estimator status stayed OK through the poison sample'
    assert any(word in s.message for s in not_ok
               for word in ('flagged', 'outlier', 'not published'))
    normal = np.max(np.abs(values[:poison - 10]))
    print(f'\npoison 1e6 rad/s: {len(lever)} of {count} samples published, '
          f'{status["outlier"]} outliers, {status["out_of_bound"]} out of bound, '
          f'{status["skipped"]} skipped, {status["repeated"]} repeats ignored; '
          f'max |lever deflection| {normal:.3g} m before, {np.max(np.abs(values)):.3g} m '
          f'overall (bound {bound_m}); estimator levels '
          f'{sorted({s.level for s in statuses})}: {not_ok[0].message!r}')
    assert node_process.stop() == 0


def storm_message(k, speed):
    """CDR of a sample whose stamp is 1 ms before the previous storm message's."""
    message = JointState(name=['crank'], position=[0.1 * k], velocity=[speed], effort=[0.0])
    message.header.stamp = ns_to_stamp(STAMP0_NS + (STORM_COUNT - k) * 10**6)
    return serialize_message(message)


STORM_COUNT = 1000
AFTER_STORM = 200


def test_reset_storm_does_not_stall_the_node(tmp_path, processes, ros):  # noqa: F811
    """
    1000 backward stamps, a new speed each (every one a restart), then 200 valid samples.

    Each restart asked for a warm start (about 0.1 s of shooting): the node fell 100 s
    behind and dropped the valid input queued behind the storm. Warm starts are now
    rate-limited, so every message is taken and every valid sample after it is answered.
    """
    node_process = NodeProcess(tmp_path, 'diagnostics.period_s:=0.2')
    processes.append(node_process)
    node_process.wait_for(READY_MESSAGE, READY_TIMEOUT_S)
    publisher, lever, diagnostics, executor = listen_to_node(ros, lever_depth=5000)

    for k in range(STORM_COUNT):
        publisher.publish(storm_message(k, 20.0 + 0.04 * k))
        time.sleep(1e-3)
        executor.spin_once(timeout_sec=0.0)
    after = [valid_message(3 * STORM_COUNT + n) for n in range(AFTER_STORM)]
    for data in after:
        publisher.publish(data)
        time.sleep(1e-3)
        executor.spin_once(timeout_sec=0.0)
    stamps = {STAMP0_NS + (3 * STORM_COUNT + n) * 10**6 for n in range(AFTER_STORM)}

    def answered():
        seen = set()
        for m in lever:
            sec, nanosec = struct.unpack_from('<iI', m, 4)
            seen.add(sec * 10**9 + nanosec)
        return seen >= stamps
    spin_until(executor, answered, 60.0, 'outputs for every valid sample after the storm',
               lambda: f': {latest_input_status(diagnostics)}\n{node_process.log()[-2000:]}')
    sent = STORM_COUNT + AFTER_STORM
    spin_until(executor, lambda: int(latest_input_status(diagnostics).get('received', 0))
               == sent, 20.0, 'the counts', lambda: f': {latest_input_status(diagnostics)}')
    status = latest_input_status(diagnostics)
    print(f'\nreset storm: {sent} sent; node counted {status}')
    assert int(status['received']) == sent        # nothing dropped from the queue
    assert int(status['skipped_internal']) == 0
    assert 'warm start skipped' in node_process.log(), node_process.log()[-2000:]
    assert node_process.stop() == 0
