"""Kang 1990 spring design: exact affine spring decomposition, fast vs true maxima, search."""

import dataclasses
import math

from flexlink_ros.core.criteria import evaluate_criteria
from flexlink_ros.core.dynamics import solve_dynamics
from flexlink_ros.core.kinematics import solve_kinematics
from flexlink_ros.core.mechanism import Spring
from flexlink_ros.core.mechanism_file import load_mechanism
from flexlink_ros.core.spring_design import (design_spring, FORCE_FACTOR, PAPER_DESIGN,
                                             SpringProblem, TORQUE_FACTOR)
import numpy as np
import pytest


@pytest.fixture(scope='module')
def kang():
    return load_mechanism('kang1990')


@pytest.fixture(scope='module')
def problem(kang):
    return SpringProblem(kang, scan_points=720)


def test_spring_superposition_equals_direct_solution(kang, problem):
    # F0 + T_s G (and its rate, and the torque) equal the Newton-Euler solution with the
    # spring in the mechanism.
    theta = np.radians(np.arange(0.0, 360.0, 17.0))
    stiffness, theta0 = 13.0, math.radians(333.0)
    force, force_rate, torque = problem._combine(problem.tables(theta), stiffness, theta0)
    mech = dataclasses.replace(kang, spring=Spring(stiffness=stiffness, theta0=theta0))
    direct = solve_dynamics(mech, solve_kinematics(mech, theta, kang.crank_speed))
    np.testing.assert_allclose(force, direct.force, atol=1e-9 * np.abs(direct.force).max())
    np.testing.assert_allclose(force_rate, direct.force_rate,
                               atol=1e-9 * np.abs(direct.force_rate).max())
    np.testing.assert_allclose(torque, direct.input_torque, atol=1e-10)


def test_paper_design_true_objective_and_its_limits(kang, problem):
    # The paper's design evaluated with true maxima: the objective agrees with
    # core.criteria on the spring mechanism, and the torque limit (Eq. 16) is where the
    # paper's search stopped.
    paper = problem.evaluate(PAPER_DESIGN[0], math.radians(PAPER_DESIGN[1]), scan_points=1800)
    mech = dataclasses.replace(kang, spring=Spring(20.0, math.radians(279.14)))
    direct = evaluate_criteria(mech, scan_points=1800)
    assert paper.objective == pytest.approx(sum(direct[j].max_ratio for j in ('A', 'B', 'O4')),
                                            rel=1e-9)
    assert paper.objective == pytest.approx(60.30, abs=0.01)
    torque = paper.constraints['torque_max']
    assert torque['limit'] == pytest.approx(TORQUE_FACTOR * problem.reference['torque_max'])
    assert abs(torque['margin']) < 1e-4 and 'torque_max' in paper.active
    force = paper.constraints['force_O4']
    assert force['limit'] == pytest.approx(FORCE_FACTOR * problem.reference['force']['O4'])
    # the fast search evaluation is within 0.5 % of the true one
    fast, _ = problem.fast(PAPER_DESIGN)
    assert fast == pytest.approx(paper.objective, rel=5e-3)


def test_reduced_search_finds_a_feasible_design_better_than_the_paper(kang):
    found = design_spring(kang, maxiter=15, popsize=8, scan_points=720)
    design, paper = found['design'], found['paper']
    assert design.feasible
    assert all(c['margin'] >= -1e-6 for c in design.constraints.values())
    assert 0.0 <= design.stiffness <= 20.0 and 0.0 <= math.degrees(design.theta0) <= 360.0
    assert design.objective < 0.9 * paper.objective
    # the reported objective is the sum of the reported true maxima
    assert design.objective == pytest.approx(sum(design.max_ratio[j] for j in ('A', 'B', 'O4')))


def test_bad_arguments(kang):
    with pytest.raises(ValueError, match='theta0_bounds_deg'):
        design_spring(kang, theta0_bounds_deg=(10.0, 5.0))
    with pytest.raises(ValueError, match='crank_speed'):
        SpringProblem(dataclasses.replace(kang, crank_speed=None))
