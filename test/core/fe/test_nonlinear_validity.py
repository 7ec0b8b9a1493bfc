"""
What the nonlinear model cannot carry (core/fe/nonlinear_validity.py).

The rotation indicator follows the strain's own truncation: an element of the real model
turned rigidly by phi strains -phi^4/8 (element_strain), and the indicator grows as phi^4 and
reads 1 at ROTATION_LIMIT. The fold indicator reads 1 at FOLD_MARGIN from +1 and flags a
multiplier on or outside the unit circle.
"""

import dataclasses

from flexlink_ros.core.fe import nonlinear_strain as ns
from flexlink_ros.core.fe import nonlinear_validity as nv
from flexlink_ros.core.fe.linkage import FlexibleLinkage
from flexlink_ros.core.mechanism_file import load_mechanism
from flexlink_ros.core.options import ModelOptions
import numpy as np
import pytest


@pytest.fixture(scope='module')
def elements():
    mech = dataclasses.replace(load_mechanism('cho1992'), elements_per_link=3)
    return ns.model_elements(FlexibleLinkage(mech, ModelOptions.full_model(rigid_crank=False)))


def _rigidly_turned(elements, phi):
    """Element coordinates of every element turned rigidly by phi about its first node."""
    le = elements.length
    q = np.zeros((len(elements), 6))
    q[:, 2] = q[:, 5] = phi
    q[:, 3] = le * (np.cos(phi) - 1.0)
    q[:, 4] = le * np.sin(phi)
    return q


@pytest.mark.parametrize('phi', [0.02, -0.1, 0.3])
def test_rotation_of_a_rigidly_turned_element_is_its_angle(elements, phi):
    rotations = nv.element_rotations(_rigidly_turned(elements, phi), elements.length)
    np.testing.assert_allclose(rotations, abs(phi), rtol=1e-12)


def test_bent_element_counts_its_largest_slope(elements):
    q = np.zeros((len(elements), 6))
    q[:, 2], q[:, 5] = 0.01, -0.04                 # antisymmetric bending, chord stays put
    np.testing.assert_allclose(nv.element_rotations(q, elements.length), 0.04)


def test_rotation_indicator_tracks_the_strain_truncation(elements):
    """The invented strain -phi^4/8 of the real element law scales as the indicator."""
    small, large = 0.05, 0.1
    strains = [ns.element_strain(elements, _rigidly_turned(elements, phi)).max()
               for phi in (small, large)]
    np.testing.assert_allclose(strains[1], -large ** 4 / 8, rtol=0.02)
    ratio = nv.rotation_indicator(large) / nv.rotation_indicator(small)
    np.testing.assert_allclose(strains[1] / strains[0], ratio, rtol=0.02)
    assert nv.rotation_indicator(nv.ROTATION_LIMIT) == pytest.approx(1.0)


def test_fold_indicator_is_one_at_the_margin_and_flags_unstable_orbits():
    assert nv.fold_indicator([0.2, 1.0 - nv.FOLD_MARGIN]) == pytest.approx(1.0)
    assert nv.fold_indicator([0.6 + 0.3j, 0.6 - 0.3j]) < 0.5
    assert nv.fold_distance([0.999]) == pytest.approx(1e-3)
    assert nv.fold_indicator([1.02, 0.1]) == float('inf')
    assert nv.fold_distance([]) == float('inf')


def test_validity_combines_and_says_why(elements):
    rotations = nv.element_rotations(_rigidly_turned(elements, 0.05), elements.length)
    fine = nv.nonlinear_validity(rotations, [0.65, -0.3])
    assert fine.valid and fine.reason == '' and fine.max_rotation == pytest.approx(0.05)
    folding = nv.nonlinear_validity(rotations, [0.97])
    assert not folding.valid and 'Floquet' in folding.reason
    turned = nv.nonlinear_validity(np.array([0.05, 0.12]))
    assert not turned.valid and 'rotation' in turned.reason and turned.fold == 0.0
    assert nv.nonlinear_validity().valid


def test_chord_frame_sees_bending_not_a_rigid_turn(elements):
    """Against the chord a rigid turn is no rotation; bending against it counts as it is."""
    turned = _rigidly_turned(elements, 0.3)
    np.testing.assert_allclose(nv.element_rotations(turned, elements.length, 'chord'), 0.0,
                               atol=1e-14)
    turned[:, 2] += 0.05                           # the first node bent 0.05 rad further
    np.testing.assert_allclose(nv.element_rotations(turned, elements.length, 'chord'), 0.05,
                               rtol=1e-9)
    judged = nv.nonlinear_validity([0.2], [0.5], frame='chord')
    assert not judged.valid and 'chord' in judged.reason
    with pytest.raises(ValueError, match='frame'):
        nv.element_rotations(turned, elements.length, 'world')
