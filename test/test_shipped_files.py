"""What `pip install .` ships: the package, never the team's benchmarks or studies."""

import pathlib
import re
import shutil
import subprocess
import sys
import zipfile

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


def test_the_wheel_installs_no_bench_or_study(tmp_path):
    # A copy of what a clone holds (tracked files), built as `pip install .` builds it.
    tracked = subprocess.run(['git', 'ls-files'], cwd=REPO, capture_output=True, text=True,
                             check=True).stdout.split()
    source = tmp_path / 'src'
    for name in tracked:
        if (REPO / name).is_file():
            (source / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(REPO / name, source / name)
    built = subprocess.run(
        [sys.executable, '-m', 'pip', 'wheel', '-q', '--no-deps', '--no-build-isolation',
         '-w', str(tmp_path / 'dist'), str(source)],
        capture_output=True, text=True, timeout=600)
    assert built.returncode == 0, built.stderr
    (wheel,) = (tmp_path / 'dist').glob('flexlink_ros-*.whl')
    names = zipfile.ZipFile(wheel).namelist()
    assert 'flexlink_ros/cli/__init__.py' in names and 'flexlink_ros/studies/bench.py' in names
    assert [n for n in names if LAB_MODULE.search(n)] == []
    assert not [n for n in names if n.startswith(('benchmarks/', 'docs/', 'test/'))]
