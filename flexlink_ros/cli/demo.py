"""
`flexlink demo`: crank_driver and flexlink_node as separate ROS 2 processes, recorded, summarised.

The demo keeps all traffic on this machine (``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` and the
loopback Fast DDS profile ``config/fastdds_localhost.xml``) in a domain of its own, starts the
node (recording its input and outputs to a rosbag2 MCAP bag), waits until it is ready, starts
the 1 kHz crank driver, lets them run for ``--seconds`` after the first sample reaches the node,
stops both with SIGINT (the node closes the recording with its summary), reads the bag back and
prints what it holds.
"""

import os
import pathlib
import queue
import re
import signal
import subprocess
import sys
import threading
import time

from .demo_summary import summarise_recording
from .main import emit
from ..core.mechanism_file import find_config
from ..names import FIRST_INPUT_MESSAGE, READY_MESSAGE
from ..ros.runtime import isolate_ros_environment

READY_TIMEOUT_S = 300.0    # node start-up, including a first model build on a slow machine
FIRST_SAMPLE_TIMEOUT_S = 30.0  # discovery between driver and node (0-3 s on loopback)
STOP_TIMEOUT_S = 20.0      # after SIGINT, before SIGTERM, then SIGKILL
FOXGLOVE_URL = 'https://app.foxglove.dev'
# The driver's exit line (ros/crank_driver.py CrankDriver.summary).
DRIVER_SUMMARY = re.compile(r'crank_driver: published (\d+) JointState messages \((\d+) while '
                            r'a subscriber was matched\); the timer skipped (\d+) periods')


class ManagedProcess:
    """A child process whose stderr and stdout lines are collected by a thread."""

    def __init__(self, name, argv, env):
        self.name = name
        self.lines = []
        self._queue = queue.Queue()
        self.process = subprocess.Popen(argv, env=env, stdin=subprocess.DEVNULL,
                                        stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                        text=True, bufsize=1)
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self):
        for line in self.process.stdout:
            line = line.rstrip('\n')
            self.lines.append(line)
            self._queue.put(line)
        self._queue.put(None)

    def wait_for_line(self, fragment, timeout_s):
        """
        Wait until a line containing ``fragment`` arrived.

        Parameters
        ----------
        fragment : str
            Text the line contains.
        timeout_s : float
            How long to wait [s].

        Returns
        -------
        bool
            True once such a line arrived; False on timeout or when the process ended.

        """
        if any(fragment in line for line in self.lines):
            return True
        deadline = time.monotonic() + timeout_s
        while True:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                return False
            try:
                line = self._queue.get(timeout=min(remaining, 0.5))
            except queue.Empty:
                continue
            if line is None:
                return False
            if fragment in line:
                return True

    def alive(self):
        """Return True while the process runs."""
        return self.process.poll() is None

    def stop(self, timeout_s=STOP_TIMEOUT_S):
        """
        Stop the process: SIGINT, then SIGTERM, then SIGKILL; return its exit code.

        Parameters
        ----------
        timeout_s : float
            How long to wait after each signal [s].

        """
        for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGKILL):
            if self.process.poll() is not None:
                break
            self.process.send_signal(sig)
            try:
                self.process.wait(timeout=timeout_s)
            except subprocess.TimeoutExpired:
                continue
        code = self.process.wait()
        self._reader.join(timeout=5.0)
        return code

    def output(self, last=40):
        """
        Return the last lines the process printed, each marked with its name.

        Parameters
        ----------
        last : int
            How many lines.

        """
        return '\n'.join(f'  [{self.name}] {line}' for line in self.lines[-last:])


def _float(value):
    # ROS parameter overrides: a float must look like one (391 would be an integer).
    return f'{float(value):.6f}'


def run_demo(seconds=6.0, rpm=391.0, out='demo_out', rate_hz=1000.0, extra_node_args=(),
             log=print):
    """
    Run driver and node, record, and summarise the recording.

    Parameters
    ----------
    seconds : float
        How long to stream after the first sample reached the node [s].
    rpm : float
        Crank speed [rpm].
    out : str or os.PathLike
        Directory receiving the bag directory.
    rate_hz : float
        Driver rate [Hz].
    extra_node_args : sequence of str
        More ``-p name:=value`` overrides for the node.
    log : callable
        Progress messages.

    Returns
    -------
    dict
        :func:`.demo_summary.summarise_recording` plus the run's settings.

    """
    if not seconds > 0 or not rate_hz > 0:
        raise ValueError('`--seconds` and `--rate-hz` must be positive')
    domain = isolate_ros_environment()
    env = dict(os.environ, PYTHONUNBUFFERED='1', RCUTILS_LOGGING_BUFFERED_STREAM='0',
               RCUTILS_COLORIZED_OUTPUT='0')
    bag = _new_bag_path(pathlib.Path(out))
    node_argv = [sys.executable, '-m', 'flexlink_ros.ros.node', '--ros-args',
                 '--params-file', str(find_config('flexlink_node')),
                 '-p', 'record.enabled:=true', '-p', f'record.path:={bag.resolve()}',
                 *extra_node_args]
    driver_argv = [sys.executable, '-m', 'flexlink_ros.ros.crank_driver', '--ros-args',
                   '--params-file', str(find_config('crank_driver')),
                   '-p', 'profile:=constant', '-p', f'speed_rpm:={_float(rpm)}',
                   '-p', f'rate_hz:={_float(rate_hz)}']
    log(f'flexlink demo: ROS_DOMAIN_ID={domain}, discovery on localhost only; '
        f'recording to {bag}')
    processes = {}
    try:
        _stream(processes, node_argv, driver_argv, env, seconds, log,
                f'{rpm:g} rpm, {rate_hz:g} Hz')
    finally:
        codes = {}
        for name in ('crank_driver', 'flexlink_node'):
            if name in processes:
                codes[name] = processes[name].stop()
    node = processes['flexlink_node']
    log('stopped; reading the recording back ...')
    if not (bag / 'metadata.yaml').exists():
        raise RuntimeError(f'the node did not close the recording {bag} (exit codes {codes}):\n'
                           + node.output())
    result = summarise_recording(bag)
    result.update({'seconds': seconds, 'rpm': rpm, 'rate_hz': rate_hz, 'domain_id': domain,
                   'exit_codes': codes,
                   'node_warnings': [line for line in node.lines if '[WARN]' in line],
                   'driver': _driver_summary(processes['crank_driver'].lines),
                   'model': _model_choice(node.lines)})
    return result


def _driver_summary(lines):
    """Return the driver's exit counts {'published', 'heard', 'periods_skipped'}, or None."""
    for line in reversed(lines):
        found = DRIVER_SUMMARY.search(line)
        if found:
            return dict(zip(('published', 'heard', 'periods_skipped'), map(int, found.groups())))
    return None


def _model_choice(lines):
    """Return the node's 'model: linear|nonlinear (why)' line, or None."""
    for line in lines:
        said = line.split(']: ', 1)[-1]
        if said.startswith(('model: linear', 'model: nonlinear')):
            return said
    return None


def _new_bag_path(out):
    """Return a bag directory path in ``out`` (created) that does not exist yet."""
    out.mkdir(parents=True, exist_ok=True)
    bag = out / time.strftime('flexlink_demo_%Y%m%d_%H%M%S')
    suffix = 1
    while bag.exists():
        bag = out / f'{bag.name.split("-")[0]}-{suffix}'
        suffix += 1
    return bag


def _stream(processes, node_argv, driver_argv, env, seconds, log, driver_settings):
    """
    Start the node, then the driver once it is ready, and let them run for ``seconds``.

    ``processes`` receives each :class:`ManagedProcess` by name as it starts (the caller
    stops them, also when this raises ``RuntimeError``).
    """
    node = processes['flexlink_node'] = ManagedProcess('flexlink_node', node_argv, env)
    log('starting flexlink_node (loads or builds the precomputed model) ...')
    if not node.wait_for_line(READY_MESSAGE, READY_TIMEOUT_S):
        raise RuntimeError('flexlink_node did not become ready:\n' + node.output())
    log(f'starting crank_driver at {driver_settings} ...')
    driver = processes['crank_driver'] = ManagedProcess('crank_driver', driver_argv, env)
    if not node.wait_for_line(FIRST_INPUT_MESSAGE, FIRST_SAMPLE_TIMEOUT_S):
        raise RuntimeError('no crank sample reached flexlink_node:\n' + node.output()
                           + '\n' + driver.output())
    log(f'streaming for {seconds:g} s ...')
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        if not (node.alive() and driver.alive()):
            raise RuntimeError('a process ended early:\n' + node.output() + '\n'
                               + driver.output())
        time.sleep(0.1)


def summary_text(result):
    """
    Return the printed summary of :func:`run_demo`.

    Parameters
    ----------
    result : dict
        What :func:`run_demo` returned.

    """
    lines = [f"flexlink demo: crank_driver ({result['rpm']:g} rpm, {result['rate_hz']:g} Hz) "
             f"-> flexlink_node for {result['seconds']:g} s "
             f"(ROS_DOMAIN_ID={result['domain_id']}, localhost only)"]
    for warning in result['node_warnings']:
        lines.append('  node warning: ' + warning.split(']: ', 1)[-1])
    driver = result.get('driver')
    if driver:
        skipped = (f" (its timer skipped {driver['periods_skipped']} periods, running late on "
                   f"this machine: the gaps in the input's stamps)"
                   if driver['periods_skipped'] else '')
        lines.append(f"  crank_driver sent {driver['heard']} messages while the node listened"
                     f"{skipped}; the node received {result['samples']}")
    lines.append(f"recording: {result['path']} (rosbag2 bag: metadata.yaml + "
                 f"{len(result['files'])} MCAP file(s), {result['bytes'] / 1e6:.2f} MB, "
                 f"{'complete' if result['complete'] else 'INCOMPLETE'})")
    for topic, count in sorted(result['topics'].items()):
        lines.append(f'  {topic:<42} {count:>7} messages')
    lost = result['samples'] - result['outputs']
    lines.append(f"input: {result['samples']} samples over {result['input_span_s']:.2f} s = "
                 f"{result['input_rate_hz']:.1f} Hz; {result['outputs']} estimates "
                 + ('(one per sample)' if lost == 0 else f'({lost} samples without output)'))
    lines.append('peak-to-peak elastic deflection [um]       dx          dy')
    for key, label in (('lever_tip', 'lever tip'), ('coupler_mid', 'coupler mid-point')):
        value = result['peak_to_peak_um'][key]
        lines.append(f'  {label:<36} {value[0]:>10.1f}  {value[1]:>10.1f}' if value
                     else f'  {label:<36} no data')
    if result.get('model'):
        lines.append(result['model'])
    lines.extend(_quality_lines(result['quality'],
                                (result.get('model') or '').startswith('model: nonlinear')))
    if result['criteria_max']:
        lines.append('Earles-Wu criterion |dgamma/dt|/R    max [rad/(s N)]   R there [N]  '
                     'median R [N]')
        for joint, value in result['criteria_max'].items():
            at_max = result['reaction_at_max_n'][joint]
            median = result['reaction_median_n'][joint]
            lines.append(f'  joint {joint:<30} {value:>12.4g}  {at_max:>12.4g}  {median:>12.4g}')
    else:
        reason = result['criteria_reason'].removeprefix('unavailable').strip(' ()')
        lines.append(f'criteria unavailable: {reason}')
    if result['latency_us']:
        lines.append('node receive -> publish (recorded log times): median '
                     f"{result['latency_us']['median']:.0f} us, p99 "
                     f"{result['latency_us']['p99']:.0f} us")
    if result['update_us']:
        lines.append(f"estimator update per sample: median {result['update_us']['median']:.0f}"
                     f" us, p99 {result['update_us']['p99']:.0f} us (node diagnostics)")
    first = result['files'][0] if result['files'] else result['path']
    lines += [f'open it: Foxglove ({FOXGLOVE_URL}, Open local file) -> {first}',
              f"         ros2 bag info {result['path']}   (with a ROS 2 distro)",
              f"         flexlink mcap-info {result['path']}",
              f"         flexlink replay {result['path']} --out replay.mcap"]
    return '\n'.join(lines)


def _demo_command(args):
    log = (lambda text: None) if args.json else (lambda text: print(text, flush=True))
    try:
        result = run_demo(args.seconds, args.rpm, args.out, args.rate_hz, log=log)
    except RuntimeError as exc:
        print(f'flexlink demo: failed: {exc}', file=sys.stderr)
        return 1
    emit(result, summary_text(result), args.json)
    return 0 if result['outputs'] > 0 else 1


def register(subparsers):
    """Add the demo subcommand."""
    parser = subparsers.add_parser('demo', help='crank driver + node + MCAP recording for a few '
                                   'seconds, then a summary of the recording')
    parser.add_argument('--seconds', type=float, default=6.0,
                        help='streaming time after the first sample [s] (default 6)')
    parser.add_argument('--rpm', type=float, default=391.0,
                        help='crank speed [rpm] (default 391, Cho 1992)')
    parser.add_argument('--rate-hz', type=float, default=1000.0,
                        help='crank driver rate [Hz] (default 1000)')
    parser.add_argument('--out', default='demo_out',
                        help='directory for the recording (default demo_out/)')
    parser.add_argument('--json', action='store_true', help='print one JSON object')
    parser.set_defaults(func=_demo_command)


def _quality_lines(quality, nonlinear=False):
    """
    Say the largest error indicator and whether the estimates can be trusted (~/quality).

    ``nonlinear``: the nonlinear model made the deflections (the indicator is its own).
    """
    if quality is None:
        return ['quality: no ~/quality messages recorded']
    verdict = quality['nonlinearity']
    why_not = ("NOT valid: the links bend beyond the slope the nonlinear model's strain "
               'carries (docs/nonlinear.md)' if nonlinear else
               'NOT valid: at this speed a crank '
               "harmonic drives a link near its resonance, where the vibration's own "
               'axial force detunes the link and no linear estimate can follow it, so '
               'read these deflections as a warning, not a measurement, or run the '
               'nonlinear model (docs/validity.md)')
    if verdict['valid'] is None:
        validity = 'validity indicator not available for this model'
    else:
        validity = (f"{'nonlinear model ' if nonlinear else ''}validity indicator max "
                    f"{verdict['indicator_max']:.3g} (threshold {verdict['threshold']:g}): "
                    + ('valid' if verdict['valid'] else why_not))
    return [f"quality: error indicator max {quality['error_indicator_max']:.3g}; {validity}"]
