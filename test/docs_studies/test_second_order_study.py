"""The reduced model's second order against the full order (docs/studies/second_order_study.py)."""

import math

from flexlink_ros.core.fe import second_order_full as so_full
from flexlink_ros.core.fe.simulate import periodic_response
from flexlink_ros.core.mechanism_file import load_mechanism
from flexlink_ros.studies import peer_exudyn as peer
import numpy as np
import pytest
import second_order_study

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


def test_order_2_against_the_nonlinear_peer_at_4_elements(mech):
    """
    Order 2 (full order, and the streaming estimate) against the Exudyn peer, 269 rpm.

    Rigid crank and bearings, no gravity, 4 elements per link (the peer runs in a few
    seconds; its lever-tip p2p is within 0.3 % of 8 elements': 20.36 / 29.67 um against
    20.39 / 29.83), all its settling revolutions (fewer leave a 15 % transient on the
    lever tip). The targets at 8 elements apply unchanged: lever tip p2p within
    10 % (streamed 12 %), coupler mid-point 3 % (4 %). Measured: full order + second order
    -2.1 / -3.6 % (lever tip), +0.7 / +0.6 % (coupler); the linear lever tip is ~90 % low.
    """
    pytest.importorskip('exudyn')
    record = second_order_study.run_case(mech, 269.0, False, ELEMENTS, points=120)
    assert all(value < 0.01 for value in record['periodicity'].values())
    assert all(second_order_study.meets_targets(record).values()), record['second_order']
    assert all(second_order_study.meets_targets(record, 'reduced').values()), record['reduced']
    for key in ('lever_tip_dx', 'lever_tip_dy'):
        assert record['linear'][key]['p2p_error'] < -0.8
