"""
The linear estimate in two parts (core/estimation/time_split.py): the warm-up and the cut.

A cold start (the static deflection) a warm-up before a row reaches, by that row, the state
of the estimate that ran from the start: the deflections agree to rounding from there on, and
a third of the warm-up is not enough.
"""

import math

from flexlink_ros.core.estimation.follow_spans import WARM_UP_TOLERANCE
from flexlink_ros.core.estimation.gate import DEFAULT_RESET_GAP_S
from flexlink_ros.core.estimation.offline import estimate_offline
from flexlink_ros.core.estimation.tables import step_tables
from flexlink_ros.core.estimation.time_split import linear_decay_rate, linear_warm_up_s, \
    split_row
from flexlink_ros.core.mechanism_file import load_mechanism
from flexlink_ros.core.reduction import mechanism_model
from flexlink_ros.ros import parameters as node_params
from flexlink_ros.studies.synthetic import synthetic_signal
import numpy as np
import pytest


@pytest.fixture(scope='module')
def model():
    """Build (or load) the node's default model."""
    options = node_params.default_model_options()
    return mechanism_model.model_for_mechanism(load_mechanism('cho1992'), options)


def largest_difference_after(model, warm_up_s, after_s=2.0):
    """Estimate from the start and cold from ``warm_up_s`` before a row; their largest gap."""
    stamps, angles, speeds = synthetic_signal(391.0, warm_up_s + after_s + 0.5, 1000.0, 0.3, 5)
    row = int(np.searchsorted(stamps, stamps[-1] - after_s * 1e9))
    cold = int(np.searchsorted(stamps, stamps[row] - warm_up_s * 1e9))
    whole = estimate_offline(model, stamps, angles, speeds)
    part = estimate_offline(model, stamps[cold:], angles[cold:], speeds[cold:],
                            warm_start=False)
    scale = np.ptp(whole['lever_tip'][row:], axis=0)
    return float(np.max(np.abs(part['lever_tip'][row - cold:] - whole['lever_tip'][row:])
                        / scale))


def test_a_cold_start_a_warm_up_earlier_reaches_the_whole_estimate(model):
    tables = step_tables(model)
    rate = linear_decay_rate(model, tables, (0.0, model.speed_max))
    warm_up = linear_warm_up_s(model, tables, DEFAULT_RESET_GAP_S)
    assert warm_up == pytest.approx(max(math.log(1 / WARM_UP_TOLERANCE) / rate,
                                        2 * DEFAULT_RESET_GAP_S))
    assert 1.0 < warm_up < 60.0
    assert largest_difference_after(model, warm_up) <= 5 * WARM_UP_TOLERANCE
    assert largest_difference_after(model, warm_up / 3) > 1e3 * WARM_UP_TOLERANCE


def test_the_cut_balances_the_parts_and_refuses_a_short_recording():
    first = split_row(60_000, 10_000, 0.5)
    assert first == 35_000 and 60_000 - first + 10_000 == first
    assert split_row(60_000, 10_000, 0.47) == 32_900
    assert split_row(20_000, 10_000, 0.5) is None      # the second part would be its warm-up
    assert split_row(0, 10, 0.5) is None
