"""criteria_rows: the criteria of many rows at once are the per-sample step's, row by row."""

from flexlink_ros.core.estimation.criteria_rows import criteria_batch
from flexlink_ros.core.estimation.step import joint_criteria
from flexlink_ros.core.estimation.streaming import DEFAULT_NEAR_ZERO_FRACTION
from flexlink_ros.core.mechanism_file import load_mechanism
from flexlink_ros.core.reduction import mechanism_model
from flexlink_ros.ros import parameters as node_params
import numpy as np
import pytest


@pytest.fixture(scope='module')
def model():
    options = node_params.default_model_options(geometric_stiffness=False)
    return mechanism_model.model_for_mechanism(load_mechanism('cho1992'), options)


def test_criteria_of_many_rows_are_the_step_criteria_of_each(model):
    rng = np.random.default_rng(2)
    count = 200
    blocks = {'force': rng.normal(scale=300.0, size=(count, 4, 2)),
              'force_dot': rng.normal(scale=3e4, size=(count, 4, 2)),
              'rms2': rng.uniform(1e3, 1e5, size=(count, 4))}
    blocks['force'][:20] *= 1e-3          # near zero: flagged
    blocks['force'][20:25] = 0.0          # zero: clamped to the floor, still finite
    reaction, gamma_dot, criterion, near_zero, available = criteria_batch(
        model, np.zeros(count), np.zeros(count), np.zeros(count), blocks=blocks)
    assert available and np.all(np.isfinite(criterion))
    for n in range(count):
        values = np.concatenate([blocks['force'][n].ravel(), blocks['force_dot'][n].ravel(),
                                 blocks['rms2'][n]]).tolist()
        expected = joint_criteria(values, DEFAULT_NEAR_ZERO_FRACTION)
        np.testing.assert_allclose(reaction[n], expected[0], rtol=1e-14)
        np.testing.assert_allclose(gamma_dot[n], expected[1], rtol=1e-14)
        np.testing.assert_allclose(criterion[n], expected[2], rtol=1e-14)
        assert near_zero[n].tolist() == list(expected[3])
    assert near_zero[:25].all() and not near_zero[25:].any()
