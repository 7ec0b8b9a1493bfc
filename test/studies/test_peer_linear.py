"""The package's linear model in the peer's conventions (studies/peer_linear.py)."""

import dataclasses
import math

from flexlink_ros.core.mechanism_file import load_mechanism
from flexlink_ros.studies import peer_linear
from flexlink_ros.studies.peer_model import OUTPUT_KEYS
import numpy as np
import pytest

ELEMENTS = 2


@pytest.fixture(scope='module')
def mech():
    return load_mechanism('cho1992')


def test_linear_model_takes_the_peers_settings(mech):
    model = peer_linear.linear_model(mech, elements_per_link=ELEMENTS, bearings='springs',
                                     gravity=False)
    assert model.options.rigid_crank and model.options.bearings == 'flexible'
    assert model.options.geometric_stiffness and model.mechanism.gravity == (0.0, 0.0)
    assert model.mechanism.elements_per_link == ELEMENTS
    pins = peer_linear.linear_model(mech, elements_per_link=ELEMENTS)
    assert pins.options.bearings == 'rigid' and pins.mechanism.gravity == mech.gravity
    with pytest.raises(KeyError):
        peer_linear.linear_model(mech, bearings='loose')


def test_static_sag_is_linear_in_gravity(mech):
    sag = peer_linear.linear_static(mech, 0.6, elements_per_link=ELEMENTS)
    assert set(sag) == set(OUTPUT_KEYS)
    assert 1e-5 < math.hypot(sag['coupler_mid_dx'], sag['coupler_mid_dy']) < 1e-3
    double = dataclasses.replace(mech, gravity=tuple(2.0 * g for g in mech.gravity))
    twice = peer_linear.linear_static(double, 0.6, elements_per_link=ELEMENTS)
    # K_G of the static axial forces doubles too: linear up to a fraction of a percent
    for key in OUTPUT_KEYS:
        assert twice[key] == pytest.approx(2.0 * sag[key], rel=0.01, abs=1e-12)
    weightless = dataclasses.replace(mech, gravity=(0.0, 0.0))
    assert all(v == 0.0 for v in peer_linear.linear_static(weightless, 0.6,
                                                           elements_per_link=ELEMENTS).values())


def test_slow_response_is_the_static_sag(mech):
    """At 2 rpm the inertia loads are 1e-4 of those at 269 rpm: the response is quasi-static."""
    slow = peer_linear.linear_response(mech, 2.0, elements_per_link=ELEMENTS, steps=360,
                                       points=8)
    assert set(OUTPUT_KEYS) <= set(slow) and 'info' in slow
    for k in (0, 3, 6):
        static = peer_linear.linear_static(mech, slow['crank_angle'][k],
                                           elements_per_link=ELEMENTS)
        for key in ('coupler_mid_dx', 'coupler_mid_dy'):
            assert slow[key][k] == pytest.approx(static[key], rel=0.02, abs=1e-7), (k, key)
    assert np.ptp(slow['coupler_mid_dy']) > 1e-6            # the sag follows the crank
