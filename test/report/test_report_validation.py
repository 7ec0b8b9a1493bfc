"""Charts of `flexlink validate` (report/validation.py) from synthetic validation records."""

from flexlink_ros.report import validation as chart
from flexlink_ros.studies import validation
import numpy as np
from png_checks import has_colour, png_size
import pytest

SETTINGS = {'bearings': 'rigid', 'gravity': False, 'elements_per_link': 4, 'beta_s': 1e-4}


def _record(rpm, indicator, error=0.05):
    angle = np.radians(np.arange(0.0, 360.0, 3.0))
    peer_angle = np.radians(np.arange(0.0, 360.0, 1.0))
    wave = lambda a, scale: np.stack([np.sin(a + k) * scale for k in range(4)], 1)  # noqa
    series = {'peer': {'crank_deg': np.degrees(peer_angle),
                       'outputs': wave(peer_angle, 1e-4)}}
    table = {}
    for index, name in enumerate(validation.MODELS):
        series[name] = {'crank_deg': np.degrees(angle),
                        'outputs': wave(angle, 1e-4 * (1 + error * (index + 1)))}
        table[name] = {key: {'p2p_error': error * (index + 1), 'rms_error': error,
                             'other_p2p': 2e-4, 'peer_p2p': 2e-4}
                       for key in validation.OUTPUT_KEYS}
    rms = {name: {'lever_tip': 2 * error, 'coupler_mid': error} for name in validation.MODELS}
    return {'rpm': rpm, 'settings': SETTINGS, 'point_rms_error': rms, 'zeta': 0.02,
            'damping': 'modal zeta 0.02', 'threshold': 0.5,
            'nonlinearity': {'indicator_max': indicator, 'valid': indicator <= 0.5},
            'models': table, 'series': series}


def test_speed_chart_draws_the_peer_and_every_model(tmp_path):
    one = chart.plot_validation([_record(269, 0.1)], tmp_path / 'one.png')
    two = chart.plot_validation([_record(269, 0.1), _record(391, 0.3)], tmp_path / 'two.png')
    assert png_size(two)[1] > 1.6 * png_size(one)[1]      # one row per speed
    for colour in ('black', 'tab:gray', 'tab:blue', 'tab:red'):
        assert has_colour(one, colour), colour


def test_sweep_chart_shades_the_flagged_speeds(tmp_path):
    valid = [_record(rpm, 0.1) for rpm in range(250, 300, 10)]
    flagged = valid[:3] + [_record(280, 0.9, 0.3), _record(290, 1.2, 0.4)]
    plain = chart.plot_validation(valid, tmp_path / 'plain.png')
    shaded = chart.plot_validation(flagged, tmp_path / 'shaded.png')
    assert png_size(plain)[0] > 500
    assert has_colour(shaded, '0.88', pixels=2000) and not has_colour(plain, '0.88',
                                                                      pixels=2000)
    assert has_colour(shaded, 'tab:green') and has_colour(shaded, 'tab:red')
    # asked for explicitly, two speeds are a sweep too
    small = chart.plot_validation(flagged[:2], tmp_path / 'small.png', sweep=True)
    assert png_size(small) == png_size(plain)


def test_no_records_is_an_error(tmp_path):
    with pytest.raises(ValueError, match='no records'):
        chart.plot_validation([], tmp_path / 'none.png')
