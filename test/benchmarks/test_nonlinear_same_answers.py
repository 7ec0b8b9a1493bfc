"""The nonlinear model's answers against another build's (benchmarks/nonlinear_same_answers.py)."""

import subprocess
import sys

import nonlinear_same_answers
import numpy as np

SCRIPT = nonlinear_same_answers.__file__


def test_a_tree_against_itself_gives_the_same_answers(tmp_path):
    # the script run as a user runs it, this tree as its own reference: zero differences
    out = subprocess.run([sys.executable, SCRIPT, '--reference-root',
                          str(nonlinear_same_answers.ROOT), '--reference-python', sys.executable,
                          '--seconds', '0.2', '--cache-dir', str(tmp_path)],
                         capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr
    lines = out.stdout.strip().splitlines()
    assert len(lines) == len(nonlinear_same_answers.SIGNALS)
    for line in lines:
        assert 'outputs 0.0e+00' in line and 'converged same' in line


def _answers(path, shift=0.0):
    """Save answers for every signal, the outputs moved by ``shift`` of their range."""
    rng = np.random.default_rng(0)
    arrays = {}
    for index in range(len(nonlinear_same_answers.SIGNALS)):
        outputs = rng.normal(size=(50, 4))
        outputs[7, 2] += shift * np.ptp(outputs[:, 2])
        arrays.update({f'{index}_outputs': outputs, f'{index}_axial_force': np.ones((50, 2)),
                       f'{index}_link_slope': np.ones((50, 2)),
                       f'{index}_converged': np.ones(50, dtype=bool)})
    np.savez(path, **arrays)
    return path


def test_an_output_moved_beyond_the_limit_is_a_difference(tmp_path):
    iterations = [{str(k): 1 for k in range(len(nonlinear_same_answers.SIGNALS))}] * 2
    same = [_answers(tmp_path / 'a.npz'), _answers(tmp_path / 'b.npz', 1e-12)]
    moved = [_answers(tmp_path / 'c.npz'), _answers(tmp_path / 'd.npz', 1e-6)]
    assert nonlinear_same_answers.compare(same, iterations, 1e-9)
    assert not nonlinear_same_answers.compare(moved, iterations, 1e-9)
