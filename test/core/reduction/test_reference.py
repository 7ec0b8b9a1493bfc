"""Full-order reference of the reduced model."""

import dataclasses
import pathlib

from flexlink_ros.core.mechanism_file import load_mechanism
from flexlink_ros.core.options import ModelOptions
from flexlink_ros.core.reduction.build import reduce_samples
from flexlink_ros.core.reduction.mechanism_model import frozen_samples_for
from flexlink_ros.core.reduction.model import output_values
from flexlink_ros.core.reduction.periodic import periodic_response
from flexlink_ros.core.reduction.reference import REFERENCE_GRID, REFERENCE_POINT_STRIDE, \
    reference_response, REFERENCE_STEPS
import numpy as np
import pytest

CONFIG = pathlib.Path(__file__).resolve().parents[3] / 'config'


def unreduced_revolution(mechanism, options, speed, steps=REFERENCE_STEPS):
    """
    Return the outputs (points, 4) over one revolution of the unreduced tables, and their source.

    The tables of :func:`reduce_samples` with every DOF kept, integrated as the reduced model
    is: a check of the tables and the integrator against core.fe.simulate's full order.
    """
    full_options = dataclasses.replace(options, grid_size=REFERENCE_GRID, modes=1, static=0)
    samples = frozen_samples_for(mechanism, full_options)
    model = reduce_samples(samples, samples.dofs, 0, max(abs(speed), options.speed_max),
                           mechanism.damping_ratio)
    grid, q, _ = periodic_response(model, speed, start_angle=0.0, steps=steps)
    outputs = output_values(model, model.evaluate(grid, speed, 0.0), q)[:-1]
    return outputs[::REFERENCE_POINT_STRIDE], 'unreduced tables'


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
