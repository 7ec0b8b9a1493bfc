"""
Every README and docs command that runs this package, run as written, or skipped with a reason.

The commands are read at test time from README.md, the pages of ``docs/`` and
``benchmarks/README.md``: every command of a fenced ``bash`` block (continuation lines
joined, comments dropped, split at ``&&``, ``;`` and a trailing ``&``) and every command in the
first column of the README's `flexlink` tool table. A command invokes the package when its
program is ``flexlink``, ``flexlink_node`` or ``crank_driver`` (bare or under ``.venv/bin/``),
``python -m flexlink_ros…``, or ``ros2 run|launch flexlink_ros``. Each such
command is either in ``RUN`` (run with the installed console scripts of the venv running this
test, ``.venv/bin/`` rewritten to it, in a temporary working directory holding what the README
says is there, e.g. the ``run1`` recording; exit code 0 and what the README says it prints or
writes asserted) or in ``SKIPPED`` with the reason (a ROS graph, a ROS distro, minutes of
work) and the test that covers it. A command in neither fails the test, so a new README
command is either run or consciously skipped.

"From a fresh venv": CI (``bash .ci/run`` on a clean clone) runs ``make test``, which creates
the venv from nothing, installs the pinned requirements and the package (``make install``:
console scripts in ``.venv/bin``), and runs this test with that venv's Python; locally, run
``make install`` first so the console scripts are the worktree's code.
"""

import dataclasses
import math
import pathlib
import re
import shlex
import shutil
import subprocess
import sys

from flexlink_ros.io.provenance import provenance_entries
from flexlink_ros.io.recorder import McapRecorder
from flexlink_ros.ros import messages as ros_messages
from flexlink_ros.ros.parameters import default_model_options
import pytest
from rclpy.serialization import serialize_message
from sensor_msgs.msg import JointState

ROOT = pathlib.Path(__file__).resolve().parents[1]
README = ROOT / 'README.md'
# The pages whose commands run too: the user's guide and the benchmarks' README.
PAGES = (README, *sorted((ROOT / 'docs').glob('*.md')), ROOT / 'benchmarks' / 'README.md')
VENV_BIN = pathlib.Path(sys.executable).parent
SCRIPTS = ('flexlink', 'flexlink_node', 'crank_driver')


@dataclasses.dataclass
class Run:
    """How a README command is run and what its README text promises."""

    prints: tuple = ()            # fragments of stdout
    creates: tuple = ()           # paths relative to the working directory
    setup: str = ''               # 'run1' (a closed recording), 'run1 killed' (no metadata)
    #                               or 'my_linkage' (a mechanism file of one's own)
    argv: tuple = ()              # the command lines run instead, where the README has a synopsis


RUN = {
    # Recording, replay, Foxglove: `run1` is the node's recording (record.path:=run1).
    'flexlink mcap-info run1':
        Run(('run1: 1000 messages over 0.999 s', '/joint_states', 'sensor_msgs/msg/JointState',
             'made with: flexlink_node'), setup='run1'),
    'flexlink mcap-recover run1/run1_0.mcap':
        Run(('recovered 1000 messages', 'into run1_0.recovered.mcap'),
            creates=('run1_0.recovered.mcap',), setup='run1'),
    'flexlink replay run1 --out rerun.mcap':
        Run(('1000 samples on /joint_states', 'wrote rerun.mcap'), creates=('rerun.mcap',),
            setup='run1'),
    'flexlink fleet run1 --out fleet --mechanism cho1992':
        Run(('run1: 1000 samples, 0 skipped', '1 bag(s), 0 failed'),
            creates=('fleet/summary.parquet',), setup='run1'),
    'flexlink reindex run1':     # "after the recorder was killed": no metadata.yaml yet
        Run(('run1/metadata.yaml: 1 files, 1000 messages',), creates=('run1/metadata.yaml',),
            setup='run1 killed'),
    'flexlink replay run1 --out rerun.mcap --chart rerun.png':
        Run(('1000 samples on /joint_states', 'wrote rerun.mcap'),
            creates=('rerun.mcap', 'rerun.png'), setup='run1'),
    # docs/cli.md and the own-linkage quick start.
    'flexlink criteria --mechanism kang1990 --rpm 300': Run(('true max', 'grid max')),
    'flexlink modes --mechanism my_linkage.yaml --crank-deg 0:360:30':
        Run(('frozen modes', 'f1 [Hz]'), setup='my_linkage'),
    'flexlink modes --mechanism my_linkage.yaml --crank-deg 0:360:45':
        Run(('frozen modes', 'f1 [Hz]'), setup='my_linkage'),
    # The `flexlink` tool table.
    'flexlink kinematics --mechanism kang1990 --crank-deg 0:360:30':
        Run(('dead centres', 'transmission angle', 'coupler', 'lever')),
    'flexlink kinematics --mechanism kang1990 --crank-deg 0:360:30 --rpm 300':
        Run(('dead centres', 'transmission angle')),
    'flexlink criteria --mechanism kang1990 [--spring K THETA0_DEG]':
        Run(('true max', 'grid max', 'min R'), argv=(
            'flexlink criteria --mechanism kang1990',
            'flexlink criteria --mechanism kang1990 --spring 20 279.14')),
    'flexlink design-spring --mechanism kang1990':
        Run(('design  K =', 'objective')),
    'flexlink beam --bc cantilever --segments 6 --method tmm3':
        Run(('cantilever beam, tmm3, 6 segments', 'omega [rad/s]', 'exact [rad/s]')),
    'flexlink modes --mechanism cho1992 --crank-deg 0:360:5':
        Run(('frozen modes', 'f1 [Hz]')),
    'flexlink simulate --mechanism cho1992 --rpm 391 --method full':
        Run(('at 391 rpm, full', 'peak-to-peak')),
    'flexlink estimate --mechanism cho1992 --rpm 391 --jitter 0.3':
        Run(('at 391 rpm', 'jitter 0.3', 'lever tip', 'update')),
    # Named in the prose; run here too if a fenced block shows them.
    'flexlink --version': Run(('flexlink ',)),
    'flexlink_node --help': Run(('parameters (--ros-args -p name:=value',)),
    '.venv/bin/flexlink_node --help': Run(('parameters (--ros-args -p name:=value',)),
    'crank_driver --help': Run(('speed_rpm',)),
}

_COLCON = ('needs a ROS 2 distro (ros2 run, colcon): '
           'test/test_packaging.py::test_colcon_build_resolves_like_ros2_run builds the package '
           'with colcon and resolves the executables as ros2 run does')
_LAUNCH = ('needs ros2 launch (a ROS 2 distro; launch and launch_ros are not on PyPI): '
           'test/test_launch_files.py builds each launch description and, where launch_ros '
           'is importable, runs it')
_PUBLISH = ('publishes into a live ROS graph (waits up to 10 s for a subscriber): '
            'test/ros/test_republish.py runs replay --publish with subscribers')
_OWN = ('builds the model of a linkage not in config/ (a minute on a loaded machine): '
        'test/report/test_cycle_chart.py::test_estimate_chart_of_a_linkage_not_in_config')
SKIPPED = {
    '.venv/bin/crank_driver --ros-args -p speed_rpm:=391.0':
        'runs until stopped, publishing into a ROS graph: test/ros/test_crank_driver.py and '
        'make demo (test/cli/test_demo.py) run it',
    '.venv/bin/flexlink_node --ros-args -p record.enabled:=true -p record.path:=run1':
        'runs until stopped and needs a crank driver: '
        'test/ros/test_node.py::test_node_end_to_end records from one',
    'ros2 run flexlink_ros crank_driver --ros-args -p profile:=sweep -p sweep.max_rpm:=600.0':
        _COLCON,
    'ros2 run flexlink_ros flexlink_node --ros-args --params-file '
    'install/flexlink_ros/share/flexlink_ros/config/flexlink_node.yaml': _COLCON,
    'ros2 run flexlink_ros flexlink_node --managed': _COLCON,
    'ros2 run flexlink_ros crank_driver --ros-args -r __ns:=/robot1 --params-file '
    'install/flexlink_ros/share/flexlink_ros/config/crank_driver.yaml': _COLCON,
    'ros2 run flexlink_ros flexlink_node --ros-args -r __ns:=/robot1 --params-file '
    'install/flexlink_ros/share/flexlink_ros/config/flexlink_node.yaml '
    '-p diagnostics.hardware_id:=linkage_1': _COLCON,
    'ros2 run flexlink_ros flexlink_node --ros-args -r __ns:=/robot2 --params-file '
    'install/flexlink_ros/share/flexlink_ros/config/flexlink_node.yaml '
    '-p diagnostics.hardware_id:=linkage_2': _COLCON,
    'ros2 launch flexlink_ros flexlink.launch.py': _LAUNCH,
    'ros2 launch flexlink_ros flexlink.launch.py driver:=true namespace:=robot1': _LAUNCH,
    'ros2 launch flexlink_ros flexlink.launch.py mechanism:=kang1990 params_file:=my_node.yaml':
        _LAUNCH,
    'ros2 launch flexlink_ros flexlink_lifecycle.launch.py driver:=true': _LAUNCH,
    'ros2 launch flexlink_ros flexlink_lifecycle.launch.py autostart:=false': _LAUNCH,
    'ros2 launch flexlink_ros flexlink.launch.py --show-args': _LAUNCH,
    'ros2 launch flexlink_ros flexlink.launch.py mechanism:=/path/my_linkage.yaml '
    'params_file:=my_node.yaml': _LAUNCH,
    'flexlink replay other_bag --mechanism cho1992 --topic /robot/joint_states '
    '--joint crank_joint --publish':
        _PUBLISH,
    'flexlink replay run1 --publish --clock --rate 2 --loop --ros-args -r __ns:=/robot1':
        _PUBLISH + '; an endless loop, ended by Ctrl-C as test_republish.py '
        '::test_sigint_ends_an_endless_loop_with_a_summary_and_exit_code_0 does',
    'flexlink replay run1 --publish --clock-topics-all --loop-count 3 '
    '--ros-args -r joint_states:=/robot1/joint_states': _PUBLISH,
    'flexlink plan --mechanism cho1992 --rpm-max 391 --tolerance 0.01':
        'about 2 minutes of full-order references: test/studies/test_plan.py plans small cases',
    'flexlink validate --peer exudyn --rpm 269 391 --chart out/validate.png':
        'about a minute of peer and full-order runs at 8 elements per link: '
        'test/cli/test_cli_validate.py runs it at 4',
    'flexlink design-spring --mechanism kang1990 --seed 1':
        'a global search of minutes: test/cli/test_cli_rigid.py'
        '::test_design_spring_json_small_budget runs it with a small budget',
    'flexlink estimate --mechanism my_linkage.yaml --rpm 300 --chart out/estimate.png': _OWN,
    'flexlink estimate --mechanism my_linkage.yaml --rpm 600 --chart my_600rpm.png': _OWN,
    'flexlink plan --mechanism my_linkage.yaml --rpm-max 600 --tolerance 0.02':
        'minutes of full-order references: test/studies/test_plan.py plans small cases',
    'flexlink replay run1 --chart run1.png':
        "replays the quick start's own node recording: test/test_quickstart.py"
        '::test_every_quickstart_command_runs_on_a_linkage_not_in_config runs it',
    'flexlink replay other_bag --mechanism my_linkage.yaml --out rerun2.mcap':
        "needs the user's own bag: test/cli/test_replay.py replays bags of other topics",
    "flexlink fleet 'recordings/line1_*' --out out/fleet --mechanism cho1992":
        'needs a directory of recordings: test/cli/test_fleet.py'
        '::test_bags_from_paths_and_globs_each_once_and_their_output_names',
    "flexlink fleet 'recordings/*' --out out/fleet --mechanism cho1992 "
    '--address 127.0.0.2:6380 --json':
        'needs a running Ray cluster: test/cli/test_fleet.py::test_fleet_on_a_two_node_cluster',
    'flexlink mcap-record run2 --topic /joint_states --duration-s 10':
        'records 10 s from a live ROS graph: test/io/test_recorder.py tests mcap-record',
    'flexlink demo --seconds 6 --rpm 391':
        'starts crank_driver and flexlink_node on a ROS graph: '
        'test/cli/test_demo.py::test_demo_runs_records_and_summarises runs it',
    'flexlink node-bench --rate-hz 1000 --seconds 3':
        'starts nodes on a ROS graph: test/cli/test_node_bench.py'
        '::test_node_bench_measures_every_target runs it',
    'flexlink_node --ros-args -p mechanism:=my_linkage.yaml -p record.enabled:=true '
    '-p record.path:=run1':
        'runs until stopped and needs a crank driver: '
        'test/ros/test_node.py::test_node_end_to_end records from one',
    'crank_driver --ros-args -p speed_rpm:=600.0':
        'runs until stopped, publishing into a ROS graph: test/ros/test_crank_driver.py',
    'flexlink_node --ros-args --params-file my_node.yaml':
        "runs until stopped and needs a crank driver and the plan's parameters file: "
        'test/cli/test_plan_params.py checks the file the node reads',
    'flexlink_node --ros-args --params-file my_node.yaml -p record.enabled:=true '
    '-p record.path:=run1':
        'runs until stopped and needs a crank driver: '
        'test/ros/test_node.py::test_node_end_to_end records from one',
    'flexlink plan --mechanism my_linkage.yaml --rpm-max 600 --tolerance 0.02 --quick '
    '--params-out my_node.yaml':
        'a quick plan of the quick start: test/test_quickstart.py'
        '::test_every_quickstart_command_runs_on_a_linkage_not_in_config runs it',
    'flexlink estimate --rpm 391 --rigid-crank --bearings flexible --stiffness-damping 1e-4 '
    '--nonlinear on':
        'builds the reduced nonlinear model (minutes on a loaded machine): '
        'test/cli/test_cli_estimate.py runs the estimator; docs/nonlinear.md names its tests',
    'flexlink node-bench': 'starts nodes on a ROS graph and measures for minutes',
    'flexlink report --out out/report': 'about 4 minutes (every chart)',
    'flexlink demo': 'starts crank_driver and flexlink_node on a ROS graph: '
                     'test/cli/test_demo.py::test_demo_runs_records_and_summarises runs it',
}


def _simple_commands(line):
    """Split one shell line (comment dropped) into its simple commands."""
    line = re.sub(r'(^|\s)#.*$', '', line).strip()
    for part in re.split(r'&&|;|(?<![&|])&(?!&)', line):
        if part.strip():
            yield ' '.join(part.split())


def fenced_commands(text):
    """Yield every simple command of the fenced ``bash`` blocks of ``text``."""
    for block in re.findall(r'^```bash\n(.*?)^```', text, flags=re.M | re.S):
        for line in block.replace('\\\n', ' ').splitlines():
            yield from _simple_commands(line)


def table_commands(text):
    """Yield the commands in the first column of the `flexlink` tool table."""
    section = text.split('## The `flexlink` tool', 1)[-1].split('\n## ', 1)[0]
    for row in re.findall(r'^\| (.*?) \|', section, flags=re.M):
        yield from (span for span in re.findall(r'`([^`]+)`', row)
                    if span.startswith('flexlink'))


def invokes_package(command):
    """Whether ``command`` runs this package (see the module docstring)."""
    words = [w for w in command.split() if not re.match(r'^[A-Z_][A-Z0-9_]*=', w)]
    if not words:
        return False
    program = words[0].rsplit('/', 1)[-1]
    if program in SCRIPTS:
        return True
    if re.match(r'python[0-9.]*$', program):
        return len(words) > 2 and words[1] == '-m' and words[2].startswith('flexlink_ros')
    return program == 'ros2' and len(words) > 2 and words[1] in ('run', 'launch') \
        and words[2] == 'flexlink_ros'


def readme_commands():
    """Every command of README and the docs pages that invokes the package, once each, in order."""
    found = []
    for page in PAGES:
        text = page.read_text()
        tables = table_commands(text) if page == README else ()
        found += [c for c in (*fenced_commands(text), *tables) if invokes_package(c)]
    return list(dict.fromkeys(found))


def _program_argv(command):
    """Return ``command``'s argv with the program taken from the venv running this test."""
    argv = shlex.split(command)
    program = argv[0].rsplit('/', 1)[-1]
    if program in SCRIPTS:
        return [str(VENV_BIN / program), *argv[1:]]
    return [sys.executable, *argv[1:]]    # python -m flexlink_ros…


@pytest.fixture(scope='module')
def run1(tmp_path_factory):
    """Write ``run1`` as ``flexlink_node -p record.path:=run1`` does: 1 s of 1 kHz crank."""
    path = tmp_path_factory.mktemp('readme') / 'run1'
    speed = 391.0 * 2.0 * math.pi / 60.0
    made_by = provenance_entries('flexlink_node', 'cho1992', default_model_options())
    with McapRecorder(path, provenance=made_by) as recorder:
        recorder.add_topic('/joint_states', JointState)
        for k in range(1000):
            stamp = 1_700_000_000_000_000_000 + k * 1_000_000
            message = JointState(name=['crank'], velocity=[speed],
                                 position=[math.remainder(speed * k * 1e-3, 2 * math.pi)])
            message.header.stamp = ros_messages.ns_to_stamp(stamp)
            recorder.write('/joint_states', serialize_message(message), stamp + 200_000)
    return path


def test_readme_commands_are_found():
    commands = readme_commands()
    assert 'flexlink replay run1 --out rerun.mcap' in commands
    assert 'flexlink kinematics --mechanism kang1990 --crank-deg 0:360:30' in commands
    # The pages moved out of the README keep their commands in the test.
    assert 'flexlink modes --mechanism my_linkage.yaml --crank-deg 0:360:45' in commands
    assert any(c.startswith('ros2 launch flexlink_ros') for c in commands)
    assert not any(invokes_package(c) for c in ('make demo', 'cd ~/ws', 'export A=1'))


@pytest.mark.parametrize('command', readme_commands())
def test_readme_command(command, tmp_path, run1):
    if command in SKIPPED:
        pytest.skip(SKIPPED[command])
    assert command in RUN, f'README command neither run nor listed in SKIPPED: {command!r}'
    case = RUN[command]
    if case.setup == 'my_linkage':
        shutil.copy(ROOT / 'config' / 'cho1992.yaml', tmp_path / 'my_linkage.yaml')
    elif case.setup:
        shutil.copytree(run1, tmp_path / 'run1')
        if case.setup == 'run1 killed':
            (tmp_path / 'run1' / 'metadata.yaml').unlink()
    for line in case.argv or (command,):
        result = subprocess.run(_program_argv(line), cwd=tmp_path, capture_output=True,
                                text=True, timeout=300)
        assert result.returncode == 0, (line, result.stderr[-2000:])
        for fragment in case.prints:
            assert fragment in result.stdout, (line, fragment, result.stdout[-2000:])
    for created in case.creates:
        assert (tmp_path / created).is_file(), created


def test_readme_python_example_runs_and_prints_a_plausible_deflection(tmp_path):
    section = README.read_text().split('## Python API', 1)[1].split('\n## ', 1)[0]
    (example,) = re.findall(r'^```python\n(.*?)^```', section, flags=re.M | re.S)
    result = subprocess.run([sys.executable, '-c', example], cwd=tmp_path, capture_output=True,
                            text=True, timeout=600)
    assert result.returncode == 0, result.stderr[-2000:]
    micrometres = float(re.search(r'lever tip peak-to-peak dx: (\d+) um', result.stdout)[1])
    # The node's default model at 391 rpm: about 10 800 um (make demo's and the reference's).
    assert 5_000 < micrometres < 20_000, result.stdout
