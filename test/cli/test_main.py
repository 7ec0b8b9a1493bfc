"""
`flexlink` (cli/main.py): the version, the split of ROS arguments, exit codes.

`--version` is one number, the same in the package, setup.py and package.xml; a mechanism
file refused on load ends every command with one line and exit code 2.
"""

import ast
import importlib.metadata
import json
import pathlib
import re
import subprocess
import sys
import xml.etree.ElementTree as ElementTree

import flexlink_ros
from flexlink_ros.cli import main as cli
import pytest
import yaml

ROOT = pathlib.Path(__file__).resolve().parents[2]
DATA = ROOT / 'test' / 'data'


def setup_py_version():
    """Return the ``version=`` literal of setup.py's ``setup(...)`` call."""
    tree = ast.parse((ROOT / 'setup.py').read_text())
    calls = [node for node in ast.walk(tree) if isinstance(node, ast.Call)
             and getattr(node.func, 'id', None) == 'setup']
    (keyword,) = [k for k in calls[0].keywords if k.arg == 'version']
    return ast.literal_eval(keyword.value)


def test_the_version_is_the_same_in_the_package_setup_py_and_package_xml():
    version = flexlink_ros.__version__
    assert re.fullmatch(r'\d+\.\d+\.\d+', version)
    assert setup_py_version() == version
    assert ElementTree.parse(ROOT / 'package.xml').getroot().findtext('version') == version
    try:
        installed = importlib.metadata.version('flexlink_ros')
    except importlib.metadata.PackageNotFoundError:
        return
    assert installed == version, 'the installed copy is stale: run `make install`'


def test_flexlink_version_prints_it_and_exits_0(capsys):
    with pytest.raises(SystemExit) as exit_info:
        cli.main(['--version'])
    assert exit_info.value.code == 0
    assert capsys.readouterr().out == f'flexlink {flexlink_ros.__version__}\n'
    run = subprocess.run([sys.executable, '-m', 'flexlink_ros.cli.main', '--version'],
                         capture_output=True, text=True, cwd=ROOT)
    assert run.returncode == 0 and run.stdout == f'flexlink {flexlink_ros.__version__}\n'


ENTRY_RUNS = [(['kinematics', '--crank-deg', '30', '--json'], 0),
              (['kinematics', '--crank-deg', 'x'], 1)]


@pytest.mark.parametrize('argv, code', ENTRY_RUNS)
def test_the_scripts_entry_exits_with_the_commands_code_after_all_its_output(argv, code):
    """The entry freezes what is left out of the collector before leaving: nothing is lost."""
    program = f'import sys; sys.argv = ["flexlink", *{argv!r}]; from flexlink_ros.cli.main ' \
              'import run; run()'
    done = subprocess.run([sys.executable, '-c', program], capture_output=True, text=True,
                          timeout=120, cwd=ROOT)
    assert done.returncode == code
    if code == 0:
        assert json.loads(done.stdout) == json.loads(subprocess.run(
            [sys.executable, '-m', 'flexlink_ros.cli', *argv], capture_output=True, text=True,
            timeout=120, cwd=ROOT, check=True).stdout)
    else:
        assert done.stdout == '' and done.stderr.startswith('flexlink kinematics: error:')


def test_ros_args_sections_are_split_off_as_rclpy_does():
    argv = ['replay', 'bag', '--ros-args', '-r', '__ns:=/r1', '--', '--publish',
            '--ros-args', '-r', 'a:=b']
    tool, ros = cli.split_ros_args(argv)
    assert tool == ['replay', 'bag', '--publish']
    assert ros == ['-r', '__ns:=/r1', '-r', 'a:=b']
    assert cli.split_ros_args(['mcap-info', 'run1']) == (['mcap-info', 'run1'], [])


MM_COMMANDS = [('modes', '--count', '1'), ('simulate', '--points-per-rev', '12'),
               ('estimate', '--rpm', '300'), ('plan', '--rpm-max', '300'),
               ('criteria', '--rpm', '300'), ('kinematics', '--crank-deg', '30')]


@pytest.mark.parametrize('command', MM_COMMANDS, ids=lambda c: c[0])
def test_a_mechanism_file_in_mm_is_refused_in_one_line_with_exit_2(command, tmp_path):
    data = yaml.safe_load((DATA / 'packaging_steel.yaml').read_text())
    data['ground_length_m'] *= 1000.0
    for link in data['links'].values():
        link['length_m'] *= 1000.0
        link['area_m2'] *= 1e6
        link['second_moment_m4'] *= 1e12
    path = tmp_path / 'packaging_mm.yaml'
    path.write_text(yaml.safe_dump(data))
    done = subprocess.run([sys.executable, '-m', 'flexlink_ros.cli', command[0], '--mechanism',
                           str(path), *command[1:]], capture_output=True, text=True,
                          timeout=120, cwd=ROOT)
    assert done.returncode == 2 and done.stdout == ''
    assert done.stderr == (f'flexlink {command[0]}: error: ground_length_m = 220: metres '
                           'expected, was this mm?\n')
