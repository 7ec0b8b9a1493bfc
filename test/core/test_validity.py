"""
Validity indicator (flexlink_ros/core/validity.py): independent checks.

* the Euler load pi^2 E I / L^2 against the FE buckling eigenvalue of a pinned-pinned link
  (K u = P G u with the unit geometric stiffness);
* the elastic axial force N_e (FE element force minus the Newton-Euler rigid-body axial force):
  zero for a static gravity load (the FE and the rigid-body analysis carry the same force),
  small against the rigid-body force far below resonance, and a few N in the lever-mode
  resonance band;
* the indicator below the threshold at 269 rpm and above it at 405 rpm (rigid bearings, rigid
  crank, 4 elements per link: the requirement at reduced size).
"""

import dataclasses
import inspect
import math

from flexlink_ros.core import validity
from flexlink_ros.core.fe import linkage as assembly
from flexlink_ros.core.fe import second_order_geometry
from flexlink_ros.core.fe.simulate import periodic_response
from flexlink_ros.core.mechanism_file import load_mechanism
from flexlink_ros.core.options import ModelOptions
from flexlink_ros.studies import peer_exudyn as peer
import numpy as np
import pytest
import scipy.linalg

ELEMENTS = 4


@pytest.fixture(scope='module')
def mech():
    return load_mechanism('cho1992')


@pytest.fixture(scope='module')
def linkage(mech):
    return peer.linear_model(mech, elements_per_link=ELEMENTS, gravity=False)


@pytest.fixture(scope='module')
def responses(linkage):
    """Linear full-order periodic responses at 269 and 405 rpm (no gravity)."""
    return {rpm: periodic_response(linkage, rpm * math.pi / 30.0, method='full', points=60)
            for rpm in (269.0, 405.0)}


def test_buckling_load_closed_form(mech):
    loads = validity.buckling_loads(mech)
    E = mech.youngs_modulus
    for link, spec in ((1, mech.links[1]), (2, mech.links[2])):
        assert loads[link] == pytest.approx(math.pi ** 2 * E * spec.second_moment
                                            / spec.length ** 2, rel=1e-12)
    assert loads[1] == pytest.approx(36.3, abs=0.1)       # the measured "36 N"
    assert loads[2] == pytest.approx(43.3, abs=0.1)


@pytest.mark.parametrize('link', [1, 2])
def test_buckling_load_against_fe_eigenvalue(mech, link):
    """Lowest P of K u = P G u, pinned-pinned (v = 0 at both ends, u = 0 at the first)."""
    spec, elements = mech.links[link], 12
    mats = assembly.link_matrices(mech.youngs_modulus, spec.area, spec.second_moment,
                                  mech.density, spec.length, elements)
    gmat = second_order_geometry.unit_geometric_stiffness(mats.element_length, elements)
    free = np.setdiff1d(np.arange(3 * (elements + 1)), [0, 1, 3 * elements + 1])
    # G is singular (no axial terms): the largest 1/P of G u = (1/P) K u, K positive definite
    inverse = scipy.linalg.eigh(gmat[np.ix_(free, free)], mats.stiffness[np.ix_(free, free)],
                                eigvals_only=True)
    expected = validity.buckling_loads(mech, [link])[link]
    assert 1.0 / inverse.max() == pytest.approx(expected, rel=1e-4)


@pytest.mark.parametrize('tension', [-5.0, 9.0])
def test_frequency_shift_of_axial_force(mech, tension):
    """Eq. 2: a uniform N shifts the first pinned-pinned mode by omega^2 (1 + N / P_cr)."""
    spec, elements = mech.links[2], 12
    mats = assembly.link_matrices(mech.youngs_modulus, spec.area, spec.second_moment,
                                  mech.density, spec.length, elements)
    gmat = second_order_geometry.unit_geometric_stiffness(mats.element_length, elements)
    free = np.setdiff1d(np.arange(3 * (elements + 1)), [0, 1, 3 * elements + 1])
    sub = np.ix_(free, free)
    first = lambda k: scipy.linalg.eigh(k[sub], mats.mass[sub], eigvals_only=True)[0]  # noqa
    ratio = first(mats.stiffness + tension * gmat) / first(mats.stiffness)
    assert ratio == pytest.approx(1.0 + tension / validity.buckling_loads(mech, [2])[2],
                                  rel=1e-3)


def test_elastic_axial_force_static_gravity_is_zero(mech):
    """At rest under gravity the FE element forces equal the Newton-Euler axial forces."""
    model = peer.linear_model(mech, elements_per_link=ELEMENTS, gravity=True)
    theta = np.linspace(0.0, 2.0 * np.pi, 5, endpoint=False)
    system = model.assemble(theta)
    u = np.linalg.solve(system.frozen_stiffness(0.0), system.load_at(0.0)[..., None])[..., 0]
    rigid = validity.rigid_element_axial_forces(model, theta, 0.0)
    elastic = validity.elastic_axial_forces(model, u, theta, 0.0)
    for link in (1, 2):
        assert np.abs(rigid[link]).max() > 0.05                  # gravity loads the links
        assert np.abs(elastic[link]).max() < 1e-3 * np.abs(rigid[link]).max()


def test_elastic_axial_force_dynamic(linkage, responses):
    """Far from resonance N_e is a few % of the rigid-body force; at 405 rpm it is 1-9 N."""
    for rpm, expected in ((269.0, (0.05, 0.6)), (405.0, (1.0, 9.0))):
        response = responses[rpm]
        speed = rpm * math.pi / 30.0
        total = linkage.element_axial_forces(response.displacement, response.crank_angle)
        rigid = validity.rigid_element_axial_forces(linkage, response.crank_angle, speed)
        elastic = validity.elastic_axial_forces(linkage, response.displacement,
                                                response.crank_angle, speed)
        for link in (1, 2):
            np.testing.assert_allclose(elastic[link], total[link] - rigid[link], atol=1e-12)
            assert expected[0] < np.abs(elastic[link]).max() < expected[1]
        if rpm == 269.0:
            assert np.abs(elastic[1]).max() < 0.05 * np.abs(rigid[1]).max()


def test_indicator_flags_the_resonance_band(linkage, responses):
    flags = {}
    for rpm, response in responses.items():
        indicator = validity.nonlinearity_indicator(
            linkage, response.displacement, response.crank_angle, rpm * math.pi / 30.0)
        assert indicator.shape == response.crank_angle.shape
        assert np.all(indicator >= 0.0)
        flags[rpm] = validity.is_valid(indicator)
    assert flags[269.0]['valid'] is True
    assert flags[405.0]['valid'] is False
    assert flags[269.0]['indicator_max'] < 0.5 * validity.VALIDITY_THRESHOLD
    assert flags[405.0]['indicator_max'] > 1.5 * validity.VALIDITY_THRESHOLD


def test_mode_reference_and_distance(linkage):
    """The two reference modes are the coupler's and the lever's first bending modes."""
    speed = 405.0 * math.pi / 30.0
    ref = validity.mode_reference(linkage, speed)
    hz = ref['omega'] / (2.0 * math.pi)
    assert hz == pytest.approx([34.1, 41.7], abs=0.6)
    assert ref['share'][0, 1] > 0.9 and ref['share'][1, 2] > 0.9
    # nearest harmonic of 6.75 Hz: 5 (33.75 Hz) and 6 (40.5 Hz)
    distance = validity.resonance_distance(ref, 0.02)
    expected = np.hypot(ref['omega'] - np.array([5.0, 6.0]) * speed, 0.02 * ref['omega'])
    np.testing.assert_allclose(distance, expected, rtol=1e-12)


def test_candidate_load_ratio(linkage, responses):
    """Max |N_e| / P_cr: 0.5-1 % at 269 rpm, about 6 % at 405 rpm (measured: 2-9 N / 36 N)."""
    values = {rpm: validity.load_ratio_indicator(linkage, r.displacement, r.crank_angle,
                                                 rpm * math.pi / 30.0).max()
              for rpm, r in responses.items()}
    assert 0.003 < values[269.0] < 0.012
    assert 0.04 < values[405.0] < 0.09


def test_is_valid_summary():
    assert inspect.signature(validity.is_valid).parameters['threshold'].default \
        is validity.VALIDITY_THRESHOLD
    assert validity.is_valid(np.array([0.0, 0.01])) == {'indicator_max': 0.01, 'valid': True,
                                                        'threshold': validity.VALIDITY_THRESHOLD}
    assert validity.is_valid(np.array([1.0]))['valid'] is False
    assert validity.is_valid(np.array([]))['valid'] is None
    assert validity.is_valid(np.array([math.nan, 0.7]))['valid'] is False


def test_rigid_crank_only_flexible_links(mech):
    """The crank is not an indicator link; a model with a flexible crank still works."""
    model = assembly.FlexibleLinkage(dataclasses.replace(mech, elements_per_link=2),
                                     ModelOptions.full_model(gravity=False))
    theta = np.array([0.0, 1.0])
    u = np.zeros((2, model.size))
    ratios = validity.load_ratios(model, u, theta, 10.0)
    assert sorted(ratios) == [1, 2]
    # zero elastic state: N_e is minus the rigid-body force, a finite number
    assert all(np.all(np.isfinite(v)) for v in ratios.values())
