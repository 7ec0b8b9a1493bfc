"""Packaging: a colcon build resolves like `ros2 run`; `pip install .` installs share/."""

import os
import pathlib
import shutil
import subprocess
import sys
import sysconfig

import pytest

REPO = pathlib.Path(__file__).resolve().parents[1]
VENV_BIN = pathlib.Path(sys.executable).parent
EXECUTABLES = ('flexlink', 'crank_driver')
SOURCES = ('package.xml', 'setup.py', 'setup.cfg', 'resource', 'config', 'launch',
           'flexlink_ros')
LAUNCH_FILES = {'flexlink.launch.py', 'flexlink_lifecycle.launch.py'}


def copy_source(destination):
    """Copy the package sources (what a clone holds) without caches to ``destination``."""
    destination.mkdir(parents=True)
    for name in SOURCES:
        source = REPO / name
        if source.is_dir():
            shutil.copytree(source, destination / name,
                            ignore=shutil.ignore_patterns('__pycache__', '*.pyc', '.*'))
        else:
            shutil.copy2(source, destination / name)


def clean_env(**extra):
    env = {k: v for k, v in os.environ.items()
           if k not in ('AMENT_PREFIX_PATH', 'PYTHONPATH', 'COLCON_PREFIX_PATH')}
    env['PATH'] = f'{VENV_BIN}{os.pathsep}{env.get("PATH", "")}'
    env.update(extra)
    return env


RESOLVE = """
import os, subprocess, sys
from ament_index_python.packages import get_package_prefix, get_package_share_directory
prefix = get_package_prefix('flexlink_ros')
share = get_package_share_directory('flexlink_ros')
print(prefix)
print(share)
for exe in sys.argv[1:]:
    path = os.path.join(prefix, 'lib', 'flexlink_ros', exe)
    result = subprocess.run([path, '--help'], capture_output=True, text=True)
    print(exe, result.returncode, result.stdout.splitlines()[0] if result.stdout else '')
"""


def test_colcon_build_resolves_like_ros2_run(tmp_path):
    workspace = tmp_path / 'ws'
    copy_source(workspace / 'src' / 'flexlink_ros')
    build = subprocess.run(
        ['colcon', '--log-base', str(workspace / 'log'), 'build', '--base-paths',
         str(workspace / 'src'), '--build-base', str(workspace / 'build'), '--install-base',
         str(workspace / 'install')],
        cwd=workspace, env=clean_env(), capture_output=True, text=True, timeout=120)
    assert build.returncode == 0, build.stdout + build.stderr
    install = workspace / 'install' / 'flexlink_ros'
    site = install / pathlib.Path(sysconfig.get_path('purelib')).relative_to(sys.prefix)
    # What `. install/setup.bash` exports for this package, then what `ros2 run` does.
    env = clean_env(AMENT_PREFIX_PATH=str(install), PYTHONPATH=str(site))
    result = subprocess.run([sys.executable, '-c', RESOLVE, *EXECUTABLES], cwd=tmp_path,
                            env=env, capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    lines = result.stdout.splitlines()
    assert pathlib.Path(lines[0]) == install
    share = pathlib.Path(lines[1])
    assert (share / 'package.xml').is_file()
    shipped = {p.name for p in (REPO / 'config').glob('*.yaml')}
    assert shipped and {p.name for p in (share / 'config').glob('*.yaml')} == shipped
    assert {p.name for p in (share / 'launch').glob('*.py')} == LAUNCH_FILES
    for exe, line in zip(EXECUTABLES, lines[2:]):
        name, code, usage = line.split(' ', 2)
        assert (name, code) == (exe, '0') and usage.startswith('usage:')
    # The installed modules are the ones imported, not the repository's.
    where = subprocess.run(
        [sys.executable, '-c', 'import flexlink_ros; print(flexlink_ros.__file__)'],
        cwd=tmp_path, env=env, capture_output=True, text=True)
    assert pathlib.Path(where.stdout.strip()).is_relative_to(install)


def test_pip_install_puts_scripts_and_share_files_in_the_prefix(tmp_path):
    source = tmp_path / 'src'
    copy_source(source)
    prefix = tmp_path / 'prefix'
    # The command of `make install` (pip install . into the venv), into a throwaway prefix.
    # --ignore-installed: otherwise pip uninstalls the venv's own flexlink_ros first.
    result = subprocess.run(
        [sys.executable, '-m', 'pip', 'install', '-q', '--no-deps', '--ignore-installed',
         '--prefix', str(prefix), str(source)],
        env=clean_env(), capture_output=True, text=True, timeout=180)
    assert result.returncode == 0, result.stderr
    for exe in EXECUTABLES:
        assert (prefix / 'bin' / exe).is_file()
    share = prefix / 'share' / 'flexlink_ros'
    assert (share / 'package.xml').is_file()
    assert (share / 'config' / 'crank_driver.yaml').is_file()
    assert {p.name for p in (share / 'launch').glob('*.py')} == LAUNCH_FILES
    assert (prefix / 'share' / 'ament_index' / 'resource_index' / 'packages' /
            'flexlink_ros').is_file()
    site = prefix / pathlib.Path(sysconfig.get_path('purelib')).relative_to(sys.prefix)
    env = clean_env(PYTHONPATH=str(site), AMENT_PREFIX_PATH=str(prefix))
    for exe in EXECUTABLES:
        run = subprocess.run([str(prefix / 'bin' / exe), '--help'], cwd=tmp_path, env=env,
                             capture_output=True, text=True, timeout=60)
        assert run.returncode == 0 and run.stdout.startswith('usage:'), run.stderr


@pytest.mark.skipif(not (VENV_BIN / 'crank_driver').exists(),
                    reason='`make install` has not been run in this venv')
def test_make_install_exposes_the_scripts_in_the_venv(tmp_path):
    for exe in EXECUTABLES:
        assert (VENV_BIN / exe).is_file()
    assert (pathlib.Path(sys.prefix) / 'share' / 'flexlink_ros' / 'config' /
            'crank_driver.yaml').is_file()
    # A bare mechanism name resolves from the venv's share/ without a sourced workspace.
    run = subprocess.run([str(VENV_BIN / 'flexlink'), 'modes', '--mechanism', 'cho1992',
                          '--crank-deg', '0:10:10', '--count', '1', '--no-geometric-stiffness',
                          '--json'], cwd=tmp_path, env=clean_env(), capture_output=True,
                         text=True, timeout=120)
    assert run.returncode == 0, run.stderr
