"""
The launch files: installed where ament_index finds them, and what they launch.

``launch`` and ``launch_ros`` are not on PyPI, so where they are missing (CI) only the
installation and the files' shape are checked; with them importable (ros2/launch and
ros2/launch_ros installed from source, see the README) the launch descriptions are built and
inspected, and then run for real by ``launch.LaunchService``: crank_driver and the node (plain,
then managed and brought up by launch events) in a namespace, their estimates received here.
"""

import ast
import os
import pathlib
import signal
import subprocess
import sys
import time

import pytest

REPO = pathlib.Path(__file__).resolve().parents[1]
LAUNCH_DIR = REPO / 'launch'
LAUNCH_FILES = ('flexlink.launch.py', 'flexlink_lifecycle.launch.py')
ARGUMENTS = {'namespace', 'params_file', 'mechanism', 'use_sim_time', 'driver',
             'driver_params_file', 'log_level'}
READY_TIMEOUT_S = 240.0     # node start-up incl. a first model build on a loaded machine


def load_launch_file(path):
    """Import a launch file as a module (as ``ros2 launch`` does)."""
    import importlib.util
    spec = importlib.util.spec_from_file_location(path.name.replace('.', '_'), path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize('name', LAUNCH_FILES)
def test_launch_file_is_python_with_a_launch_description_function(name):
    tree = ast.parse((LAUNCH_DIR / name).read_text('utf-8'))
    functions = {node.name for node in tree.body if isinstance(node, ast.FunctionDef)}
    assert 'generate_launch_description' in functions
    compile(tree, name, 'exec')


def test_make_install_puts_the_launch_files_where_ament_index_finds_them():
    share = pathlib.Path(sys.prefix) / 'share' / 'flexlink_ros'
    if not (share / 'package.xml').is_file():
        pytest.skip('`make install` has not been run in this venv')
    # What `ros2 launch flexlink_ros NAME` looks up, with the venv as the ament prefix.
    code = ('from ament_index_python.packages import get_package_share_directory as share; '
            "print(share('flexlink_ros'))")
    env = dict(os.environ, AMENT_PREFIX_PATH=sys.prefix)
    found = subprocess.run([sys.executable, '-c', code], env=env, capture_output=True,
                           text=True, timeout=60, check=True).stdout.strip()
    for name in LAUNCH_FILES:
        installed = pathlib.Path(found) / 'launch' / name
        assert installed.is_file(), f'{installed}: run `make install`'
        assert installed.read_text('utf-8') == (LAUNCH_DIR / name).read_text('utf-8'), \
            f'{installed} is stale: run `make install`'


# -- with launch_ros (not on PyPI: skipped where it is missing) -------------------------------

def _require_launch_ros():
    pytest.importorskip('launch', reason='launch (ros2/launch) is not installed: not on PyPI')
    return pytest.importorskip('launch_ros',
                               reason='launch_ros (ros2/launch_ros) is not installed: not on PyPI')


def _text(context, substitutions):
    from launch.utilities import perform_substitutions
    return perform_substitutions(context, list(substitutions))


def _node_actions(description):
    from launch_ros.actions import Node
    return [entity for entity in description.entities if isinstance(entity, Node)]


@pytest.mark.parametrize('name', LAUNCH_FILES)
def test_launch_description_declares_and_launches_the_package_executables(name, monkeypatch):
    _require_launch_ros()
    from launch import LaunchContext
    from launch.actions import DeclareLaunchArgument
    monkeypatch.setenv('AMENT_PREFIX_PATH', sys.prefix)
    if not (pathlib.Path(sys.prefix) / 'share' / 'flexlink_ros').is_dir():
        pytest.skip('`make install` has not been run in this venv')
    description = load_launch_file(LAUNCH_DIR / name).generate_launch_description()
    declared = {entity.name: entity for entity in description.entities
                if isinstance(entity, DeclareLaunchArgument)}
    assert ARGUMENTS <= set(declared)
    assert all(argument.description for argument in declared.values())
    context = LaunchContext()
    defaults = {key: _text(context, argument.default_value)
                for key, argument in declared.items()}
    assert defaults['mechanism'] == 'cho1992' and defaults['driver'] == 'false'
    assert pathlib.Path(defaults['params_file']).name == 'flexlink_node.yaml'
    assert pathlib.Path(defaults['params_file']).is_file()
    nodes = {node.node_executable: node for node in _node_actions(description)}
    assert set(nodes) == {'flexlink_node', 'crank_driver'}
    node = nodes['flexlink_node']
    assert node.node_package == 'flexlink_ros'
    managed = name == 'flexlink_lifecycle.launch.py'
    assert (type(node).__name__ == 'LifecycleNode') == managed
    assert ('--managed' in [getattr(s, 'text', None) for s in node.cmd[1]]) == managed
    # The parameters as launch evaluates them: the file, then the arguments' overrides.
    context.launch_configurations.update(defaults)
    context.launch_configurations['mechanism'] = '1990'   # a string, though YAML reads a number
    params_file, overrides = _evaluated_parameters(context, node)
    assert pathlib.Path(params_file) == pathlib.Path(defaults['params_file'])
    assert overrides == {'mechanism': '1990', 'use_sim_time': False}
    params_file, = _evaluated_parameters(context, nodes['crank_driver'])
    assert pathlib.Path(params_file).name == 'crank_driver.yaml'


def _evaluated_parameters(context, node):
    from launch_ros.utilities import evaluate_parameters
    # launch_ros keeps a node's parameters private (no public accessor).
    return evaluate_parameters(context, node._Node__parameters)


def _ament_prefix(tmp_path):
    """Lay out an install prefix as colcon does, its executables running this source tree."""
    prefix = tmp_path / 'prefix'
    index = prefix / 'share' / 'ament_index' / 'resource_index' / 'packages'
    index.mkdir(parents=True)
    (index / 'flexlink_ros').write_text('')
    share = prefix / 'share' / 'flexlink_ros'
    share.mkdir()
    for name in ('config', 'launch', 'package.xml'):
        (share / name).symlink_to(REPO / name)
    lib = prefix / 'lib' / 'flexlink_ros'
    lib.mkdir(parents=True)
    for executable, module in (('flexlink_node', 'node'), ('crank_driver', 'crank_driver')):
        script = lib / executable
        script.write_text(f'#!/bin/sh\nexec {sys.executable} -m flexlink_ros.ros.{module} "$@"\n')
        script.chmod(0o755)
    return prefix


@pytest.fixture
def ros():
    """Give an rclpy context, a test node and its executor (shut down at the end)."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor

    context = rclpy.Context()
    rclpy.init(context=context)
    node = rclpy.create_node('flexlink_launch_test', context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    try:
        yield node, executor
    finally:
        executor.shutdown()
        node.destroy_node()
        context.try_shutdown()


RUN_LAUNCH = """
import sys
from launch import LaunchService
from launch.actions import IncludeLaunchDescription
from launch.launch_description_sources import PythonLaunchDescriptionSource
service = LaunchService()
arguments = [tuple(item.split(':=', 1)) for item in sys.argv[2:]]
service.include_launch_description(IncludeLaunchDescription(
    PythonLaunchDescriptionSource(sys.argv[1]), launch_arguments=arguments))
sys.exit(service.run())
"""


@pytest.mark.parametrize('name', LAUNCH_FILES)
def test_launch_service_runs_driver_and_node_in_a_namespace(name, tmp_path, ros):
    launch_ros = _require_launch_ros()
    from geometry_msgs.msg import Vector3Stamped
    prefix = _ament_prefix(tmp_path)
    paths = [str(REPO), str(pathlib.Path(launch_ros.__file__).parents[1]), *sys.path]
    env = dict(os.environ, AMENT_PREFIX_PATH=str(prefix), PYTHONPATH=os.pathsep.join(paths),
               PYTHONUNBUFFERED='1')
    log_path = tmp_path / 'launch.log'
    with open(log_path, 'w') as log:
        launch_file = prefix / 'share' / 'flexlink_ros' / 'launch' / name
        process = subprocess.Popen(
            [sys.executable, '-c', RUN_LAUNCH, str(launch_file), 'namespace:=robot7',
             'driver:=true'], env=env, stdout=log, stderr=subprocess.STDOUT,
            start_new_session=True)
    try:
        test_node, executor = ros
        received = []
        test_node.create_subscription(
            Vector3Stamped, '/robot7/flexlink_node/lever_tip/deflection', received.append, 100)
        deadline = time.monotonic() + READY_TIMEOUT_S
        while len(received) < 50:
            assert process.poll() is None, log_path.read_text()
            assert time.monotonic() < deadline, log_path.read_text()
            executor.spin_once(timeout_sec=0.05)
        assert received[-1].header.frame_id == 'linkage_ground'
        if name == 'flexlink_lifecycle.launch.py':
            assert 'flexlink_node is inactive: activating' in log_path.read_text()
    finally:
        if process.poll() is None:
            # Ctrl-C on `ros2 launch`: the terminal signals the whole process group (launch
            # then leaves the signal to the nodes and escalates only if they do not exit).
            os.killpg(process.pid, signal.SIGINT)
            try:
                process.wait(timeout=30)
            except subprocess.TimeoutExpired:
                os.killpg(process.pid, signal.SIGKILL)
                process.wait()
    log = log_path.read_text()
    assert process.returncode == 0, log
    assert 'escalating' not in log and log.count('process has finished cleanly') == 2, log
