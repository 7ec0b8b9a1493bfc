"""
`flexlink fleet` against `flexlink replay` one bag after another, in alternating whole processes.

    .venv/bin/python benchmarks/fleet_bench.py [--bags 16] [--seconds 60] [--pairs 3]

Writes BAGS bags of SECONDS at 1 kHz (a crank at 300-420 rpm, one per bag; kept in
--bags-dir for the next run), then runs PAIRS rounds, each in alternating order: the bags
replayed one after another (`flexlink replay BAG --out X`, one process per bag, as a user
would loop over them) and `flexlink fleet BAGS --out DIR` (the table only) and with
`--write-mcap` (the table and every bag's MCAP, as replay writes them). Prints each run and
the medians and ratios, and the Ray start-up that fleet reports. `--split` also measures how
long a split file estimated on its own (a warm start at its first sample) differs from the
same samples estimated as part of the whole bag; `--read-mcap` times Ray Data's read_mcap on
one bag against the project's reader.
"""

import argparse
import math
import os
import pathlib
import re
import shutil
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np

# This tree's package (not an installed copy), here and in the processes it starts.
ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
RATE_HZ = 1000.0
T0 = 1_700_000_000_000_000_000


def write_bags(directory, count, seconds):
    """Write the bags (skipping those already there); return their paths."""
    from flexlink_ros.io.recorder import McapRecorder
    from rclpy.serialization import serialize_message
    from sensor_msgs.msg import JointState
    paths = []
    for k in range(count):
        path = directory / f'machine{k:02d}'
        paths.append(str(path))
        if path.exists():
            continue
        rpm = 300.0 + 120.0 * k / max(count - 1, 1)
        speed = rpm * 2.0 * math.pi / 60.0
        times = np.arange(int(seconds * RATE_HZ)) / RATE_HZ
        angles = np.mod(speed * times + math.pi, 2.0 * math.pi) - math.pi
        message = JointState(name=['crank'], position=[0.0], velocity=[speed])
        with McapRecorder(path) as recorder:
            recorder.add_topic('/joint_states', JointState)
            for t, angle in zip(times.tolist(), angles.tolist()):
                stamp = T0 + int(round(t * 1e9))
                message.header.stamp.sec, message.header.stamp.nanosec = divmod(stamp, 10**9)
                message.position = [angle]
                recorder.write('/joint_states', serialize_message(message), stamp + 200_000)
    return paths


def timed(command):
    """Run a command; return its wall time [s] and its stderr."""
    start = time.perf_counter()
    result = subprocess.run(command, capture_output=True, text=True, cwd=ROOT)
    seconds = time.perf_counter() - start
    if result.returncode != 0:
        raise SystemExit(f'{" ".join(command)} failed:\n{result.stderr}')
    return seconds, result.stdout + result.stderr


def replay_one_after_another(flexlink, bags, scratch):
    """Replay every bag in its own process, one after another; total wall time [s]."""
    total = 0.0
    for bag in bags:
        out = scratch / (pathlib.Path(bag).name + '.mcap')
        seconds, _ = timed([*flexlink, 'replay', bag, '--out', str(out), '--mechanism', 'cho1992'])
        total += seconds
        out.unlink()
    return total


def fleet(flexlink, bags, scratch, write_mcap):
    """One fleet run; (wall time [s], Ray start [s] as fleet reports it)."""
    out = scratch / 'fleet'
    seconds, text = timed([*flexlink, 'fleet', *bags, '--out', str(out), '--mechanism',
                           'cho1992'] + (['--write-mcap'] if write_mcap else []))
    shutil.rmtree(out)
    found = re.search(r'Ray start ([0-9.]+) s', text)
    return seconds, float(found.group(1)) if found else math.nan


def split_warm_up(seconds):
    """How a split file estimated alone differs from the same samples of the whole bag."""
    from flexlink_ros.core.estimation.offline import estimate_offline
    from flexlink_ros.core.mechanism_file import load_mechanism
    from flexlink_ros.core.reduction import mechanism_model
    from flexlink_ros.ros import parameters as node_params
    model = mechanism_model.model_for_mechanism(load_mechanism('cho1992'),
                                                node_params.default_model_options())
    for rpm in (300.0, 391.0):
        speed = rpm * 2.0 * math.pi / 60.0
        times = np.arange(int(seconds * RATE_HZ)) / RATE_HZ
        stamps = T0 + np.round(times * 1e9).astype(np.int64)
        angles = np.mod(speed * times + math.pi, 2.0 * math.pi) - math.pi
        speeds = np.full(times.size, speed)
        whole = estimate_offline(model, stamps, angles, speeds)
        half = times.size // 2
        alone = estimate_offline(model, stamps[half:], angles[half:], speeds[half:])
        for key in ('lever_tip', 'coupler_mid'):
            reference = whole[key][half:]
            scale = np.max(np.abs(reference))
            error = np.max(np.abs(alone[key] - reference), axis=1) / scale
            print(f'split at {times[half]:.0f} s, {rpm:.0f} rpm, {key}: largest difference '
                  f'{error.max():.2e} of the peak at the first sample; below 1e-3 after '
                  f'{_settled(error, 1e-3) / RATE_HZ:.3f} s, below 1e-6 after '
                  f'{_settled(error, 1e-6) / RATE_HZ:.3f} s')


def _settled(error, level):
    """Count the samples until the error stays below ``level``."""
    above = np.flatnonzero(error >= level)
    return int(above[-1]) + 1 if above.size else 0


def read_mcap_figures(bag):
    """Ray Data's read_mcap of one bag to rows, against the project's reader."""
    os.environ['RAY_USAGE_STATS_ENABLED'] = '0'
    os.environ.setdefault('RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER', '0')
    import ray
    from flexlink_ros.io.joint_states import read_crank_samples
    start = time.perf_counter()
    samples = read_crank_samples(bag, '/joint_states', 'crank')
    project_s = time.perf_counter() - start
    ray.init(num_cpus=2, include_dashboard=False, logging_level='ERROR', log_to_driver=False)
    try:
        start = time.perf_counter()
        rows = ray.data.read_mcap(bag, topics={'/joint_states'}).take_all()
        ray_s = time.perf_counter() - start
        truncated = pathlib.Path(tempfile.mkdtemp()) / 'truncated.mcap'
        data = pathlib.Path(sorted(pathlib.Path(bag).glob('*.mcap'))[0]).read_bytes()
        truncated.write_bytes(data[:len(data) * 2 // 3])
        try:
            kept = len(ray.data.read_mcap(str(truncated)).take_all())
            truncated_text = f'{kept} messages'
        except Exception as exc:  # noqa: B902 - reported as it is
            truncated_text = f'failed: {type(exc).__name__}: {str(exc).splitlines()[0][:120]}'
        salvaged = len(read_crank_samples(truncated, '/joint_states', 'crank')['data'])
    finally:
        ray.shutdown()
    print(f'read_mcap: {len(rows)} rows in {ray_s:.2f} s (one dict per message); the project '
          f"reader: {len(samples['data'])} samples in {project_s:.2f} s")
    print(f'a file cut at 2/3: read_mcap {truncated_text}; the project reader '
          f'{salvaged} samples')


def main():
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--bags', type=int, default=16)
    parser.add_argument('--seconds', type=float, default=60.0)
    parser.add_argument('--pairs', type=int, default=3)
    parser.add_argument('--bags-dir', default='/tmp/flexlink_fleet_bench_bags')
    parser.add_argument('--split', action='store_true')
    parser.add_argument('--read-mcap', action='store_true')
    args = parser.parse_args()
    directory = pathlib.Path(args.bags_dir)
    directory.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    bags = write_bags(directory, args.bags, args.seconds)
    print(f'{len(bags)} bags of {args.seconds:g} s at {RATE_HZ:g} Hz in {directory} '
          f'({time.perf_counter() - start:.1f} s to write)')
    if args.split:
        split_warm_up(args.seconds)
    if args.read_mcap:
        read_mcap_figures(bags[0])
    flexlink = [sys.executable, '-m', 'flexlink_ros.cli.main']
    runs = {'replay': [], 'fleet': [], 'fleet --write-mcap': [], 'ray start': []}
    with tempfile.TemporaryDirectory() as scratch:
        scratch = pathlib.Path(scratch)
        for pair in range(args.pairs):
            order = ['replay', 'fleet', 'fleet --write-mcap']
            for name in (order if pair % 2 == 0 else order[::-1]):
                if name == 'replay':
                    seconds = replay_one_after_another(flexlink, bags, scratch)
                else:
                    seconds, ray_s = fleet(flexlink, bags, scratch, 'write' in name)
                    runs['ray start'].append(ray_s)
                runs[name].append(seconds)
                print(f'pair {pair + 1}: {name:20s} {seconds:7.2f} s', flush=True)
    if not args.pairs:
        return
    medians = {name: statistics.median(values) for name, values in runs.items()}
    print(f"medians: replay one after another {medians['replay']:.2f} s, fleet "
          f"{medians['fleet']:.2f} s, fleet --write-mcap {medians['fleet --write-mcap']:.2f} s "
          f"(Ray start {medians['ray start']:.2f} s of each)")
    for name in ('fleet', 'fleet --write-mcap'):
        ratios = [f / r for f, r in zip(runs[name], runs['replay'])]
        print(f'{name}: {medians[name] / medians["replay"]:.3f}x the replays (pairs: '
              + ', '.join(f'{r:.3f}' for r in ratios) + ')')


if __name__ == '__main__':
    main()
