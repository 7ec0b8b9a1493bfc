"""The Earles-Wu criteria study (studies/criteria_check.py) against Kang 1990's Table 2."""

import math

from flexlink_ros.core import criteria, spring_design
from flexlink_ros.core.mechanism import Spring
from flexlink_ros.core.mechanism_file import load_mechanism
from flexlink_ros.studies import criteria_check
import numpy as np
import pytest


@pytest.fixture(scope='module')
def kang():
    return load_mechanism('kang1990')


def test_paper_cases_swap_only_the_spring(kang):
    class Design:
        stiffness, theta0 = 12.0, 1.5
    cases = criteria_check.paper_cases(kang, Design())
    assert set(cases) == {'original', 'paper', 'design'}
    assert cases['original'].spring is None
    k, deg = spring_design.PAPER_DESIGN
    assert cases['paper'].spring == Spring(k, math.radians(deg))
    assert cases['design'].spring == Spring(12.0, 1.5)
    assert all(c.links == kang.links for c in cases.values())


def test_peak_zoom_of_the_coupler_rocker_joint_finds_table_2_on_the_grid(kang):
    original = criteria_check.paper_cases(kang, Spring(1.0, 0.0))['original']
    peak = criteria.evaluate_criteria(original, kang.crank_speed)['B']
    zoom = criteria_check.peak_zoom(original, peak)
    fine_deg, fine = zoom['fine']
    grid_deg, grid = zoom['grid']
    assert zoom['centre'] == pytest.approx(math.degrees(peak.at_crank_angle))
    assert np.all(np.diff(grid_deg) == 1.0) and np.all(grid_deg == np.round(grid_deg))
    assert fine_deg[0] == pytest.approx(zoom['centre'] - 3.0) and fine.size == 3001
    # Kang 1990, Table 2, joint 2 (B), on the 1-degree grid; the true peak lies between grid
    # points and is higher
    assert grid.max() == pytest.approx(criteria_check.TABLE_2['original'][1], rel=2e-3)
    assert fine.max() > 1.2 * grid.max()
    assert fine.max() == pytest.approx(peak.max_ratio, rel=1e-3)
