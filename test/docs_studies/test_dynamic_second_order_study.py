"""The dynamic-pass study (docs/studies/dynamic_second_order_study.py) at a reduced size."""

import shutil

import dynamic_second_order_study as study
from flexlink_ros.core.mechanism_file import load_mechanism
import numpy as np
import pytest


@pytest.fixture(scope='module')
def mech():
    return load_mechanism('cho1992')


def test_accuracy_shows_the_pass_needs_the_larger_basis(mech):
    result = study.accuracy(mech, 391.0, 4, [(4, 2), (6, 4)], revolutions=8)
    small, large = result['bases']
    assert (small['r'], large['r']) == (6, 10)
    # the quasi-static estimate is the full order's to 0.1 % on either basis ...
    for entry in (small, large):
        np.testing.assert_allclose(entry['quasi_static'], result['full_order']['quasi_static'],
                                   atol=1e-3)
    # ... 3 % off the pass on the coupler; the streamed pass is within 2 % on the larger
    # basis, not on the default one (measured +3.7 / +5.6 %)
    assert min(np.abs(result['full_order']['quasi_static'][2:])) > 0.025
    assert max(np.abs(large['dynamic'])) < 0.02
    assert max(np.abs(small['dynamic'][2:])) > 0.03
    text = study.format_result({'accuracy': result})
    assert 'r=10 streamed dynamic' in text


def test_cost_times_every_step(mech):
    compiler = shutil.which('cc') or shutil.which('gcc')
    entries = study.cost(mech, 391.0, 4, [(4, 2)], rounds=1, samples=20,
                         kernel_samples=50 if compiler else 0)
    assert entries[0]['r'] == 6
    names = ['numpy', 'numpy_dynamic', 'compiled']
    if compiler:
        names += ['kernel', 'kernel_tabulated']
    assert all(entries[0][name] > 0.0 for name in names)
    assert 'the pass compiled' in study.format_result(
        {'accuracy': {'rpm': 391.0, 'elements': 4, 'full_order': {'quasi_static': [0.0] * 4},
                      'bases': []}, 'cost': entries}) or not compiler
