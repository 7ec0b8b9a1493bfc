"""DOF layout of the FE model (core/fe/dofs.py): joint mass shares and the gathers of Eq. 25."""

import pathlib

from flexlink_ros.core.fe.linkage import FlexibleLinkage
from flexlink_ros.core.mechanism_file import load_mechanism
from flexlink_ros.core.options import ModelOptions
import numpy as np
import pytest

CONFIG = pathlib.Path(__file__).resolve().parents[3] / 'config'

NO_KG = {'geometric_stiffness': False}


@pytest.fixture(scope='module')
def cho():
    return load_mechanism(CONFIG / 'cho1992.yaml')


def test_joint_masses_are_conserved_and_split(cho):
    pins = FlexibleLinkage(cho, ModelOptions.full_model(**NO_KG))
    springs = FlexibleLinkage(cho, ModelOptions.full_model(bearings='flexible', **NO_KG))
    total = sum(cho.joint_masses.values())
    assert sum(sum(pins.end_masses(link)) for link in pins.links) == pytest.approx(total)
    # flexible bearings: the ground's shares at O2 and O4 stay on the ground
    grounded = (cho.joint_mass_split * cho.joint_masses['O2']
                + (1 - cho.joint_mass_split) * cho.joint_masses['O4'])
    assert sum(sum(springs.end_masses(link)) for link in springs.links) == pytest.approx(
        total - grounded)
    assert springs.end_masses(1)[1] == pytest.approx(cho.joint_mass_split * cho.joint_masses['B'])
    assert springs.end_masses(2)[1] == pytest.approx(
        (1 - cho.joint_mass_split) * cho.joint_masses['B'])


def test_gather_derivatives_match_finite_differences(cho):
    model = FlexibleLinkage(cho, ModelOptions.full_model(bearings='flexible', **NO_KG))
    angle, h = np.array([0.7]), 1e-5
    for link in model.links:
        t = [model.gather(link, angle + k * h) for k in (-1, 0, 1)]
        np.testing.assert_allclose(model.gather(link, angle, 1), (t[2] - t[0]) / (2 * h),
                                   atol=1e-9)
        np.testing.assert_allclose(model.gather(link, angle, 2),
                                   (t[2] - 2 * t[1] + t[0]) / h ** 2, atol=1e-5)
