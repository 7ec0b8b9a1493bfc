"""What `pip install .` ships: what the node and the commands import, never the lab."""

import pathlib
import re
import shutil
import subprocess
import sys

REPO = pathlib.Path(__file__).resolve().parents[1]
LAB_MODULE = re.compile(r'(^|/)[a-z0-9_]+_(bench|study)\.py$')


def test_lab_module_pattern_names_what_it_forbids():
    assert LAB_MODULE.search('flexlink_ros/studies/update_bench.py')
    assert LAB_MODULE.search('damping_study.py')
    assert not LAB_MODULE.search('flexlink_ros/studies/bench.py')
    assert not LAB_MODULE.search('flexlink_ros/studies/benchmarks.py')


def test_the_package_tree_holds_no_bench_or_study_module():
    modules = [str(p.relative_to(REPO)) for p in (REPO / 'flexlink_ros').rglob('*.py')]
    assert len(modules) > 100
    assert [m for m in modules if LAB_MODULE.search(m)] == []


def test_pip_install_installs_no_bench_or_study(tmp_path):
    # A copy of what a clone holds (tracked files), built as `pip install .` builds it.
    tracked = subprocess.run(['git', 'ls-files'], cwd=REPO, capture_output=True, text=True,
                             check=True).stdout.split()
    source = tmp_path / 'src'
    for name in tracked:
        if (REPO / name).is_file():
            (source / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(REPO / name, source / name)
    prefix = tmp_path / 'prefix'
    # The command of `make install` (pip install .), into a throwaway prefix.
    built = subprocess.run(
        [sys.executable, '-m', 'pip', 'install', '-q', '--no-deps', '--ignore-installed',
         '--prefix', str(prefix), str(source)],
        capture_output=True, text=True, timeout=600)
    assert built.returncode == 0, built.stderr
    names = [str(p.relative_to(prefix)) for p in prefix.rglob('*.py')]
    assert any(n.endswith('flexlink_ros/cli/__init__.py') for n in names)
    assert any(n.endswith('flexlink_ros/studies/configurations.py') for n in names)
    assert not any(n.endswith('flexlink_ros/studies/bench.py') for n in names)
    assert [n for n in names if LAB_MODULE.search(n)] == []
    assert not [n for n in names if '/benchmarks/' in n or '/docs/' in n or 'test_' in n]


def entry_modules():
    """Return the modules a user runs: console scripts, CLI commands, report sections."""
    from flexlink_ros.cli import report
    from flexlink_ros.cli.main import COMMAND_MODULES
    scripts = re.findall(r"= (flexlink_ros[\w.]+):\w+'", (REPO / 'setup.py').read_text())
    assert len(scripts) == 3
    return {*scripts, 'flexlink_ros.cli.__main__', *COMMAND_MODULES,
            *(module for _, module, _ in report.SECTIONS)}


def reached_from(starts):
    """Return every package module ``starts`` import, directly or not (and their packages)."""
    from test_layout import imported_modules, PACKAGE

    def path_of(name):
        base = PACKAGE.parent / name.replace('.', '/')
        return base / '__init__.py' if base.is_dir() else base.with_suffix('.py')

    reached, todo = set(), list(starts)
    while todo:
        name = todo.pop()
        while name.startswith('flexlink_ros') and not path_of(name).exists():
            name = name.rpartition('.')[0]      # `from module import function`
        if not name.startswith('flexlink_ros') or name in reached:
            continue
        reached.add(name)
        parts = name.split('.')
        todo += ['.'.join(parts[:k]) for k in range(1, len(parts))]
        todo += [imported for imported, _, _ in imported_modules(path_of(name))]
    return reached


def test_every_module_of_the_package_is_reached_from_what_a_user_runs():
    from test_layout import module_name, modules
    shipped = {module_name(path) for path in modules()}
    reached = reached_from(entry_modules())
    assert len(shipped) > 100
    assert sorted(shipped - reached) == []      # a module only the lab imports lives beside it


def test_the_reach_sees_a_module_nothing_imports():
    reached = reached_from(['flexlink_ros.ros.crank_driver'])
    assert 'flexlink_ros.ros.crank_driver' in reached and 'flexlink_ros.ros' in reached
    assert 'flexlink_ros.cli.fleet' not in reached
