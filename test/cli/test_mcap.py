"""`flexlink mcap-recover FILE` without --out, as the README runs it on a bag's file."""

import os
import pathlib
import subprocess
import sys

from flexlink_ros.cli import main as cli
from flexlink_ros.cli.mcap import default_recovered_path
from hostile_bag import ENTRIES, plant_hostile_entries
from mcap.reader import make_reader
from mcap.writer import Writer
import pytest

MESSAGES = 200
ROOT = pathlib.Path(__file__).resolve().parents[2]
# the tree's flexlink_ros, whatever the venv holds
ENV = dict(os.environ, PYTHONPATH=os.pathsep.join(
    [str(ROOT)] + [p for p in os.environ.get('PYTHONPATH', '').split(os.pathsep) if p]))


def write_truncated_bag(folder):
    """Write ``folder/<name>_0.mcap`` in small chunks and cut it short, as a SIGKILL does."""
    folder.mkdir()
    path = folder / f'{folder.name}_0.mcap'
    with open(path, 'wb') as stream:
        writer = Writer(stream, chunk_size=2048)
        writer.start(profile='ros2', library='test')
        schema = writer.register_schema('std_msgs/msg/String', 'ros2msg', b'string data')
        channel = writer.register_channel('/chatter', 'cdr', schema)
        for n in range(MESSAGES):
            writer.add_message(channel, n * 1000, bytes(100), n * 1000, sequence=n)
        writer.finish()
    data = path.read_bytes()
    path.write_bytes(data[:len(data) // 2])
    return path


def test_default_output_is_beside_the_bag_directory_and_never_overwritten(tmp_path):
    source = write_truncated_bag(tmp_path / 'run1')
    run = subprocess.run([sys.executable, '-m', 'flexlink_ros.cli.main', 'mcap-recover',
                          'run1/run1_0.mcap'], cwd=tmp_path, env=ENV, capture_output=True,
                         text=True)
    assert run.returncode == 0, run.stderr
    out = tmp_path / 'run1_0.recovered.mcap'
    assert 'into run1_0.recovered.mcap' in run.stdout
    assert sorted(p.name for p in (tmp_path / 'run1').iterdir()) == ['run1_0.mcap']
    with open(out, 'rb') as stream:
        reader = make_reader(stream)
        sequences = [message.sequence for _, _, message in reader.iter_messages()]
        summary = reader.get_summary()
    # the intact first half, in order, in a complete file (summary written)
    assert 0 < len(sequences) < MESSAGES and sequences == list(range(len(sequences)))
    assert summary.statistics.message_count == len(sequences)
    recovered = out.read_bytes()
    run = subprocess.run([sys.executable, '-m', 'flexlink_ros.cli.main', 'mcap-recover',
                          'run1/run1_0.mcap'], cwd=tmp_path, env=ENV, capture_output=True,
                         text=True)
    assert run.returncode == 1 and run.stdout == ''
    assert run.stderr.count('\n') == 1 and 'exists' in run.stderr and '--out' in run.stderr
    assert out.read_bytes() == recovered
    assert cli.main(['mcap-recover', str(source), '--out', str(tmp_path / 'x.mcap')]) == 0


def test_default_output_of_a_file_outside_a_bag_is_beside_it(tmp_path):
    assert default_recovered_path(tmp_path / 'cut.mcap') == tmp_path / 'cut.recovered.mcap'
    assert default_recovered_path('run1/run1_0.mcap').as_posix() == 'run1_0.recovered.mcap'
    assert default_recovered_path('/data/run1_3.mcap').as_posix() == \
        '/data/run1_3.recovered.mcap'


def test_recovery_and_info_keep_what_made_the_recording(tmp_path, capsys):
    """A killed node's file, recovered: the copy still names its mechanism and model."""
    from flexlink_ros.io.provenance import provenance_entries, read_provenance
    from flexlink_ros.io.recorder import McapRecorder
    from flexlink_ros.ros.parameters import default_model_options
    from sensor_msgs.msg import JointState
    made_by = provenance_entries('flexlink_node', 'kang1990', default_model_options())
    path = tmp_path / 'run.mcap'
    with McapRecorder(path, provenance=made_by, chunk_size_bytes=2048) as recorder:
        for n in range(300):
            recorder.write('/joint_states', JointState(name=['crank'], position=[0.01 * n]),
                           10**9 + n * 10**6)
    data = path.read_bytes()
    path.write_bytes(data[:len(data) // 2])     # cut short, as a SIGKILL does
    out = tmp_path / 'recovered.mcap'
    assert cli.main(['mcap-recover', str(path), '--out', str(out)]) == 0
    recorded = read_provenance(out)
    assert recorded is not None and recorded.producer == 'flexlink_node'
    assert recorded.mechanism().name == 'kang1990'
    assert recorded.options() == default_model_options()
    capsys.readouterr()
    assert cli.main(['mcap-info', str(out)]) == 0
    assert 'made with: flexlink_node' in capsys.readouterr().out


@pytest.mark.parametrize('names', [(name,) for name in ENTRIES] + [ENTRIES],
                         ids=[name[:-5] for name in ENTRIES] + ['all'])
def test_mcap_info_of_a_bag_skips_a_fifo_links_out_and_a_device_with_a_warning(tmp_path, names):
    """These once hung mcap-info for ever, read a file outside the bag, or failed the bag."""
    from flexlink_ros.io.recorder import McapRecorder
    from sensor_msgs.msg import JointState
    paths = {}
    for name in ('bag', 'elsewhere'):
        with McapRecorder(tmp_path / name) as recorder:
            for k in range(MESSAGES if name == 'bag' else 7):
                recorder.write('/joint_states', JointState(name=['crank']), 10**18 + k)
        paths[name] = tmp_path / name
    planted = plant_hostile_entries(paths['bag'], paths['elsewhere'] / 'elsewhere_0.mcap', names)
    done = subprocess.run([sys.executable, '-m', 'flexlink_ros.cli.main', 'mcap-info',
                           str(paths['bag'])], capture_output=True, text=True, timeout=60,
                          env=ENV)
    assert done.returncode == 0, done.stderr
    assert f'{MESSAGES} messages' in done.stdout.splitlines()[0]
    for name in planted:        # each said on stderr (warning) and in the report
        assert f'{paths["bag"] / name} skipped' in done.stderr
        assert f'  skipped {paths["bag"] / name}: ' in done.stdout
