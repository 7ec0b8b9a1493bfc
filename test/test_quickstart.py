"""
docs/quickstart-own-linkage.md, run as a new user would on a linkage not in config/.

Every command of the page's fenced ``bash`` blocks runs, in page order, in one directory
holding the stiff steel linkage as ``my_linkage.yaml``: modes, estimate with its chart, the
node with the crank driver recording ``run1`` (real processes), mcap-info naming the
mechanism, and replay with no model flag reproducing the node's deflections. The one
exception is ``flexlink plan`` (a quarter of an hour on 2 cores): it is parsed by the real
parser and its ``--params-out`` file is written by the same function
(:func:`cli.plan_params.write_params_file`) for a small model.
"""

import math
import os
import pathlib
import shlex
import shutil
import subprocess

from flexlink_ros.cli import main as cli
from flexlink_ros.core.options import ModelOptions
from node_runs import stream_node_with_driver, write_small_plan_params
import numpy as np
from test_readme import fenced_commands, SCRIPTS, VENV_BIN

ROOT = pathlib.Path(__file__).resolve().parents[1]
PAGE = ROOT / 'docs' / 'quickstart-own-linkage.md'
LINKAGE = ROOT / 'test' / 'data' / 'packaging_steel.yaml'
# A small model of the steel linkage (what the plan writes, smaller): few elements and modes.
CHOICE = ModelOptions(modes=8, static=2, grid_size=64, rigid_crank=False, elements_per_link=3,
                      speed_max=1.05 * 600.0 * math.pi / 30.0, soft_modes=0)
STREAM_S = 3.0          # of the crank driver at 600 rpm


def _argv(command):
    argv = shlex.split(command)
    return [str(VENV_BIN / argv[0]), *argv[1:]] if argv[0] in SCRIPTS else argv


def _run(command, cwd):
    result = subprocess.run(_argv(command), cwd=cwd, capture_output=True, text=True,
                            timeout=600)
    assert result.returncode == 0, (command, result.stdout, result.stderr)
    assert 'Traceback' not in result.stderr, (command, result.stderr)
    return result.stdout


def _write_plan_params(command, cwd):
    """Parse the page's plan command and write its --params-out file for CHOICE."""
    args = cli.build_parser().parse_args(shlex.split(command)[1:])
    assert args.params_out == 'my_node.yaml' and args.rpm_max == 600.0
    write_small_plan_params(cwd / args.params_out, cwd / args.mechanism, CHOICE, cwd / 'cache',
                            args.rpm_max, args.tolerance)


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


def test_every_quickstart_command_runs_on_a_linkage_not_in_config(tmp_path):
    commands = list(fenced_commands(PAGE.read_text()))
    names = [c.split()[:2] for c in commands]
    assert names == [['flexlink', 'modes'], ['flexlink', 'estimate'], ['flexlink', 'plan'],
                     ['crank_driver', '--ros-args'], ['flexlink_node', '--ros-args'],
                     ['flexlink', 'mcap-info'], ['flexlink', 'replay']], commands
    shutil.copy(LINKAGE, tmp_path / 'my_linkage.yaml')
    modes = _run(commands[0], tmp_path)
    assert 'Hz' in modes
    _run(commands[1] + ' --cache-dir cache', tmp_path)
    assert (tmp_path / 'my_600rpm.png').stat().st_size > 10_000
    _write_plan_params(commands[2], tmp_path)
    _run_node_and_driver(commands[3:5], tmp_path)
    info = _run(commands[5], tmp_path)
    assert 'my_linkage.yaml (sha256' in info and 'modes=8, static=2' in info, info
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
