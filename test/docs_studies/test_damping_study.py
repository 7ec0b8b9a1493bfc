"""Stiffness-proportional damping studied against the peer (docs/studies/damping_study.py)."""

import math

import damping_study as ds
import numpy as np
import pytest

BETA = 1e-4


def test_naive_spurious_axial_force_in_coupler_end_element_at_391_rpm():
    """
    The measured ~760 N: naive beta K U' minus objective, coupler's element at B, 8 elements.

    Measured 738 N (391 rpm, bearing springs, rigid crank, split masses, no gravity; 171 N at
    269 rpm; 240 steps per revolution instead of 720 change it by 0.1 %). It is
    beta E A w_L v_e / l_e, so it halves with half the elements (mesh-dependent, unphysical):
    3 elements give 283 N.
    """
    speed = 391.0 * 2.0 * math.pi / 60.0
    forces = {}
    for elements in (8, 4):
        model = ds.matched_model('cho1992', elements, gravity=False)
        run = ds.full_order_response(model, speed, BETA, 'objective', steps=240)
        spurious = ds.spurious_axial_force(model, run, speed, BETA)
        forces[elements] = np.abs(spurious[1]).max(axis=0)
        assert np.argmax(forces[elements]) == elements - 1     # the end element at B
    assert 700.0 < forces[8][-1] < 780.0
    assert forces[4][-1] == pytest.approx(0.5 * forces[8][-1], rel=0.05)


def test_beta_damped_full_order_and_streaming_estimate_against_peer_at_four_elements():
    """
    269 rpm, bearing springs, matched conventions: lever / coupler within 4.5 % RMS.

    Measured 2.8 / 3.4 % at 4 elements and 2.8 / 3.3 % at 8 (first measured: 2.9 / 3.4 %). The
    remainder is the second-order motion the linear model lacks (the quasi-static
    correction brings the lever to 1 %); 4.5 % leaves room for the peer's time step and
    elements while staying inside the 5 % target. Modal zeta = 0.02 is 4.5 % on the
    coupler: the beta model must beat it there.
    """
    peer_exudyn = pytest.importorskip('flexlink_ros.studies.peer_exudyn')
    if not peer_exudyn.exudyn_available():
        pytest.skip('exudyn is not installed')
    peer = peer_exudyn.peer_response('cho1992', 269.0, elements_per_link=4, bearings='springs',
                                     gravity=False, beta_s=BETA, mass_placement='split',
                                     steps_per_revolution=720, samples_per_revolution=120)
    model = ds.matched_model('cho1992', 4, gravity=False)
    speed = 269.0 * 2.0 * math.pi / 60.0
    full = ds.full_order_response(model, speed, BETA, 'objective')
    beta = ds.point_rms(peer, full)
    modal = ds.point_rms(peer, ds.full_order_response(model, speed, BETA, 'modal', zeta=0.02))
    assert beta['lever_tip'] < 0.045 and beta['coupler_mid'] < 0.045
    assert beta['coupler_mid'] < modal['coupler_mid'] - 0.005
    # The streaming estimate (reduced tables with C_beta and D_beta, zeta = 0): measured
    # 2.8 / 3.3 % against the peer and 0.08 / 0.09 % off the full order (8 elements:
    # 2.8 / 3.3 % and 0.2 / 0.1 %).
    reduced = ds.matched_reduced_model('cho1992', 4, gravity=False, beta=BETA, use_cache=False)
    stream = ds.streaming_response(reduced, speed)
    assert np.allclose(stream['crank_angle'], full['crank_angle'])
    streaming = ds.point_rms(peer, stream)
    assert streaming['lever_tip'] < 0.045 and streaming['coupler_mid'] < 0.045
    for key in ds.OUTPUT_KEYS:
        scale = np.abs(full[key]).max()
        assert np.sqrt(np.mean((stream[key] - full[key]) ** 2)) < 0.005 * scale, key
