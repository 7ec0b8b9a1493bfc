"""benchmarks/node_bench.py end to end: echo, node and node + recording as real processes."""

import json
import pathlib
import subprocess
import sys

REPO = pathlib.Path(__file__).resolve().parents[1]
BENCH = REPO / 'benchmarks' / 'node_bench.py'


def test_node_bench_measures_every_target(tmp_path):
    # Not a timed test: one slow rate, checked for what the figures are made of.
    result = subprocess.run([sys.executable, str(BENCH), '--rate-hz', '200',
                             '--max-rate-hz', '200', '--seconds', '1',
                             '--out', str(tmp_path / 'bench'), '--json'],
                            capture_output=True, text=True, timeout=400, cwd=tmp_path)
    assert result.returncode == 0, result.stderr[-3000:]
    summary = json.loads(result.stdout)
    assert summary['run'] == 1
    names = [target['name'] for target in summary['targets']]
    assert names == ['echo (EventsExecutor)', 'echo (rclpy.spin)', 'flexlink_node',
                     'flexlink_node + recording']
    for target in summary['targets']:
        (row,) = target['rows']
        assert row['sent'] >= 150, target          # 1 s at 200 Hz
        assert row['received'] >= 0.9 * row['sent'], target
        assert 0 < row['latency_us_p50'] <= row['latency_us_p99'], target
        assert 0 <= row['cpu_us_per_message'] < 1e6 / 200, target   # the target's own CPU
        assert target['rss_mb'] > 0
    recording = summary['recording']
    assert recording['complete'] and recording['messages'] > 0


def test_node_bench_alternates_this_node_and_a_reference_tree(tmp_path):
    # The reference is this tree again: the run names both nodes, in alternating order.
    result = subprocess.run([sys.executable, str(BENCH), '--rate-hz', '200',
                             '--max-rate-hz', '200', '--seconds', '0.5', '--runs', '2',
                             '--no-recording', '--reference-root', str(REPO),
                             '--out', str(tmp_path / 'bench'), '--json'],
                            capture_output=True, text=True, timeout=600, cwd=tmp_path)
    assert result.returncode == 0, result.stderr[-3000:]
    runs = [json.loads(line) for line in result.stdout.splitlines()]
    assert [run['run'] for run in runs] == [1, 2]
    assert [[t['name'] for t in run['targets']] for run in runs] == [
        ['echo (EventsExecutor)', 'echo (rclpy.spin)', 'flexlink_node',
         'flexlink_node (reference)'],
        ['echo (EventsExecutor)', 'echo (rclpy.spin)', 'flexlink_node (reference)',
         'flexlink_node']]
    assert all(run['recording'] is None for run in runs)
    for run in runs:
        for target in run['targets']:
            (row,) = target['rows']
            assert row['received'] >= 0.9 * row['sent'] >= 0.9 * 90, target
