"""Charts and table of the streaming estimator (report/estimator.py) from small data."""

import math

from flexlink_ros.report import estimator
from flexlink_ros.studies.synthetic import synthetic_signal
import numpy as np
from png_checks import has_colour, png_size

ROWS = [{'label': 'default', 'size': 18, 'step_size': 6, 'grid_size': 128,
         'error_coupler_mid': 0.004, 'error_lever_tip': 0.0123, 'bytes': 2_500_000,
         'default': True},
        {'label': 'small', 'size': 2, 'step_size': 2, 'grid_size': 64, 'error_coupler_mid': 0.08,
         'error_lever_tip': 0.0, 'bytes': 40_000}]


def _revolution():
    """One revolution of a 269 rpm crank at 200 Hz, deflections a harmonic of its angle."""
    stamps, angles, _ = synthetic_signal(269.0, 60.0 / 269.0, 200.0, jitter=0.2, seed=1)
    crank_deg = np.degrees(np.mod(angles, 2.0 * math.pi))
    wave = np.column_stack([np.sin(2.0 * angles), np.cos(angles)]) * 1e-3
    return crank_deg, {'lever_tip': wave, 'coupler_mid': 0.5 * wave}


def test_estimate_chart_draws_estimate_and_reference(tmp_path):
    crank_deg, reference = _revolution()
    estimate = {key: 1.05 * value for key, value in reference.items()}
    path = estimator.plot_estimate(crank_deg, estimate, reference, tmp_path / 'sub' / 'e.png',
                                   title='269 rpm')
    assert path == tmp_path / 'sub' / 'e.png'          # the directory is made
    assert png_size(path) == (1200, 720)
    assert has_colour(path, 'black', pixels=200) and has_colour(path, 'tab:red', pixels=200)


def test_configuration_table_has_one_row_per_configuration():
    lines = estimator.configuration_table(ROWS).splitlines()
    assert len(lines) == 2 + len(ROWS)
    assert all(line.count('|') == 8 for line in lines)
    assert lines[2] == '| default | 18 | 6 | 128 | 0.40% | 1.23% | 2.50 |'
    assert lines[3] == '| small | 2 | 2 | 64 | 8.00% | 0.00% | 0.04 |'
