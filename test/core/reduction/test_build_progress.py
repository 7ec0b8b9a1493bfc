"""Progress of a model build: percentages that rise to 100 and leave the model unchanged."""

import pathlib

from flexlink_ros.core.mechanism_file import load_mechanism
from flexlink_ros.core.options import ModelOptions
from flexlink_ros.core.reduction.build_progress import ASSEMBLED_PERCENT, BASIS_STEP, DAMPING_STEP
from flexlink_ros.core.reduction.mechanism_model import build_model
import numpy as np

CONFIG = pathlib.Path(__file__).resolve().parents[3] / 'config'


def test_build_reports_rising_percentages_and_builds_the_same_model():
    mechanism = load_mechanism(CONFIG / 'cho1992.yaml')
    options = ModelOptions.linear(bearings='rigid', geometric_stiffness=False, grid_size=16,
                                  modes=4, static=2)
    reports = []
    followed = build_model(mechanism, options, lambda *args: reports.append(args))
    plain = build_model(mechanism, options)
    np.testing.assert_array_equal(followed.table, plain.table)
    percents = [percent for percent, _, _ in reports]
    assert all(total == 100 for _, total, _ in reports)
    assert percents[0] == ASSEMBLED_PERCENT and percents[-1] == 100.0
    assert all(b >= a for a, b in zip(percents, percents[1:]))
    steps = [what for _, _, what in reports]
    # One report per basis eigenproblem (16 angles x 3 speeds) and damping matrix (16 x 4),
    # each loop finishing before the next starts; the loops reach 90 % exactly.
    assert steps.count(BASIS_STEP) == 16 * 3 and steps.count(DAMPING_STEP) == 16 * 4
    assert steps.index(DAMPING_STEP) > len(steps) - 1 - steps[::-1].index(BASIS_STEP)
    assert percents[-2] == 90.0
