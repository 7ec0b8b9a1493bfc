"""What `pip install .` ships: the package, never the team's benchmarks or studies."""

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
