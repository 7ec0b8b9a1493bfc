"""Full-order reference of the reduced model."""

import pathlib

from flexlink_ros.core.mechanism_file import load_mechanism
from flexlink_ros.core.options import ModelOptions
from flexlink_ros.core.reduction.reference import reference_response, unreduced_revolution
import numpy as np
import pytest

CONFIG = pathlib.Path(__file__).resolve().parents[3] / 'config'


@pytest.mark.parametrize('bearings', ['rigid', 'flexible'])
def test_unreduced_tables_agree_with_core_simulate(bearings):
    # Two independent full-order solutions: core/fe/simulate.py (assembly at every stage) and
    # the reduced model's tables with every DOF kept.
    mechanism = load_mechanism(CONFIG / 'cho1992.yaml')
    options = ModelOptions.linear(bearings=bearings, geometric_stiffness=False)
    speed = 391 * np.pi / 30
    outputs, source = unreduced_revolution(mechanism, options, speed)
    nodes = np.linspace(0.0, 2 * np.pi, outputs.shape[0], endpoint=False)
    tables = {'source': source, 'lever_tip': outputs[:, :2], 'coupler_mid': outputs[:, 2:]}
    simulated = reference_response(mechanism, options, speed, nodes)
    assert simulated['source'].startswith('core.simulate')
    assert tables['source'].startswith('unreduced')
    for key in ('lever_tip', 'coupler_mid'):
        error = np.sqrt(np.sum((tables[key] - simulated[key]) ** 2)
                        / np.sum(simulated[key] ** 2))
        assert error < 2e-4, (key, error)
