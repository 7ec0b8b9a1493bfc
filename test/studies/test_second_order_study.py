"""The reduced model's second order against the full order (studies/second_order_study.py)."""

import math

from flexlink_ros.core.fe import second_order_full as so_full
from flexlink_ros.core.fe.simulate import periodic_response
from flexlink_ros.core.mechanism_file import load_mechanism
from flexlink_ros.studies import peer_exudyn as peer
from flexlink_ros.studies import second_order_study
import numpy as np
import pytest

ELEMENTS = 4


@pytest.fixture(scope='module')
def mech():
    return load_mechanism('cho1992')


def test_reduced_model_second_order_follows_the_full_order(mech):
    """
    The default reduced basis streams the second order of the full order.

    The default reduced basis (r = 6, rigid bearings) as the estimator streams it: linear +
    second order within 1 % of the full order's p2p (measured 0.1-0.2 % at 8 elements).
    """
    angles, streamed, size = second_order_study.reduced_response(
        mech, 269.0, True, ELEMENTS, points=120, grid=64)
    assert size == 6
    linkage = peer.linear_model(mech, elements_per_link=ELEMENTS, gravity=True)
    full = so_full.corrected_response(
        linkage, periodic_response(linkage, 269.0 * math.pi / 30.0, method='full',
                                   points=120))
    assert np.allclose(full['crank_angle'], angles)
    span = np.ptp(full['total'], axis=0)
    assert np.all(np.ptp(streamed - full['total'], axis=0) < 0.01 * span)
    assert np.ptp(full['second'][:, 0]) > 5.0 * np.ptp(full['linear'][:, 0])
