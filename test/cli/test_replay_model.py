"""
replay_model: `flexlink replay BAG` runs the model the recording says made it.

End to end through real processes: crank_driver -> flexlink_node (a soft test linkage that is
not in config/, non-default model options) -> bag -> `flexlink replay BAG` with no model flags
gives the node's deflections; a different --mechanism is used and said; a bag that names no
model is refused without --mechanism (exit code 2, one line).
"""

import json
import os
import pathlib
import signal
import subprocess
import sys
import time

from flexlink_ros.cli import main as cli_main
from flexlink_ros.cli.model_args import model_options
from flexlink_ros.cli.replay_model import replay_model, with_flag_defaults
from flexlink_ros.core import mechanism_file
from flexlink_ros.names import FIRST_INPUT_MESSAGE, READY_MESSAGE
from matplotlib import image
from node_runs import wait_for_log
import pytest
from test_replay import deflections_by_stamp, joint_state, write_recording

ROOT = pathlib.Path(__file__).resolve().parents[2]
SOFT = ROOT / 'test' / 'data' / 'soft_linkage.yaml'
STEEL = ROOT / 'test' / 'data' / 'steel_linkage.yaml'
CONFIG = ROOT / 'config'
# Each linkage, its crank speed [rpm] and the markers' exaggeration the node derives for it.
# The markers' exaggeration the node derives: the expected peak up to the machine's speed
# (1.25 x the file's speed, not the range's 620 rpm floor) drawn as at least 5 % of the
# coupler, on a 1-2-5 scale (soft: 250 um up to 375 rpm on a 0.2 m coupler, x50).
# Last: the node's model.nonlinear (auto: whatever the node chose, replay must choose too).
LINKAGES = {'soft': (SOFT, 300.0, 50, 'auto'), 'steel': (STEEL, 600.0, 200, 'auto'),
            'soft_nonlinear': (SOFT, 300.0, 50, 'on')}
READY_TIMEOUT_S = 240.0     # node start-up incl. a first model build on a loaded machine
ENV = dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path), PYTHONUNBUFFERED='1',
           RCUTILS_LOGGING_BUFFERED_STREAM='0')


def replay(*arguments, timeout=600):
    return subprocess.run([sys.executable, '-m', 'flexlink_ros.cli.main', 'replay',
                           *map(str, arguments)], capture_output=True, text=True,
                          timeout=timeout)


def test_a_bag_that_names_no_model_needs_mechanism(tmp_path):
    """A bag as `ros2 bag record` writes it: refused in one line without --mechanism."""
    bag = tmp_path / 'plain'
    write_recording(bag, [10**9 + k * 10**6 for k in range(50)],
                    [0.03 * k for k in range(50)], [30.0] * 50)
    result = replay(bag, '--out', tmp_path / 'out.mcap')
    assert result.returncode == 2, result.stderr
    assert result.stderr.count('\n') == 1 and 'give --mechanism' in result.stderr
    assert 'does not say which mechanism' in result.stderr
    assert not (tmp_path / 'out.mcap').exists()
    result = replay(bag, '--out', tmp_path / 'out.mcap', '--mechanism', 'cho1992',
                    '--markers-every-n', '0')
    assert result.returncode == 0, result.stderr
    assert 'note: the recording names no model: using --mechanism cho1992' in result.stdout


def test_the_mechanism_file_is_read_once_for_the_model_and_its_record(tmp_path, monkeypatch):
    """--mechanism on a bag that names no model: one read, and the record holds those bytes."""
    bag = tmp_path / 'plain'
    write_recording(bag, [10**9 + k * 10**6 for k in range(20)],
                    [0.03 * k for k in range(20)], [30.0] * 20)
    source = CONFIG / 'cho1992.yaml'
    linkage = tmp_path / 'linkage.yaml'
    linkage.write_bytes(source.read_bytes().replace(b'damping_ratio: 0.02',
                                                    b'damping_ratio: 0.03'))
    reads = []
    read_mapping = mechanism_file._read_mapping

    def counted(path_or_name, raw=None):
        reads.append(path_or_name)
        return read_mapping(path_or_name, raw)
    monkeypatch.setattr(mechanism_file, '_read_mapping', counted)
    args = cli_main.build_parser(['replay']).parse_args(
        ['replay', str(bag), '--mechanism', str(linkage), '--out', str(tmp_path / 'o.mcap')])
    mechanism, options, _, provenance = replay_model(args)
    assert len(reads) == 1
    assert mechanism.damping_ratio == 0.03 and provenance['damping_ratio'] == '0.03'
    assert provenance['mechanism_yaml'].encode() == linkage.read_bytes()
    assert provenance['mechanism_file'] == str(linkage.resolve())
    assert options == model_options(with_flag_defaults(args))     # as the flags alone give


def _record_linkage(tmp_path, processes, mechanism, rpm, nonlinear='auto'):
    """Driver -> node on a linkage for about 2 s; return the bag and the cache."""
    bag, cache, log = tmp_path / 'bag', tmp_path / 'cache', tmp_path / 'node.log'
    parameters = [f'mechanism:={mechanism}', 'record.enabled:=true', f'record.path:={bag}',
                  f'model.cache_dir:={cache}', 'model.grid_size:=96', 'damping_ratio:=0.05',
                  'crank_joint:=wheel', f'model.nonlinear:={nonlinear}']
    with open(log, 'w') as stream:
        node = subprocess.Popen(
            [sys.executable, '-m', 'flexlink_ros.ros.node', '--ros-args',
             *[arg for item in parameters for arg in ('-p', item)]],
            env=ENV, stdout=stream, stderr=subprocess.STDOUT)
    processes.append(node)
    wait_for_log(log, READY_MESSAGE, node, READY_TIMEOUT_S)
    driver = subprocess.Popen([sys.executable, '-m', 'flexlink_ros.ros.crank_driver',
                               '--ros-args', '-p', f'speed_rpm:={rpm}', '-p', 'joint_name:=wheel'],
                              env=ENV, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    processes.append(driver)
    wait_for_log(log, FIRST_INPUT_MESSAGE, node, 20.0)
    time.sleep(2.0)     # recording time, not synchronisation
    driver.send_signal(signal.SIGINT)
    driver.wait(timeout=20)
    node.send_signal(signal.SIGTERM)
    assert node.wait(timeout=30) == 0, log.read_text()
    return bag, cache


@pytest.mark.parametrize('linkage', sorted(LINKAGES))
def test_replay_of_a_node_bag_reproduces_the_node_with_no_flags(tmp_path, processes, linkage):
    mechanism, rpm, exaggeration, nonlinear = LINKAGES[linkage]
    bag, cache = _record_linkage(tmp_path, processes, mechanism, rpm, nonlinear)
    node_log = (tmp_path / 'node.log').read_text()
    (choice,) = [line.split(']: ', 1)[1] for line in node_log.splitlines()
                 if ']: model: linear (' in line or ']: model: nonlinear (' in line]
    node_nonlinear = choice.startswith('model: nonlinear')
    assert node_nonlinear or nonlinear != 'on', choice
    info = subprocess.run([sys.executable, '-m', 'flexlink_ros.cli.main', 'mcap-info',
                           str(bag)], capture_output=True, text=True, timeout=120)
    assert info.returncode == 0, info.stderr
    assert 'made with: flexlink_node' in info.stdout
    assert f'mechanism {mechanism}' in info.stdout and 'grid_size=96' in info.stdout

    # The node drew its markers at the exaggeration it derived and said so.
    assert f'markers: deflections drawn x{exaggeration} when markers.exaggeration is 0' in \
        (tmp_path / 'node.log').read_text()

    out, chart = tmp_path / 'replay.mcap', tmp_path / 'replay.png'
    result = replay(bag, '--out', out, '--cache-dir', cache, '--markers-every-n', '0',
                    '--json', '--chart', chart)
    assert result.returncode == 0, result.stderr
    summary = json.loads(result.stdout)
    assert summary['chart'] == str(chart)
    assert image.imread(chart).shape == (900, 1000, 4)   # the deflections over crank angle
    assert summary['notes'] == [] and 'grid_size=96' in summary['model']['options']
    assert summary['model_choice']['nonlinear'] is node_nonlinear, (choice, summary)
    node, replayed = deflections_by_stamp(bag), deflections_by_stamp(out)
    # (hundreds of samples: on a loaded machine the driver sends fewer than its 1 kHz)
    assert len(node) > 300 and sorted(replayed) == sorted(node)
    worst = max(abs(a - b) / max(abs(b), 1e-9) for stamp, values in node.items()
                for a, b in zip(replayed[stamp], values))
    assert worst < 1e-6
    peak = max(abs(v) for values in node.values() for v in values)
    assert peak > 1e-6          # micrometres: a real deflection, the same in both
    if linkage != 'soft':
        return

    # The replay's own output says the same, so it replays again with no flags.
    again = replay(out, '--out', tmp_path / 'again.mcap', '--cache-dir', cache,
                   '--markers-every-n', '0', '--json')
    assert again.returncode == 0, again.stderr
    assert json.loads(again.stdout)['notes'] == []
    assert deflections_by_stamp(tmp_path / 'again.mcap') == replayed

    other = replay(bag, '--out', tmp_path / 'cho.mcap', '--cache-dir', cache,
                   '--markers-every-n', '0', '--mechanism', ROOT / 'config' / 'cho1992.yaml',
                   '--bearings', 'rigid')
    assert other.returncode == 0, other.stderr
    notes = [line for line in other.stdout.splitlines() if 'note:' in line]
    assert len(notes) == 2, other.stdout
    assert "cho1992.yaml differs from the recording's" in notes[0]
    assert "--bearings rigid differs from the recording's flexible: using rigid" in notes[1]


@pytest.mark.parametrize('flag', ['--joint', '--mechanism'])
def test_a_broken_record_is_refused_in_one_line(tmp_path, flag):
    """A provenance record whose mechanism text was altered: one line, exit 1, no traceback."""
    from flexlink_ros.io.provenance import provenance_entries
    from flexlink_ros.io.recorder import McapRecorder
    from flexlink_ros.ros.parameters import default_model_options
    entries = provenance_entries('flexlink_node', str(SOFT), default_model_options())
    entries['mechanism_yaml'] = entries['mechanism_yaml'].replace('0.20,', '0.02,')
    bag = tmp_path / 'bag.mcap'
    with McapRecorder(bag, provenance=entries) as recorder:
        for k in range(50):
            recorder.write('/joint_states', joint_state(10**9 + k * 10**6, ['crank'],
                                                        [0.03 * k], [30.0]), 10**9 + k * 10**6)
    value = 'crank' if flag == '--joint' else 'cho1992'
    result = replay(bag, '--out', tmp_path / 'out.mcap', flag, value, '--markers-every-n', '0')
    if flag == '--joint':
        assert result.returncode == 1 and result.stderr.count('\n') == 1
        assert 'does not match its SHA-256' in result.stderr and 'Traceback' not in result.stderr
    else:    # --mechanism given: the broken record is set aside, said in a note
        assert 'does not match its SHA-256' in result.stdout, result.stderr
