"""`flexlink node-bench` end to end: echo, node and node + recording as real processes (short)."""

import json
import os
import subprocess
import sys


def test_node_bench_measures_every_target(tmp_path):
    # Not a timed test: one slow rate, checked for what the figures are made of.
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path))
    result = subprocess.run([sys.executable, '-m', 'flexlink_ros.cli.main', 'node-bench',
                             '--rate-hz', '200', '--max-rate-hz', '200', '--seconds', '1',
                             '--out', str(tmp_path / 'bench'), '--json'],
                            capture_output=True, text=True, timeout=400, env=env, cwd=tmp_path)
    assert result.returncode == 0, result.stderr[-3000:]
    summary = json.loads(result.stdout)
    names = [target['name'] for target in summary['targets']]
    assert names == ['echo (bare rclpy)', 'flexlink_node', 'flexlink_node + recording']
    for target in summary['targets']:
        (row,) = target['rows']
        assert row['sent'] >= 150, target          # 1 s at 200 Hz
        assert row['received'] >= 0.9 * row['sent'], target
        assert 0 < row['latency_us_p50'] <= row['latency_us_p99'], target
        assert target['rss_mb'] > 0
    recording = summary['recording']
    assert recording['complete'] and recording['messages'] > 0
