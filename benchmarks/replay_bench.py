"""
`flexlink replay` as a whole process: this build against another one, in alternating runs.

    python benchmarks/replay_bench.py make-bag BAG [--seconds 60] [--rate 1000]
    python benchmarks/replay_bench.py compare BAG [--pairs 7]
        [--reference-python OTHER/.venv/bin/python --reference-root OTHER] [--same-output]
        [--nonlinear] [--flags 'F...'] [--reference-flags 'F...']

``make-bag`` writes a rosbag2 MCAP of one crank ``sensor_msgs/JointState`` topic: the
synthetic signal the estimator benches use (:func:`flexlink_ros.studies.synthetic
.synthetic_signal`: 391 rpm, sampling jittered by +-30 %), the angle wrapped to [-pi, pi) as
an encoder gives it, logged 150 us after its stamp, written in batches (bounded memory).

``compare`` replays the bag with this build and, given ``--reference-python``, with another
(a worktree of an older commit with its own venv, run from its root), in turn: A B A B ...,
each a fresh process ``PY -m flexlink_ros.cli replay BAG --out TMP`` with the default model
and flags (its cache, and each build's compiled modules in a directory of the benchmark's own,
filled by a first, untimed run of each build: an installed package has its modules compiled).
It prints every run's wall time, CPU
time (``os.wait4``) and peak resident size (the child's own ``VmHWM``, read as it exits: the
``ru_maxrss`` of ``wait4`` also counts the parent's pages the child held between fork and
exec), the medians and the ratio of the medians. Timing is
printed, never asserted: the machine is shared. ``--same-output`` also compares what the two
builds wrote: every message's topic, log and publish time, sequence number and length, how many
messages' bytes differ and, where they do, each topic's largest difference over the range of
the value (a replay in two processes writes its second part's values to rounding). The replay is
the linear model's (``--nonlinear off``), or with ``--nonlinear`` the reduced nonlinear
model's (``--nonlinear on``, and ``--threads 2`` for a build that has it; its deflections
agree between builds to rounding, not to the byte, where one steps runs of samples at once).
``--flags`` / ``--reference-flags`` add replay flags to one build's runs (``--flags
'--processes 1'`` against this build's default times the second process).
"""

import argparse
import math
import os
import pathlib
import shutil
import statistics
import struct
import subprocess
import sys
import tempfile
import time

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))       # the tree's package, not an installed copy
from flexlink_ros.io.cdr import serialize_message  # noqa: E402, I201
from flexlink_ros.io.recorder import McapRecorder  # noqa: E402, I201
from flexlink_ros.studies.synthetic import synthetic_signal  # noqa: E402, I201
from mcap.reader import make_reader  # noqa: E402, I201
import numpy as np  # noqa: E402, I201
from sensor_msgs.msg import JointState  # noqa: E402, I201
from std_msgs.msg import Header  # noqa: E402, I201

TOPIC = '/joint_states'
START_NS = 1_700_000_000_000_000_000
LOG_DELAY_NS = 150_000
BATCH = 100_000           # messages encoded and written at a time by make-bag
_SENTINELS = (1.0e300 + 3e285, 1.0e300 + 7e285)


def crank_messages(stamps_ns, angles, speeds):
    """CDR of crank JointStates (frame 'crank_link', joint 'crank'), one row each."""
    template = serialize_message(JointState(header=Header(frame_id='crank_link'), name=['crank'],
                                            position=[_SENTINELS[0]], velocity=[_SENTINELS[1]]))
    rows = np.tile(np.frombuffer(template, dtype=np.uint8), (len(stamps_ns), 1))
    sec, nanosec = np.divmod(np.asarray(stamps_ns, dtype=np.int64), 1_000_000_000)
    rows[:, 4:8] = sec.astype('<i4').view(np.uint8).reshape(-1, 4)
    rows[:, 8:12] = nanosec.astype('<u4').view(np.uint8).reshape(-1, 4)
    for sentinel, values in zip(_SENTINELS, (angles, speeds)):
        offset = template.index(struct.pack('<d', sentinel))
        rows[:, offset:offset + 8] = np.asarray(values, dtype='<f8').view(np.uint8).reshape(-1, 8)
    return [row.tobytes() for row in rows]


def make_bag(path, seconds, rate_hz, rpm=391.0):
    """Write the synthetic crank recording; return its message count."""
    stamps, angles, speeds = synthetic_signal(rpm, seconds, rate_hz, jitter=0.3, seed=1)
    stamps = stamps + START_NS
    angles = np.mod(angles + math.pi, 2.0 * math.pi) - math.pi
    with McapRecorder(path) as recorder:
        recorder.add_topic(TOPIC, JointState)
        for first in range(0, stamps.size, BATCH):
            part = slice(first, first + BATCH)
            recorder.write_batch(TOPIC, crank_messages(stamps[part], angles[part], speeds[part]),
                                 stamps[part] + LOG_DELAY_NS)
    return stamps.size


# Runs `python -m flexlink_ros.cli ARGS` and, as the process exits, prints its own peak
# resident size (VmHWM: the pages of this process image alone) on stderr.
_PEAK_MARK = 'flexlink-peak-rss-kb'
_PEAK_WRAPPER = (
    'import atexit, runpy, sys\n'
    'def _peak():\n'
    "    with open('/proc/self/status') as status:\n"
    "        kb = [line.split()[1] for line in status if line.startswith('VmHWM:')]\n"
    f"    sys.stderr.write('\\n{_PEAK_MARK} ' + kb[0] + '\\n')\n"
    'atexit.register(_peak)\n'
    "runpy.run_module('flexlink_ros.cli', run_name='__main__', alter_sys=True)\n")


def run_measured(python, root, args, bytecode=None):
    """
    Run ``python -m flexlink_ros.cli ARGS`` from ``root`` to its end.

    Returns wall time [s], CPU time [s] (``os.wait4``: the process's and the children it
    waited for, a forked part of the replay included) and the process's own peak resident
    size [MB]: the ``ru_maxrss`` of ``wait4`` would also count the parent's pages the child
    held between fork and exec (a large parent makes every child look as large).
    ``bytecode``: a directory where Python keeps the compiled modules
    (``PYTHONPYCACHEPREFIX``), as an installed package has them, even where the environment
    says not to write them (``PYTHONDONTWRITEBYTECODE``): the source trees stay untouched.
    """
    argv = [python, '-c', _PEAK_WRAPPER, *args]
    environment = dict(os.environ)
    if bytecode is not None:
        environment.pop('PYTHONDONTWRITEBYTECODE', None)
        environment['PYTHONPYCACHEPREFIX'] = str(bytecode)
    start = time.perf_counter()
    process = subprocess.Popen(argv, cwd=root, stdout=subprocess.DEVNULL,
                               stderr=subprocess.PIPE, env=environment)
    _, status, usage = os.wait4(process.pid, 0)
    seconds = time.perf_counter() - start
    error = process.stderr.read().decode(errors='replace')
    process.stderr.close()
    if os.waitstatus_to_exitcode(status) != 0:
        raise RuntimeError(f'flexlink {" ".join(args)} failed:\n{error[-2000:]}')
    peaks = [line.split()[1] for line in error.splitlines() if line.startswith(_PEAK_MARK)]
    return seconds, usage.ru_utime + usage.ru_stime, int(peaks[-1]) / 1024.0


def replay_once(python, root, bag, out, extra=(), bytecode=None):
    """Replay in a fresh process from ``root``: wall time [s], CPU time [s], peak RSS [MB]."""
    threads = (['--threads', '2'] if '--nonlinear' in extra
               and '--threads' in replay_help(python, root) else [])
    return run_measured(python, root, ['replay', str(pathlib.Path(bag).resolve()), '--out',
                                       str(out), '--mechanism', 'cho1992',
                                       *linear_flag(python, root), *extra, *threads],
                        bytecode)


def replay_help(python, root):
    """Return the build's ``replay --help`` text."""
    return subprocess.run([python, '-m', 'flexlink_ros.cli.main', 'replay', '--help'],
                          capture_output=True, text=True, cwd=root, timeout=120).stdout


def linear_flag(python, root):
    """``--nonlinear off`` for a build that has the nonlinear model: the linear replay is timed."""
    shown = subprocess.run([python, '-m', 'flexlink_ros.cli.main', 'replay', '--help'],
                           capture_output=True, text=True, cwd=root, timeout=120)
    return ['--nonlinear', 'off'] if '--nonlinear' in shown.stdout else []


def messages(path):
    """(topic, log time, publish time, sequence, bytes) of every message of an MCAP."""
    path = pathlib.Path(path)
    for file in (sorted(path.glob('*.mcap')) if path.is_dir() else [path]):
        with open(file, 'rb') as stream:
            for _, channel, message in make_reader(stream).iter_messages(log_time_order=False):
                yield (channel.topic, message.log_time, message.publish_time, message.sequence,
                       bytes(message.data))


def same_messages(first, second):
    """Return whether two MCAPs hold the same messages in the same order."""
    missing = object()
    left, right = messages(first), messages(second)
    while True:
        a, b = next(left, missing), next(right, missing)
        if a != b:
            return False
        if a is missing:
            return True


def _doubles(data):
    """Read a message's bytes after the CDR encapsulation as little-endian doubles."""
    size = (len(data) - 4) // 8 * 8
    return np.frombuffer(data[4:4 + size], dtype='<f8')


def compare_outputs(first, second):
    """
    Compare two outputs message by message.

    Returns whether every message's topic, times, sequence and length agree, how many
    messages' bytes differ, and each topic's largest difference over the range of the value
    (the doubles of the message, compared where they differ).
    """
    ranges = {}
    for topic, *_, data in messages(first):
        values = _doubles(data)
        low, high = ranges.get(topic, (values, values))
        if len(low) == len(values):
            ranges[topic] = (np.minimum(low, values), np.maximum(high, values))
    missing = (None,) * 5
    heads, differing, worst = True, 0, {}
    left, right = messages(first), messages(second)
    while True:
        a, b = next(left, missing), next(right, missing)
        if a is missing and b is missing:
            return heads, differing, worst
        if a[:4] != b[:4] or len(a[4] or b'') != len(b[4] or b''):
            heads = False
            continue
        if a[4] != b[4]:
            differing += 1
            x, y = _doubles(a[4]), _doubles(b[4])
            changed = x != y
            span = (ranges[a[0]][1] - ranges[a[0]][0])[changed]
            scaled = np.abs(x - y)[changed] / np.where(span > 0, span, np.inf)
            worst[a[0]] = max(worst.get(a[0], 0.0), float(np.max(scaled, initial=0.0)))


def compare(args):
    """Alternate the builds; print each run, the medians and the ratio."""
    builds = [('this', args.python, args.root, tuple(args.flags.split()))]
    if args.reference_python:
        builds.append(('reference', args.reference_python, args.reference_root,
                       tuple(args.reference_flags.split())))
    work = pathlib.Path(tempfile.mkdtemp(prefix='replay_bench_'))
    # --nonlinear given last wins over the linear_flag before it; --threads where a build has it.
    extra = ('--nonlinear', 'on') if args.nonlinear else ()
    times = {name: [] for name, *_ in builds}
    cpu = {name: [] for name, *_ in builds}
    try:
        for name, python, root, flags in builds:       # fill each build's caches, untimed
            replay_once(python, root, args.bag, work / f'warm_{name}.mcap', extra + flags,
                        work / f'bytecode_{name}')
        if args.same_output and len(builds) == 2:
            heads, differing, worst = compare_outputs(work / 'warm_reference.mcap',
                                                      work / 'warm_this.mcap')
            print(f'same topics, times and sequence numbers: {heads}; messages whose bytes '
                  f'differ: {differing}' + ''.join(f'\n  {topic}: largest difference '
                                                   f'{value:.2g} of its range'
                                                   for topic, value in worst.items()))
        for pair in range(args.pairs):
            for name, python, root, flags in builds:
                out = work / f'{name}_{pair}.mcap'
                seconds, cpu_s, peak_mb = replay_once(python, root, args.bag, out,
                                                      extra + flags, work / f'bytecode_{name}')
                times[name].append(seconds)
                cpu[name].append(cpu_s)
                print(f'pair {pair + 1} {name:9s} {seconds:6.3f} s  CPU {cpu_s:6.3f} s  '
                      f'peak RSS {peak_mb:6.1f} MB', flush=True)
                out.unlink()
    finally:
        shutil.rmtree(work, ignore_errors=True)
    medians = {name: statistics.median(values) for name, values in times.items()}
    for name, values in times.items():
        print(f'{name:9s} median {medians[name]:.3f} s  (min {min(values):.3f}, '
              f'max {max(values):.3f}, {len(values)} runs); CPU median '
              f'{statistics.median(cpu[name]):.3f} s')
    if len(builds) == 2:
        print(f'reference / this: {medians["reference"] / medians["this"]:.2f}x '
              '(medians of alternating runs); CPU: '
              f'{statistics.median(cpu["reference"]) / statistics.median(cpu["this"]):.2f}x')
    return medians


def main(argv=None):
    """Parse the command line and run."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    commands = parser.add_subparsers(dest='command', required=True)
    bag = commands.add_parser('make-bag', help='write the synthetic crank recording')
    bag.add_argument('bag', type=pathlib.Path)
    bag.add_argument('--seconds', type=float, default=60.0)
    bag.add_argument('--rate', type=float, default=1000.0, help='sample rate [Hz]')
    runs = commands.add_parser('compare', help='replay it, alternating two builds')
    runs.add_argument('bag', type=pathlib.Path)
    runs.add_argument('--pairs', type=int, default=7)
    runs.add_argument('--python', default=sys.executable)
    runs.add_argument('--root', type=pathlib.Path, default=ROOT)
    runs.add_argument('--reference-python')
    runs.add_argument('--reference-root', type=pathlib.Path)
    runs.add_argument('--nonlinear', action='store_true',
                      help='time the replay with the reduced nonlinear model (--nonlinear on)')
    runs.add_argument('--flags', default='', help="more flags of this build's replay, e.g. "
                      "'--processes 1'")
    runs.add_argument('--reference-flags', default='',
                      help="more flags of the reference build's replay")
    runs.add_argument('--same-output', action='store_true',
                      help='check that both builds write the same messages')
    args = parser.parse_args(argv)
    if args.command == 'make-bag':
        print(f'{args.bag}: {make_bag(args.bag, args.seconds, args.rate)} messages')
        return 0
    if args.reference_python and args.reference_root is None:
        parser.error('--reference-root is needed with --reference-python')
    compare(args)
    return 0


if __name__ == '__main__':
    sys.exit(main())
