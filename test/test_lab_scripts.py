"""
The benchmarks and the docs' studies run as scripts from the repository root, at a tiny size.

They print figures (never assert times); the test only checks that each still runs as
``python benchmarks/<name>.py`` or ``python docs/studies/<name>.py`` and prints what it measured.
"""

import os
import pathlib
import shutil
import subprocess
import sys

import pytest

REPO = pathlib.Path(__file__).resolve().parents[1]
# Each script with the smallest arguments that still run its whole main.
TINY_RUNS = {
    'benchmarks/update_bench.py': ['--rounds', '2', '--samples', '300'],
    'benchmarks/second_order_bench.py': ['--rounds', '2', '--samples', '300'],
    'benchmarks/estimator_bench.py': ['--only-default', '--speeds', '269', '--seconds', '0.2',
                                      '--grid-size', '32', '--modes', '4', '--no-chart',
                                      '--no-nonlinear'],
    'docs/studies/soft_basis_study.py': ['--no-ramp', '--no-paper'],
    'docs/studies/validity_study.py': ['--rpm', '150', '--elements', '2', '--json'],
    'docs/studies/damping_study.py': ['--elements', '2', '--steps', '120'],
    'docs/studies/second_order_study.py': ['--rpm', '269', '--gravity', 'off', '--elements',
                                           '2', '--json'],
    'docs/studies/dynamic_second_order_study.py': ['--elements', '2', '--sizes', '4,2',
                                                   '--json'],
    'docs/studies/dynamic_second_order_peer.py': ['--rpm', '269', '--elements', '2', '--json'],
}
NEEDS_CC = {'benchmarks/second_order_bench.py'}


def run_script(script, arguments):
    """Run ``script`` from the repository root as a user would; return the finished process."""
    env = dict(os.environ, OPENBLAS_NUM_THREADS='1', MPLBACKEND='Agg')
    return subprocess.run([sys.executable, script, *arguments], cwd=REPO, env=env,
                          capture_output=True, text=True, timeout=900)


@pytest.mark.parametrize('script', sorted(TINY_RUNS))
def test_the_script_runs_at_a_tiny_size_and_prints_figures(script):
    if script in NEEDS_CC and shutil.which('cc') is None:
        pytest.skip('no C compiler: the compiled kernel is not built')
    run = run_script(script, TINY_RUNS[script])
    assert run.returncode == 0, run.stderr[-3000:]
    assert any(ch.isdigit() for ch in run.stdout), run.stdout


def test_every_moved_lab_script_is_run_here():
    # dynamic_second_order_bench has no main: the dynamic study imports and runs it.
    moved = {'benchmarks/update_bench.py', 'benchmarks/second_order_bench.py',
             'benchmarks/estimator_bench.py',
             'docs/studies/damping_study.py', 'docs/studies/validity_study.py',
             'docs/studies/second_order_study.py', 'docs/studies/dynamic_second_order_study.py',
             'docs/studies/dynamic_second_order_peer.py', 'docs/studies/soft_basis_study.py'}
    assert set(TINY_RUNS) == moved
    assert all((REPO / script).is_file() for script in moved)
