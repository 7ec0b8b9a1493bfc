"""
End-to-end latency, loss and footprint of flexlink_node next to a bare rclpy echo node.

    python benchmarks/node_bench.py [--rate-hz 1000] [--max-rate-hz 8000] [--seconds 3]
        [--runs 1] [--reference-root OTHER] [--no-recording] [--out DIR] [--json]
        [--node-param NAME:=VALUE ...]

Prints figures (it is not a timed test). One run measures, on loopback in a domain of its own,
a bare rclpy echo node (JointState in, the same bytes out: the floor any Python node pays)
under rclpy's EventsExecutor (the node's executor) and under ``rclpy.spin`` (the
SingleThreadedExecutor a plain rclpy node spins in), and flexlink_node without and with
recording, each in its own process (the node of this source tree, not an installed copy):

- latency JointState -> output (the output carries the input's stamp, which is the send time):
  p50 and p99 at each rate;
- CPU: the target process's CPU time (all its threads, user and system) per input message at
  each rate, a figure that the machine's load disturbs less than the latency;
- loss: inputs sent minus outputs received at each rate; the highest rate without loss;
- RSS of the node process; recording throughput (messages and bytes per second written).

The source publishes at rates doubling from ``--rate-hz`` until messages are lost or
``--max-rate-hz`` is reached, for ``--seconds`` each. ``--runs`` repeats the whole run;
``--reference-root`` adds, in every run, the node of another source tree (an export of an
older commit, its extensions built in place), the two nodes measured in alternating order.
"""

import argparse
import json
import math
import os
import pathlib
import struct
import subprocess
import sys
import tempfile
import time

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))       # the tree's package, not an installed copy
from flexlink_ros.cli.mcap import mcap_info  # noqa: E402, I201
from flexlink_ros.io.cdr import CDR_LE  # noqa: E402, I201
from flexlink_ros.io.msg_schema import message_class  # noqa: E402, I201
from flexlink_ros.names import JOINT_STATE, VECTOR3_STAMPED  # noqa: E402, I201
from flexlink_ros.ros.runtime import (isolate_ros_environment, make_executor,  # noqa: E402, I201
                                      spin_until_shutdown)
import numpy as np  # noqa: E402, I201

INPUT_TOPIC = '/bench/joint_states'
ECHO_TOPIC = '/bench/echo'
NODE_OUTPUT = '/flexlink_node/lever_tip/deflection'
SPEED = 391.0 * 2.0 * math.pi / 60.0   # rad/s
WARMUP_MESSAGES = 500      # before measuring (the node's warm start happens here)
DRAIN_S = 1.0              # wait for the last outputs after a rate step [s]
START_TIMEOUT_S = 300.0
WARMUP_TIMEOUT_S = 60.0
SPIN_LEAD_S = 1e-4        # wake this early before a due publication [s]
KEEPALIVE_HZ = 50.0        # input rate between measured rate steps [Hz]


def _stamp_of(data):
    """Stamp [ns] of a CDR message whose first field is a std_msgs/Header."""
    sec, nanosec = struct.unpack_from('<iI', data, 4)
    return sec * 1_000_000_000 + nanosec


def _rss_mb(pid):
    try:
        for line in pathlib.Path(f'/proc/{pid}/status').read_text().splitlines():
            if line.startswith('VmRSS:'):
                return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return None


def echo_main(executor_kind):
    """Run the bare echo node: republish every JointState unchanged (raw bytes)."""
    import rclpy
    from rclpy.executors import ExternalShutdownException
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    joint_state = message_class(JOINT_STATE)
    try:
        with rclpy.init():
            node = rclpy.create_node('bench_echo')
            qos = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
            publisher = node.create_publisher(joint_state, ECHO_TOPIC, qos)
            node.create_subscription(joint_state, INPUT_TOPIC, publisher.publish, qos, raw=True)
            if executor_kind == 'spin':
                rclpy.spin(node)      # a plain rclpy node: the SingleThreadedExecutor
            else:
                executor = make_executor()
                executor.add_node(node)
                spin_until_shutdown(executor)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass


class Source:
    """Publishes crank JointStates and collects the target's outputs (one thread)."""

    def __init__(self):
        import rclpy
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.qos import QoSProfile, ReliabilityPolicy

        joint_state = message_class(JOINT_STATE)
        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node('bench_source', context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.qos = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
        self.publisher = self.node.create_publisher(joint_state, INPUT_TOPIC, self.qos)
        self.received = []
        self._subscriptions = {}
        self._prefix = CDR_LE
        self._types = {'echo': joint_state}

    def listen(self, topic, msg_type):
        """Subscribe to a target's output (raw; only the stamp is read)."""
        if topic not in self._subscriptions:
            self._subscriptions[topic] = self.node.create_subscription(
                msg_type, topic, lambda data: self.received.append(
                    (time.time_ns(), _stamp_of(data))), self.qos, raw=True)

    def message(self, stamp_ns):
        """CDR of a one-joint JointState at a stamp (angle of the constant-speed crank)."""
        sec, nanosec = divmod(stamp_ns, 1_000_000_000)
        angle = math.fmod(SPEED * stamp_ns * 1e-9, 2.0 * math.pi)
        data = self._prefix + struct.pack('<iII', sec, nanosec, 1) + b'\x00'
        data += b'\x00' * 3 + struct.pack('<I', 1) + struct.pack('<I', 6) + b'crank\x00'
        data += b'\x00' * ((-(len(data) - 4)) % 4) + struct.pack('<I', 1)
        data += b'\x00' * ((-(len(data) - 4)) % 8) + struct.pack('<d', angle)
        data += struct.pack('<I', 1) + b'\x00' * ((-(len(data) + 4 - 4)) % 8)
        data += struct.pack('<d', SPEED) + struct.pack('<I', 0)
        return data

    def wait_for(self, condition, timeout_s, what):
        deadline = time.monotonic() + timeout_s
        while not condition():
            if time.monotonic() > deadline:
                raise RuntimeError(f'timed out waiting for {what}')
            self.executor.spin_once(timeout_sec=0.02)

    def stream(self, rate_hz, seconds):
        """Publish at a rate; returns the stamps sent."""
        period_ns = int(1e9 / rate_hz)
        sent = []
        start = time.time_ns()
        due = start
        end = start + int(seconds * 1e9)
        while due < end:
            now = time.time_ns()
            if now >= due:
                self.publisher.publish(self.message(now))
                sent.append(now)
                due += period_ns
            else:
                # Wait in the executor (outputs are received meanwhile) rather than spin
                # busily: on two cores a busy source takes the CPU the target needs.
                self.executor.spin_once(timeout_sec=max(0.0, (due - now) * 1e-9 - SPIN_LEAD_S))
        return sent

    def drain(self, seconds=DRAIN_S):
        """
        Collect late outputs while a slow keep-alive stream goes on (not measured).

        A pause longer than the estimator's reset gap (0.5 s) would restart it, and the
        warm start of the restart would be measured as latency of the next rate step.
        """
        self.stream(KEEPALIVE_HZ, seconds)

    def close(self):
        self.executor.shutdown()
        self.node.destroy_node()
        self.context.try_shutdown()


def measure_target(source, name, argv, output_topic, output_type, rates, seconds, env):
    """Start a target, step through the rates, stop it; returns its rows and footprint."""
    process = subprocess.Popen(argv, env=env, stdout=subprocess.DEVNULL, cwd=env['PYTHONPATH'],
                               stderr=subprocess.DEVNULL)
    try:
        source.listen(output_topic, output_type)
        source.wait_for(lambda: source.publisher.get_subscription_count() > 0
                        and source.node.count_publishers(output_topic) > 0
                        or process.poll() is not None, START_TIMEOUT_S, f'{name} to start')
        if process.poll() is not None:
            raise RuntimeError(f'{name} exited with code {process.returncode}')
        _warm_up(source, name, process)
        rows = _step_rates(source, rates, seconds, process.pid)
        rss = _rss_mb(process.pid)
    finally:
        process.send_signal(2)   # SIGINT: the node closes its recording
        try:
            process.wait(timeout=30)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()
    lossless = [row['rate_hz'] for row in rows if row['lost'] == 0]
    return {'name': name, 'rows': rows, 'rss_mb': rss,
            'max_rate_without_loss_hz': max(lossless) if lossless else 0.0}


def _warm_up(source, name, process):
    """Stream until the target answers, then until its start-up backlog is answered."""
    # Warm up in batches until outputs flow: outputs published before discovery has
    # matched the listener both ways are lost, so one fixed batch may never be answered.
    source.received.clear()
    deadline = time.monotonic() + WARMUP_TIMEOUT_S
    last = None
    while len(source.received) < WARMUP_MESSAGES:
        if time.monotonic() > deadline or process.poll() is not None:
            raise RuntimeError(f'timed out waiting for {name} warm-up outputs '
                               f'({len(source.received)} of {WARMUP_MESSAGES})')
        last = max(source.stream(1000.0, 0.1))
        source.drain(0.05)

    # Measure the steady state: the target's first sample (the node's warm start, 0.2 s)
    # leaves a backlog, which must be answered before the first rate step starts. The
    # target answers in order, so the backlog is gone once the last warm-up message is
    # answered (the messages sent before discovery matched are never answered, and a
    # full input queue drops the oldest, never the last).
    def answered():
        return any(stamp == last for _, stamp in source.received)

    while not answered() and time.monotonic() < deadline and process.poll() is None:
        source.drain(0.1)
    if not answered():
        raise RuntimeError(f'{name} did not answer its last warm-up message in time')


def _cpu_s(pid):
    """CPU time [s] a process used so far, all its threads, user and system (None: gone)."""
    try:
        fields = pathlib.Path(f'/proc/{pid}/stat').read_text().rsplit(')', 1)[1].split()
    except (OSError, IndexError):
        return None
    return (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')


def _step_rates(source, rates, seconds, pid):
    """Stream at each rate in turn until one loses messages; return a row per rate."""
    rows = []
    for rate in rates:
        source.drain(0.2)
        source.received.clear()
        cpu_before = _cpu_s(pid)
        sent = source.stream(rate, seconds)
        cpu_after = _cpu_s(pid)
        source.drain()
        wanted = set(sent)
        latency = np.array([recv - stamp for recv, stamp in source.received
                            if stamp in wanted]) / 1e3
        rows.append({'rate_hz': len(sent) / seconds, 'sent': len(sent),
                     'received': int(latency.size), 'lost': len(sent) - int(latency.size),
                     'latency_us_p50': float(np.median(latency)) if latency.size else None,
                     'latency_us_p99': (float(np.percentile(latency, 99))
                                        if latency.size else None),
                     'cpu_us_per_message': (None if None in (cpu_before, cpu_after) else
                                            (cpu_after - cpu_before) * 1e6 / len(sent))})
        if rows[-1]['lost'] > 0:
            break
    return rows


def rate_steps(rate_hz, max_rate_hz):
    """Return the rates doubling from ``rate_hz`` up to ``max_rate_hz``."""
    rates = []
    rate = rate_hz
    while rate <= max_rate_hz:
        rates.append(rate)
        rate *= 2.0
    return rates


def bench_targets(bag, recording=True, reference_root=None, reference_first=False,
                  node_params=()):
    """Return (name, argv, output topic, output type, source root) of every target of a run."""
    node = [sys.executable, '-m', 'flexlink_ros.ros.node', '--ros-args',
            '-p', f'input_topic:={INPUT_TOPIC}', '-p', 'qos.depth:=1000']
    for item in node_params:
        node += ['-p', item]
    joint_state, vector3_stamped = message_class(JOINT_STATE), message_class(VECTOR3_STAMPED)
    nodes = [('flexlink_node', node, NODE_OUTPUT, vector3_stamped, ROOT)]
    if reference_root is not None:
        nodes.insert(1 - reference_first, ('flexlink_node (reference)', node, NODE_OUTPUT,
                                           vector3_stamped, pathlib.Path(reference_root)))
    echo = [sys.executable, str(pathlib.Path(__file__).resolve()), '--echo']
    targets = [('echo (EventsExecutor)', echo + ['events'], ECHO_TOPIC, joint_state, ROOT),
               ('echo (rclpy.spin)', echo + ['spin'], ECHO_TOPIC, joint_state, ROOT), *nodes]
    if recording:
        targets.append(('flexlink_node + recording', node + [
            '-p', 'record.enabled:=true', '-p', f'record.path:={bag}'],
            NODE_OUTPUT, vector3_stamped, ROOT))
    return targets


def run_node_bench(rate_hz=1000.0, max_rate_hz=8000.0, seconds=3.0, work_dir=None,
                   recording=True, reference_root=None, reference_first=False,
                   node_params=()):
    """
    Run the benchmark once (see the module docstring).

    Parameters
    ----------
    rate_hz : float
        First input rate [Hz]; doubled until ``max_rate_hz`` or a loss.
    max_rate_hz : float
        Highest input rate [Hz].
    seconds : float
        Time per rate [s].
    work_dir : str or os.PathLike, optional
        Directory of the bench recording (default: a new temporary directory).
    recording : bool
        Also measure the node with its recording on.
    reference_root : str or os.PathLike, optional
        Source tree of a second node to measure (run with its root on PYTHONPATH).
    reference_first : bool
        Measure the reference node before this tree's.
    node_params : sequence of str
        ``name:=value`` parameters of every node measured (both trees).

    Returns
    -------
    dict
        'targets': list of {name, rows, rss_mb, max_rate_without_loss_hz}, 'recording':
        {messages_per_s, bytes_per_s, path} (None without recording).

    """
    if not 0 < rate_hz <= max_rate_hz or not seconds > 0:
        raise ValueError('need 0 < `--rate-hz` <= `--max-rate-hz` and `--seconds` > 0')
    domain = isolate_ros_environment()
    rates = rate_steps(rate_hz, max_rate_hz)
    work_dir = pathlib.Path(work_dir or tempfile.mkdtemp(prefix='flexlink_node_bench_'))
    bag = work_dir / 'bench_bag'
    source = Source()
    results = []
    try:
        for name, argv, topic, msg_type, root in bench_targets(bag, recording, reference_root,
                                                               reference_first, node_params):
            env = dict(os.environ, PYTHONPATH=str(root))
            results.append(measure_target(source, name, argv, topic, msg_type, rates,
                                          seconds, env))
    finally:
        source.close()
    return {'domain_id': domain, 'seconds_per_rate': seconds, 'targets': results,
            'recording': recording_figures(bag) if recording else None}


def recording_figures(bag):
    """Messages and bytes per second the node with recording on wrote."""
    info = mcap_info(bag)
    duration = info['duration_s'] or math.nan
    size = sum(p.stat().st_size for p in bag.glob('*.mcap'))
    return {'path': str(bag), 'messages': info['message_count'],
            'messages_per_s': info['message_count'] / duration,
            'bytes_per_s': size / duration, 'complete': info['complete']}


def _text(result):
    lines = [f'{"target":<27} {"rate Hz":>8} {"sent":>6} {"lost":>5} {"p50 us":>7} '
             f'{"p99 us":>7} {"CPU us":>7}']
    for target in result['targets']:
        for row in target['rows']:
            p50 = '-' if row['latency_us_p50'] is None else f'{row["latency_us_p50"]:.0f}'
            p99 = '-' if row['latency_us_p99'] is None else f'{row["latency_us_p99"]:.0f}'
            cpu = ('-' if row['cpu_us_per_message'] is None
                   else f'{row["cpu_us_per_message"]:.0f}')
            lines.append(f'{target["name"]:<27} {row["rate_hz"]:>8.0f} {row["sent"]:>6} '
                         f'{row["lost"]:>5} {p50:>7} {p99:>7} {cpu:>7}')
    for target in result['targets']:
        rss = '?' if target['rss_mb'] is None else f'{target["rss_mb"]:.0f} MB'
        lines.append(f'{target["name"]}: highest rate without loss '
                     f'{target["max_rate_without_loss_hz"]:.0f} Hz, RSS {rss}')
    lines += _overhead_lines(result['targets'])
    rec = result['recording']
    if rec is not None:
        lines.append(f'recording: {rec["messages_per_s"]:.0f} messages/s, '
                     f'{rec["bytes_per_s"] / 1e3:.0f} kB/s ({rec["path"]})')
    return '\n'.join(lines)


def _overhead_lines(targets):
    """Each node's latency at the first rate against each echo's: p50 above, p99 ratio."""
    def first_row(target):
        row = target['rows'][0] if target['rows'] else {}
        return row if row.get('latency_us_p50') is not None else None

    echoes = [(t['name'], first_row(t)) for t in targets if t['name'].startswith('echo')]
    lines = []
    for target in targets:
        row = first_row(target)
        if target['name'].startswith('echo') or row is None:
            continue
        for name, echo in echoes:
            if echo is not None:
                lines.append(f'{target["name"]} vs {name} at {row["rate_hz"]:.0f} Hz: p50 '
                             f'{row["latency_us_p50"] - echo["latency_us_p50"]:+.0f} us, p99 '
                             f'{row["latency_us_p99"] / echo["latency_us_p99"]:.2f}x')
    return lines


def build_parser():
    """Build the command-line parser (see the module docstring)."""
    parser = argparse.ArgumentParser(description='latency, loss and footprint of '
                                     'flexlink_node next to a bare rclpy echo node')
    parser.add_argument('--rate-hz', type=float, default=1000.0, help='first rate [Hz]')
    parser.add_argument('--max-rate-hz', type=float, default=8000.0,
                        help='stop doubling the rate here [Hz]')
    parser.add_argument('--seconds', type=float, default=3.0, help='time per rate [s]')
    parser.add_argument('--runs', type=int, default=1, help='whole runs, one after another')
    parser.add_argument('--reference-root', type=pathlib.Path, default=None,
                        help='also measure the node of this source tree (alternating order)')
    parser.add_argument('--no-recording', dest='recording', action='store_false',
                        help='leave out the node with recording on')
    parser.add_argument('--out', default=None, help='directory of the bench recordings '
                        '(default: a new temporary directory)')
    parser.add_argument('--node-param', dest='node_params', action='append', default=[],
                        metavar='NAME:=VALUE', help='a parameter of every node measured '
                        '(repeatable), e.g. model.nonlinear:=off')
    parser.add_argument('--json', action='store_true', help='print one JSON object per run')
    parser.add_argument('--echo', choices=('events', 'spin'), help=argparse.SUPPRESS)
    return parser


def main(argv=None):
    """Run the benchmark (or, with ``--echo``, be the echo node it starts)."""
    args = build_parser().parse_args(argv)
    if args.echo:
        echo_main(args.echo)
        return 0
    out = pathlib.Path(args.out or tempfile.mkdtemp(prefix='flexlink_node_bench_'))
    for run in range(args.runs):
        result = run_node_bench(args.rate_hz, args.max_rate_hz, args.seconds,
                                out / f'run{run + 1}', args.recording, args.reference_root,
                                reference_first=run % 2 == 1, node_params=args.node_params)
        result['run'] = run + 1
        print(json.dumps(result) if args.json else f'run {run + 1}\n{_text(result)}',
              flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
