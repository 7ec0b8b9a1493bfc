"""
The nonlinear full order against the real Exudyn peer (studies/nonlinear_validation.py).

Reduced size for CI time: 4 elements per link in both models, the peer at 360 steps per
revolution, bearing springs, beta = 3e-4 s in both (the transient settles in 11
revolutions), no gravity, 391 rpm (the paper's speed, inside the links' resonance band).
Measured: vector relative RMS lever tip / coupler mid linear 22.0 / 38.6 %, nonlinear
1.2 / 2.5 %; nonlinear p2p errors -0.3, -0.4, -0.6, -0.8 %.
"""

from flexlink_ros.studies import nonlinear_validation as nv
from flexlink_ros.studies import validation
from flexlink_ros.studies.peer_model import exudyn_available, OUTPUT_KEYS
import numpy as np
import pytest

needs_exudyn = pytest.mark.skipif(not exudyn_available(),
                                  reason="exudyn is not installed (pip install '.[peer]')")


@pytest.fixture(scope='module')
def record():
    settings = validation.Settings(elements_per_link=4, bearings='flexible',
                                   stiffness_damping=3e-4, gravity=False, peer_steps=360,
                                   points=120)
    return nv.validate_nonlinear('cho1992', 391.0, settings)


@needs_exudyn
def test_the_nonlinear_full_order_tracks_the_peer_through_resonance(record):
    assert record['peer_beta_s'] == 3e-4 and record['damping'] == 'beta 0.0003 s, zeta 0'
    assert max(record['periodicity'].values()) < 1e-3          # the peer had settled
    rms = record['point_rms_error']
    assert rms['linear']['lever_tip'] > 0.15 and rms['linear']['coupler_mid'] > 0.3
    assert rms['nonlinear']['lever_tip'] < 0.03 and rms['nonlinear']['coupler_mid'] < 0.04
    for key in OUTPUT_KEYS:
        assert abs(record['models']['nonlinear'][key]['p2p_error']) < 0.02
    assert record['targets_met'] == {'lever_tip': True, 'coupler_mid': True}
    assert record['spectral_radius'] < 1.0 and 2.0 <= record['newton_mean'] <= 5.0


@needs_exudyn
def test_record_structure_and_text(record):
    series = record['series']
    assert series['peer']['outputs'].shape == (360, 4)
    assert series['nonlinear'].shape == (120, 4) and series['crank_deg'].shape == (120,)
    # the record's p2p is the series'
    p2p = series['nonlinear'].max(axis=0) - series['nonlinear'].min(axis=0)
    np.testing.assert_allclose([record['models']['nonlinear'][k]['other_p2p']
                                for k in OUTPUT_KEYS], p2p, rtol=1e-12)
    assert 'series' not in nv.without_series(record)
    lines = nv.format_nonlinear(record).splitlines()
    assert lines[0].startswith('391 rpm, flexible bearings, gravity off, 4 elements per link')
    assert lines[-3] == ('nonlinear within 5 % RMS and 3 % p2p: lever tip yes, '
                         'coupler mid yes')
    assert lines[-2].startswith('Floquet multipliers |mu| ')
    assert lines[-1].startswith('nonlinear validity: largest element rotation ')
    validity = record['nonlinear_validity']
    assert 0.0 < validity['max_element_rotation_rad'] < 0.5
    assert validity['fold_distance'] >= 1.0 - record['spectral_radius'] - 1e-12
