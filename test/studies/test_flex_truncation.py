"""Modal truncation of the flexible four-bar (studies/flex_truncation.py)."""

import dataclasses

from flexlink_ros.core.fe.linkage import FlexibleLinkage
from flexlink_ros.core.fe.simulate import periodic_response
from flexlink_ros.core.mechanism_file import load_mechanism
from flexlink_ros.core.numerics import relative_rms, RPM
from flexlink_ros.core.options import ModelOptions
from flexlink_ros.studies import flex_truncation
import numpy as np
import pytest


@pytest.fixture(scope='module')
def small_mechanism():
    return dataclasses.replace(load_mechanism('cho1992'), elements_per_link=2)


def test_relative_rms_and_modes_needed():
    reference = np.column_stack([np.cos(np.linspace(0, 6, 50)), np.sin(np.linspace(0, 6, 50))])
    assert relative_rms(1.1 * reference, reference) == pytest.approx(0.1)
    counts = np.array([1, 2, 3, 4, 6])
    errors = np.array([0.5, 0.008, 0.02, 0.004, 1e-9])
    # N = 2 passes but 3 fails again
    assert flex_truncation.modes_needed(counts, errors, 0.01) == 4
    assert flex_truncation.modes_needed(counts, errors, 0.05) == 2
    assert flex_truncation.modes_needed(counts, errors, 1.0) == 1
    assert flex_truncation.modes_needed(counts, np.full(5, 0.5), 0.01) is None


def test_truncation_error_falls_with_modes_and_vanishes_with_all(small_mechanism):
    model = FlexibleLinkage(small_mechanism, ModelOptions.full_model(rigid_crank=True,
                                                                     geometric_stiffness=False))
    counts = [1, 2, 5, 9, model.size]
    study = flex_truncation.truncation_study(model, 391.0 * RPM, counts, steps=120, points=30)
    plain, static = study['plain'], study['static']
    assert np.all(np.diff(plain, axis=0) <= 1e-3 * plain[:-1])   # non-increasing in N
    assert np.all(plain[-1] < 1e-9) and np.all(static[-1] < 1e-9)
    assert np.all(static[0] < 0.1 * plain[0])   # the static correction pays at N = 1
    assert flex_truncation.modes_needed(study['modes'], static[:, 1], 0.01) == 1
    # the post-processed static correction is the one periodic_response applies
    run = periodic_response(model, 391.0 * RPM, 'modal', modes=2,
                            static_correction=True, steps=120, points=30)
    assert flex_truncation.output_errors(run.outputs, study['reference'].outputs) == pytest.approx(
        static[1], rel=1e-9)
