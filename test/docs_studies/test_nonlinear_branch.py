"""
The periodic-branch study (docs/studies/nonlinear_branch.py) at a reduced size in CI time.

2 elements per link, 240 steps per revolution, 380-420 rpm in 20 rpm steps: each sweep's orbit
is the orbit that the full order finds from the linear start at that speed (one branch at this
size), the fold distance is that of the orbit's own multipliers, and the chart is a real PNG.
"""

import importlib.util
import math
import pathlib

from flexlink_ros.core.fe.nonlinear_response import nonlinear_response
import matplotlib.image
import numpy as np
import pytest

PATH = pathlib.Path(__file__).resolve().parents[2] / 'docs' / 'studies' / 'nonlinear_branch.py'


@pytest.fixture(scope='module')
def study():
    spec = importlib.util.spec_from_file_location('nonlinear_branch', PATH)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope='module')
def result(study):
    return study.branch('flexible', 380.0, 420.0, 20.0, elements=2, steps=240, points=60)


def test_sweeps_visit_the_speeds_in_order(result):
    assert [r['rpm'] for r in result['up']] == [380.0, 400.0, 420.0]
    assert [r['rpm'] for r in result['down']] == [420.0, 400.0, 380.0]


def test_continued_orbit_is_the_orbit_from_the_linear_start(study, result):
    model = study.linear_model(study.resolve_mechanism('cho1992'), elements_per_link=2,
                               bearings=study.BEARINGS['flexible'], gravity=True)
    direct = nonlinear_response(model, 400.0 * math.pi / 30.0, steps=240, points=60, zeta=0.0,
                                beta=study.BETA)
    tip = np.hypot(*direct.peak_to_peak[:2])
    for direction in ('up', 'down'):
        row = result[direction][1]
        assert row['lever_tip_p2p_m'] == pytest.approx(tip, rel=1e-5)
        moduli = np.abs(direct.floquet_multipliers)
        assert row['spectral_radius'] == pytest.approx(moduli.max(), rel=1e-5)
        assert row['fold_distance'] == pytest.approx(
            np.abs(1.0 - direct.floquet_multipliers).min(), rel=1e-4)


def test_chart_is_a_png(study, result, tmp_path):
    path = tmp_path / 'branch.png'
    study.chart(result, path)
    image = matplotlib.image.imread(path)
    assert image.shape[0] > 400 and image.shape[1] > 400
