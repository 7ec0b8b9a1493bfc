"""Charts and table of the streaming estimator (report/estimator.py) from small data."""

import math

from flexlink_ros.report import estimator
from flexlink_ros.studies.synthetic import synthetic_signal
import numpy as np
from png_checks import has_colour, png_size

ROWS = [{'label': 'default', 'size': 18, 'us_per_sample': 9.5, 'us_per_sample_p99': 14.25,
         'offline_samples_per_s': 81234.4, 'error_coupler_mid': 0.004, 'error_lever_tip': 0.0123,
         'bytes': 2_500_000, 'default': True},
        {'label': 'small', 'size': 2, 'us_per_sample': 3.0, 'us_per_sample_p99': 4.0,
         'offline_samples_per_s': 200000.0, 'error_coupler_mid': 0.08, 'error_lever_tip': 0.0,
         'bytes': 40_000}]


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


def test_error_vs_cost_marks_the_default(tmp_path):
    path = estimator.plot_error_vs_cost(ROWS, tmp_path / 'cost.png', tolerance=0.01)
    assert png_size(path) == (1200, 504)
    assert has_colour(path, 'tab:red') and has_colour(path, 'tab:blue')
    plain = estimator.plot_error_vs_cost(ROWS[1:], tmp_path / 'plain.png')
    assert not has_colour(plain, 'tab:red')            # no default: no red star


def test_bench_table_has_one_row_per_configuration():
    lines = estimator.bench_table(ROWS).splitlines()
    assert len(lines) == 2 + len(ROWS)
    assert all(line.count('|') == 9 for line in lines)
    assert lines[2] == ('| default | 18 | 9.5 | 14.2 | 81234 | 0.40% | 1.23% | 2.50 |')
    assert lines[3].startswith('| small | 2 | 3.0 | 4.0 | 200000 | 8.00% | 0.00% | 0.04 |')
