"""`flexlink fleet` on a real Ray: embedded and on a two-node cluster, against single replays."""

import json
import math
import os
import pathlib
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time

from fleet_bags import bad_messages, crank_stream, MODEL_FLAGS, write_bag
from flexlink_ros.cli.fleet import expand_bags, output_paths
import numpy as np
import pandas as pd
import pytest
from rclpy.serialization import deserialize_message
from rosbags.highlevel import AnyReader, AnyReaderError
from sensor_msgs.msg import JointState

RAY = pathlib.Path(sys.executable).with_name('ray')
ROOT = pathlib.Path(__file__).resolve().parents[2]
# Replay's --json keys whose values depend on the run's timing or output path.
TIMING_KEYS = {'read_s', 'estimate_s', 'write_s', 'samples_per_s', 'times_real_time',
               'output', 'output_files', 'input'}


def flexlink(*args, env=None, timeout=300):
    return subprocess.run([sys.executable, '-m', 'flexlink_ros.cli.main', *args],
                          capture_output=True, text=True, timeout=timeout, env=env)


def messages(path, topic_suffix, decode=None):
    """(stamp [ns], message, raw bytes) on the topic ending so, in log order (readable ones)."""
    found = []
    with AnyReader([pathlib.Path(path)]) as reader:
        chosen = [c for c in reader.connections if c.topic.endswith(topic_suffix)]
        for connection, _, data in reader.messages(connections=chosen):
            try:
                message = (decode(bytes(data)) if decode
                           else reader.deserialize(data, connection.msgtype))
            except (AnyReaderError, ValueError, TypeError):   # the tests' bad messages
                continue
            stamp = message.header.stamp.sec * 1_000_000_000 + message.header.stamp.nanosec
            found.append((stamp, message, bytes(data)))
    return found


def check_rows_against_replay(rows, replay_out):
    """Each row's numbers from the replay's own output file, over the row's stamps."""
    # The input as rclpy wrote it (its padding is not what rosbags expects).
    decode = lambda data: deserialize_message(data, JointState)  # noqa: E731
    inputs = [(s, m, b) for s, m, b in messages(replay_out, '/joint_states', decode)
              if list(m.name) == ['crank'] and np.isfinite(m.position[0])]
    stamps = np.array([s for s, _, _ in inputs])
    angles = np.mod([m.position[0] for _, m, _ in inputs], 2 * math.pi)
    lever = {s: (m.vector.x, m.vector.y)
             for s, m, _ in messages(replay_out, 'lever_tip/deflection')}
    criteria = {s: list(m.position) for s, m, _ in messages(replay_out, '/joint_criteria')}
    rows = rows.sort_values('index')
    assert rows['samples'].sum() == stamps.size
    for _, row in rows.iterrows():
        inside = (stamps >= row['start_stamp_ns']) & (stamps <= row['end_stamp_ns'])
        assert np.count_nonzero(inside) == row['samples']
        first = int(np.flatnonzero(inside)[0])
        # A revolution starts where the angle passed 2 pi (or after the gap's restart).
        assert first == 0 or angles[first] < angles[first - 1] or (
            stamps[first] - stamps[first - 1] > 500_000_000)
        values = np.array([lever[s] for s in stamps[inside] if s in lever])
        assert row['lever_tip_dx_p2p_um'] == pytest.approx(
            1e6 * (values[:, 0].max() - values[:, 0].min()), rel=1e-9, abs=1e-9)
        assert row['lever_tip_dy_p2p_um'] == pytest.approx(
            1e6 * (values[:, 1].max() - values[:, 1].min()), rel=1e-9, abs=1e-9)
        worst = np.max([criteria[s] for s in stamps[inside] if s in criteria], axis=0)
        for k, joint in enumerate(('O2', 'A', 'B', 'O4')):
            assert row[f'criterion_max_{joint}'] == pytest.approx(worst[k], rel=1e-9)


@pytest.fixture(scope='module')
def bags(tmp_path_factory):
    root = tmp_path_factory.mktemp('fleet')
    stamps, angles, speeds = crank_stream(2.0, 391.0)
    write_bag(root / 'steady', stamps, angles, speeds)
    stamps, angles, speeds = crank_stream(1.5, 300.0, gap_at=1.0, start_angle=-2.0)
    write_bag(root / 'gappy.mcap', stamps, angles, speeds, bad_messages(stamps, [7, 900, 1300]))
    (root / 'corrupt.mcap').write_bytes(b'not a recording\n' * 64)
    return root


def test_fleet_equals_one_replay_per_bag(bags, tmp_path):
    out = tmp_path / 'out'
    result = flexlink('fleet', str(bags / 'steady'), str(bags / '*.mcap'),
                      str(bags / 'no_such_*'), '--out', str(out), '--mechanism', 'cho1992',
                      *MODEL_FLAGS, '--write-mcap', '--json', '--num-cpus', '2')
    assert result.returncode == 1, result.stderr      # two of four failed
    assert 'Traceback' not in result.stderr
    summaries = {pathlib.Path(s['bag']).name: s
                 for s in map(json.loads, result.stdout.splitlines())}
    assert sorted(summaries) == ['corrupt.mcap', 'gappy.mcap', 'no_such_*', 'steady']
    assert 'corrupt.mcap is not an MCAP file' in summaries['corrupt.mcap']['error']
    assert 'no such file' in summaries['no_such_*']['error']
    table = pd.read_parquet(out / 'summary.parquet')
    for name in ('steady', 'gappy.mcap'):
        replay_out = tmp_path / f'replay_{name}.mcap'
        replay = flexlink('replay', str(bags / name), '--out', str(replay_out), '--json',
                          '--mechanism', 'cho1992', *MODEL_FLAGS)
        assert replay.returncode == 0, replay.stderr
        expected = json.loads(replay.stdout)
        got = summaries[name]
        assert got['error'] is None and got['node'] == '127.0.0.1'
        assert set(expected) <= set(got)
        # Replay's note on where its model came from is the fleet's 'mechanism' column.
        assert got['mechanism'] == '--mechanism cho1992'
        # Both chose by the linear estimate's validity (auto: the bag names no model).
        assert got['model_choice'] == expected['model_choice']
        assert got['model_choice']['asked'] == 'auto'
        for key in set(expected) - TIMING_KEYS - {'notes'}:
            if key.endswith('peak_to_peak_um'):
                assert got[key] == pytest.approx(expected[key], rel=1e-9), key
            else:
                assert got[key] == expected[key], key
        rows = table[table['bag'].map(lambda b: pathlib.Path(b).name) == name]
        assert rows['error'].isna().all() and rows['mechanism'].eq('--mechanism cho1992').all()
        check_rows_against_replay(rows, replay_out)
        assert rows['skipped'].sum() == expected['skipped']
        # The written MCAP is replay's, message for message.
        written = pathlib.Path(got['output'])
        assert written.parent == out / 'mcap'
        for topic in ('lever_tip/deflection', 'coupler_mid/deflection', '/joint_criteria',
                      '/quality'):
            assert [b for _, _, b in messages(written, topic)] == [
                b for _, _, b in messages(replay_out, topic)]
    assert summaries['gappy.mcap']['skipped'] == 3 and summaries['gappy.mcap']['segments'] == 2
    failed = table[table['index'] == -1]
    failed_names = sorted(failed['bag'].map(lambda b: pathlib.Path(b).name))
    assert failed_names == ['corrupt.mcap', 'no_such_*']


def test_a_bag_made_with_the_nonlinear_model_is_recomputed_with_it(bags, tmp_path):
    """A recording whose provenance says nonlinear: on (the node's default near resonance)."""
    made = tmp_path / 'nonlinear.mcap'
    first = flexlink('replay', str(bags / 'steady'), '--out', str(made), '--mechanism',
                     'cho1992', *MODEL_FLAGS, '--nonlinear', 'on')
    assert first.returncode == 0, first.stderr
    replay_out = tmp_path / 'replayed.mcap'
    replay = flexlink('replay', str(made), '--out', str(replay_out), '--json')
    assert replay.returncode == 0, replay.stderr
    expected = json.loads(replay.stdout)
    assert expected['model_choice']['nonlinear'] is True
    out = tmp_path / 'out'
    result = flexlink('fleet', str(made), '--out', str(out), '--write-mcap', '--json',
                      '--num-cpus', '1')
    assert result.returncode == 0, result.stderr
    (got,) = map(json.loads, result.stdout.splitlines())
    assert got['error'] is None and got['model_choice'] == expected['model_choice']
    assert got['nonlinear'] == expected['nonlinear'] and got['nonlinear']['samples'] > 1000
    for key in set(expected) - TIMING_KEYS - {'notes'}:
        if key.endswith('peak_to_peak_um'):
            assert got[key] == pytest.approx(expected[key], rel=1e-9), key
        else:
            assert got[key] == expected[key], key
    check_rows_against_replay(pd.read_parquet(out / 'summary.parquet'), replay_out)
    for topic in ('lever_tip/deflection', 'coupler_mid/deflection'):
        assert [b for _, _, b in messages(got['output'], topic)] == [
            b for _, _, b in messages(replay_out, topic)]


def test_without_a_mechanism_a_bag_fails_with_its_reason(bags, tmp_path):
    result = flexlink('fleet', str(bags / 'steady'), '--out', str(tmp_path), '--num-cpus', '1')
    assert result.returncode == 1 and 'Traceback' not in result.stderr
    assert 'no recorded mechanism: give `--mechanism`' in result.stdout
    table = pd.read_parquet(tmp_path / 'summary.parquet')
    assert table['index'].tolist() == [-1]
    assert 'no recorded mechanism' in table.loc[0, 'error']
    again = flexlink('fleet', str(bags / 'steady'), '--out', str(tmp_path))
    assert again.returncode == 1 and 'summary.parquet' in again.stderr and 'exists' in again.stderr
    a_file = tmp_path / 'summary.parquet'
    again = flexlink('fleet', str(bags / 'steady'), '--out', str(a_file))
    assert again.returncode == 1 and 'is not a directory' in again.stderr


# Runs the CLI with ray and pyarrow unimportable (as without the .[fleet] extra).
WITHOUT_RAY = """
import sys
sys.modules['ray'] = sys.modules['pyarrow'] = None
from flexlink_ros.cli import main
main.build_parser()     # every command's module imports
assert main.main(['kinematics', '--mechanism', 'kang1990', '--crank-deg', '0:360:90']) == 0
sys.exit(main.main(sys.argv[1:]))
"""


def test_without_ray_only_fleet_refuses(bags, tmp_path):
    result = subprocess.run([sys.executable, '-c', WITHOUT_RAY, 'fleet', str(bags / 'steady'),
                             '--out', str(tmp_path / 'out'), '--mechanism', 'cho1992'],
                            capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert result.returncode == 1, result.stderr
    assert "flexlink fleet: error: needs Ray (pip install '.[fleet]'" in result.stderr
    assert 'Traceback' not in result.stderr and not (tmp_path / 'out').exists()


def free_port(host):
    with socket.socket() as probe:
        probe.bind((host, 0))
        return probe.getsockname()[1]


def ray_node(args, env, log):
    """Start one Ray node in its own process group (ended by its id at the end)."""
    return subprocess.Popen([str(RAY), 'start', '--block', '--num-cpus', '1',
                             '--object-store-memory', str(80 * 1024 * 1024), *args],
                            env=env, stdout=log, stderr=subprocess.STDOUT,
                            start_new_session=True)


def stop_nodes(nodes):
    """End the nodes' process groups: politely, then for good."""
    for node in nodes:
        with_group(node, signal.SIGTERM)
    deadline = time.monotonic() + 10.0
    for node in nodes:
        try:
            node.wait(max(deadline - time.monotonic(), 0.1))
        except subprocess.TimeoutExpired:
            pass
        with_group(node, signal.SIGKILL)
        node.wait(10)


def with_group(node, signum):
    try:
        os.killpg(node.pid, signum)
    except ProcessLookupError:
        pass


def wait_for_nodes(address, env, count, timeout=90.0):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        status = subprocess.run([str(RAY), 'status', '--address', address], env=env,
                                capture_output=True, text=True, timeout=60)
        active = status.stdout.split('Active:')[-1].split('Pending:')[0]
        if active.count('node_') >= count:
            return
        time.sleep(1.0)
    raise AssertionError(f'the cluster did not reach {count} nodes: {status.stdout}')


def test_fleet_on_a_two_node_cluster(bags, tmp_path):
    """Two nodes on loopback addresses (127.0.0.2 head, 127.0.0.3), the bags spread on both."""
    env = dict(os.environ, RAY_USAGE_STATS_ENABLED='0', RAY_AUTH_MODE='token')
    env.pop('RAY_ADDRESS', None)
    temp = tempfile.mkdtemp(prefix='rayfl', dir='/tmp')    # short: Ray's socket paths
    port = free_port('127.0.0.2')
    address = f'127.0.0.2:{port}'
    nodes = []
    # The cluster's token (~/.ray/auth_token), made if missing (kept if there; not printed).
    subprocess.run([str(RAY), 'get-auth-token', '--generate'], env=env, capture_output=True,
                   check=True, timeout=60)
    try:
        with open(tmp_path / 'nodes.log', 'w') as log:
            nodes.append(ray_node(['--head', f'--port={port}', '--node-ip-address=127.0.0.2',
                                   '--include-dashboard=false', '--disable-usage-stats',
                                   f'--temp-dir={temp}'], env, log))
            wait_for_nodes(address, env, 1)
            nodes.append(ray_node([f'--address={address}', '--node-ip-address=127.0.0.3'],
                                  env, log))
            wait_for_nodes(address, env, 2)
        inputs = [str(bags / 'steady')] * 1 + [str(bags / 'gappy.mcap')]
        copies = []
        for k in range(4):     # four bags for two one-CPU nodes
            copy = tmp_path / f'bag{k}'
            shutil.copytree(inputs[0], copy) if k % 2 == 0 else shutil.copy(inputs[1], copy)
            copies.append(str(copy))
        result = flexlink('fleet', *copies, '--out', str(tmp_path / 'out'), '--address',
                          address, '--mechanism', 'cho1992', *MODEL_FLAGS, '--json',
                          '--per', 'minute', env=env)
    finally:
        stop_nodes(nodes)
        shutil.rmtree(temp, ignore_errors=True)
    assert result.returncode == 0, result.stderr + (tmp_path / 'nodes.log').read_text()
    summaries = [json.loads(line) for line in result.stdout.splitlines()]
    assert {s['node'] for s in summaries} == {'127.0.0.2', '127.0.0.3'}
    table = pd.read_parquet(tmp_path / 'out' / 'summary.parquet')
    assert table['error'].isna().all() and table['per'].eq('minute').all()
    # Bags of under a minute: a row per segment of the estimate (the gap starts one).
    for summary in summaries:
        rows = table[table['bag'] == summary['bag']]
        assert len(rows) == summary['segments'] and rows['samples'].sum() == summary['samples']
    # The same numbers for the same recording, whichever node computed it.
    by_bag = {b: rows.drop(columns='bag').reset_index(drop=True)
              for b, rows in table.groupby('bag')}
    pd.testing.assert_frame_equal(by_bag[copies[0]], by_bag[copies[2]])
    pd.testing.assert_frame_equal(by_bag[copies[1]], by_bag[copies[3]])


def test_bags_from_paths_and_globs_each_once_and_their_output_names(tmp_path):
    for name in ('a/run', 'b/run', 'b/other.mcap'):
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_bytes(b'')
    bags, unmatched = expand_bags([str(tmp_path / 'a' / 'run'), str(tmp_path / '*' / 'run'),
                                   str(tmp_path / '**' / '*.mcap'), str(tmp_path / 'none*')])
    assert bags == [str(tmp_path / p) for p in ('a/run', 'b/run', 'b/other.mcap')]
    assert unmatched == [str(tmp_path / 'none*')]
    outputs = output_paths(bags, tmp_path / 'out')
    assert [pathlib.Path(p).name for p in outputs] == ['run.mcap', 'run_2.mcap', 'other.mcap']
    (tmp_path / 'out' / 'mcap').mkdir(parents=True)
    (tmp_path / 'out' / 'mcap' / 'run_2.mcap').write_bytes(b'')
    with pytest.raises(FileExistsError, match='run_2.mcap'):
        output_paths(bags, tmp_path / 'out')
