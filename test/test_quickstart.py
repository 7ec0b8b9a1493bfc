"""
docs/quickstart-own-linkage.md, run as a new user would on a linkage not in config/.

Every command of the page's fenced ``bash`` blocks runs, in page order, in one directory
holding a linkage not in config/ as ``my_linkage.yaml`` (the stiff steel one at 600 rpm, the
soft aluminium one at its 300 rpm, the page's speed replaced): modes, estimate with its
chart, ``flexlink plan --quick --params-out`` writing the node's parameters file, the node
started with that file as it is and the crank driver recording ``run1`` (real processes),
mcap-info naming the mechanism and the plan's model, and replay with no model flag
reproducing the node's deflections per stamp.
"""

import os
import pathlib
import shlex
import shutil
import subprocess

from node_runs import stream_node_with_driver
import numpy as np
import pytest
from test_readme import fenced_commands, SCRIPTS, VENV_BIN
import yaml

ROOT = pathlib.Path(__file__).resolve().parents[1]
PAGE = ROOT / 'docs' / 'quickstart-own-linkage.md'
DATA = ROOT / 'test' / 'data'
PAGE_RPM = '600'        # the page's speed, replaced by each linkage's own
STREAM_S = 3.0          # of the crank driver


def _argv(command):
    argv = shlex.split(command)
    return [str(VENV_BIN / argv[0]), *argv[1:]] if argv[0] in SCRIPTS else argv


def _run(command, cwd):
    result = subprocess.run(_argv(command), cwd=cwd, capture_output=True, text=True,
                            timeout=600)
    assert result.returncode == 0, (command, result.stdout, result.stderr)
    assert 'Traceback' not in result.stderr, (command, result.stderr)
    return result.stdout


def _run_node_and_driver(commands, cwd):
    """Start the page's driver and node; stop both after STREAM_S of streaming."""
    driver_command, node_command = commands
    env = dict(os.environ, PYTHONUNBUFFERED='1')
    node = _argv(node_command) + ['-p', f'model.cache_dir:={cwd}/cache']
    stream_node_with_driver(node, _argv(driver_command), cwd / 'node.log', env, STREAM_S,
                            cwd=cwd, first_input_timeout_s=30.0)


def _lever_deflections(bag):
    """Return the lever tip's deflection x by input stamp of every output MCAP in ``bag``."""
    from rosbags.highlevel import AnyReader

    found = {}
    with AnyReader([pathlib.Path(bag)]) as reader:
        for connection, _, raw in reader.messages():
            if connection.topic.endswith('lever_tip/deflection'):
                message = reader.deserialize(raw, connection.msgtype)
                stamp = message.header.stamp.sec * 10**9 + message.header.stamp.nanosec
                found[stamp] = message.vector.x
    return found


def _plan_model(params_path):
    """Return the model choices of the plan's parameters file as mcap-info prints them."""
    model = yaml.safe_load(params_path.read_text())['/**']['ros__parameters']['model']
    return f"modes={model['modes']}, static={model['static']}"


@pytest.mark.parametrize('linkage, rpm', [('packaging_steel.yaml', '600'),
                                          ('soft_linkage.yaml', '300')])
def test_every_quickstart_command_runs_on_a_linkage_not_in_config(tmp_path, linkage, rpm):
    commands = [c.replace(PAGE_RPM, rpm) for c in fenced_commands(PAGE.read_text())]
    names = [c.split()[:2] for c in commands]
    assert names == [['flexlink', 'modes'], ['flexlink', 'estimate'], ['flexlink', 'plan'],
                     ['crank_driver', '--ros-args'], ['flexlink_node', '--ros-args'],
                     ['flexlink', 'mcap-info'], ['flexlink', 'replay']], commands
    shutil.copy(DATA / linkage, tmp_path / 'my_linkage.yaml')
    modes = _run(commands[0], tmp_path)
    assert 'Hz' in modes
    _run(commands[1] + ' --cache-dir cache', tmp_path)
    assert (tmp_path / f'my_{rpm}rpm.png').stat().st_size > 10_000
    planned = _run(commands[2] + ' --cache-dir cache', tmp_path)
    assert 'choice:' in planned and 'node parameters: my_node.yaml' in planned, planned
    _run_node_and_driver(commands[3:5], tmp_path)
    info = _run(commands[5], tmp_path)
    assert 'my_linkage.yaml (sha256' in info and _plan_model(tmp_path / 'my_node.yaml') in info, (
        info)
    replayed = _run(commands[6] + ' --out rerun.mcap --cache-dir cache', tmp_path)
    assert (tmp_path / 'run1.png').stat().st_size > 10_000, replayed
    node = _lever_deflections(tmp_path / 'run1')
    again = _lever_deflections(tmp_path / 'rerun.mcap')
    common = sorted(set(node) & set(again))
    assert len(common) >= 0.9 * len(node) > 1000, (len(node), len(again))
    ours = np.array([node[s] for s in common])
    theirs = np.array([again[s] for s in common])
    assert np.max(np.abs(ours)) > 1e-7                      # micrometres, not nothing
    np.testing.assert_allclose(theirs, ours, rtol=0, atol=1e-6 * np.max(np.abs(ours)))
