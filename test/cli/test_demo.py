"""`flexlink demo`: driver and node as real processes, the recording read back and summarised."""

import json
import os
import pathlib
import re
import subprocess
import sys

from flexlink_ros.cli import demo as cli_demo
from flexlink_ros.ros import runtime
import numpy as np
import pytest


def test_isolate_ros_environment_sets_loopback_and_a_valid_domain():
    env = {'ROS_LOCALHOST_ONLY': '1'}
    domain = runtime.isolate_ros_environment(env)
    assert env['ROS_AUTOMATIC_DISCOVERY_RANGE'] == 'LOCALHOST'
    assert 'ROS_LOCALHOST_ONLY' not in env
    assert 0 <= domain <= 101 and env['ROS_DOMAIN_ID'] == str(domain)


def test_demo_runs_records_and_summarises(tmp_path):
    # The whole command as `make demo` runs it, short, with --json for the checks.
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path))
    result = subprocess.run([sys.executable, '-m', 'flexlink_ros.cli.main', 'demo',
                             '--seconds', '3', '--out', str(tmp_path / 'out'), '--json'],
                            capture_output=True, text=True, timeout=400, env=env, cwd=tmp_path)
    assert result.returncode == 0, result.stderr[-3000:]
    summary = json.loads(result.stdout)
    bag = tmp_path / 'out' / os.path.basename(summary['path'])
    assert (bag / 'metadata.yaml').exists() and summary['complete']
    assert summary['exit_codes'] == {'crank_driver': 0, 'flexlink_node': 0}
    topics = summary['topics']
    inputs = topics['/joint_states']
    # About 3 s at 1 kHz after the first sample (a loaded machine may miss driver ticks).
    assert inputs > 1500 and summary['input_rate_hz'] > 500
    for name in ('/flexlink_node/lever_tip/deflection', '/flexlink_node/coupler_mid/deflection',
                 '/flexlink_node/joint_criteria', '/flexlink_node/quality'):
        assert topics[name] == inputs     # one estimate per sample, none lost in the node
    assert summary['samples'] == summary['outputs'] == inputs
    # The driver says what it sent while the node listened, and the node took about as many:
    # the match may land between the driver's count and its publish (a message or two), and
    # a node behind its input at the stop leaves what waits in its queue untaken.
    driver = summary['driver']
    assert driver['published'] >= driver['heard'] and driver['periods_skipped'] >= 0
    assert -2 <= driver['heard'] - inputs <= max(2, inputs // 50), (driver, inputs)
    assert f"crank_driver sent {driver['heard']} messages while the node listened" in \
        cli_demo.summary_text(summary)
    assert inputs // 10 <= topics['/flexlink_node/markers'] <= inputs // 10 + 1
    assert topics['/diagnostics'] >= 2
    lever, coupler = summary['peak_to_peak_um']['lever_tip'], \
        summary['peak_to_peak_um']['coupler_mid']
    # The Cho 1992 linkage at 391 rpm deflects by millimetres, not micrometres or metres.
    assert all(100.0 < value < 1e5 for value in lever + coupler)
    if summary['criteria_max'] is None:
        assert summary['criteria_reason']
    else:
        assert all(np.isfinite(list(summary['criteria_max'].values())))
        assert all(value > 0 for value in summary['reaction_median_n'].values())
        assert 'Earles-Wu criterion' in cli_demo.summary_text(summary)
    assert summary['latency_us']['median'] > 0 and summary['update_us']['median'] > 0
    # The default model at 391 rpm is near its coupler and lever resonances, where the linear
    # model is not valid: model.nonlinear auto found it so over the model's speed range and
    # runs the nonlinear model, whose own validity indicator holds there.
    assert summary['model'].startswith('model: nonlinear (auto: the linear model is not '
                                       'valid at ')
    ranges = summary['model'].split(' of its speed range ', 1)[0]
    assert any(int(low) <= 391 < int(high) for low, high in re.findall(r'(\d+)-(\d+)', ranges))
    verdict = summary['quality']['nonlinearity']
    assert verdict['valid'] is True and 0.0 < verdict['indicator_max'] < verdict['threshold']
    assert 0.0 <= summary['quality']['error_indicator_max'] < 0.5
    text = cli_demo.summary_text(summary)
    assert 'nonlinear model validity indicator max' in text and 'NOT valid' not in text
    assert summary['model'] in text
    for fragment in ('peak-to-peak', 'lever tip', 'coupler mid-point', 'Foxglove',
                     'estimator update per sample', summary['path']):
        assert fragment in text


@pytest.mark.parametrize('bad', [['--seconds', '0'], ['--rate-hz', '-5']])
def test_demo_rejects_bad_arguments(tmp_path, bad):
    result = subprocess.run([sys.executable, '-m', 'flexlink_ros.cli.main', 'demo', *bad,
                             '--out', str(tmp_path)], capture_output=True, text=True,
                            timeout=60)
    assert result.returncode == 1 and 'must be positive' in result.stderr


def test_python_m_flexlink_ros_cli_runs_the_same_command_line(tmp_path):
    result = subprocess.run([sys.executable, '-m', 'flexlink_ros.cli', 'demo', '--seconds', '0',
                             '--out', str(tmp_path)], capture_output=True, text=True,
                            timeout=60)
    assert result.returncode == 1 and 'must be positive' in result.stderr


def test_the_not_valid_line_says_why_in_one_sentence_and_where_to_read_more():
    quality = {'error_indicator_max': 0.004,
               'nonlinearity': {'valid': False, 'indicator_max': 3.9, 'threshold': 0.5}}
    (line,) = cli_demo._quality_lines(quality)
    assert 'NOT valid' in line and 'resonance' in line
    verdict = line.split('NOT valid', 1)[1]
    assert verdict.count('. ') == 0 and verdict.rstrip().endswith(')')    # one sentence
    (doc,) = [word.strip('()') for word in verdict.split() if word.startswith('(docs/')]
    assert (pathlib.Path(__file__).resolve().parents[2] / doc).is_file()
    assert 'Where the estimate holds' in (pathlib.Path(__file__).resolve().parents[2]
                                          / doc).read_text()
    (line,) = cli_demo._quality_lines(quality, nonlinear=True)
    assert 'nonlinear model validity indicator max 3.9' in line
    assert "beyond the slope the nonlinear model's strain carries (docs/nonlinear.md)" in line
