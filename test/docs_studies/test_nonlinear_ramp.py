"""
The ramp study (docs/studies/nonlinear_ramp.py) at a reduced size in CI time.

2 elements per link, 120 peer steps per revolution, a 1 s ramp between 390 and 410 rpm: the
peer run is kept and read back for the same profile, the summary holds every model's branch
measures and the estimates' errors against the peer, and the chart is a real PNG.
"""

import argparse
import importlib.util
import pathlib

from flexlink_ros.studies.peer_model import exudyn_available
import matplotlib.image
import numpy as np
import pytest
from ramp_sweep import POINTS, RampProfile

PATH = pathlib.Path(__file__).resolve().parents[2] / 'docs' / 'studies' / 'nonlinear_ramp.py'
PROFILE = RampProfile(390.0, 410.0, 1.0, 3.0, 2.0)

pytestmark = pytest.mark.skipif(not exudyn_available(), reason='exudyn is not installed')


@pytest.fixture(scope='module')
def study():
    spec = importlib.util.spec_from_file_location('nonlinear_ramp', PATH)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope='module')
def kept(tmp_path_factory):
    return tmp_path_factory.mktemp('ramp') / 'peer.npz'


@pytest.fixture(scope='module')
def result(study, kept):
    args = argparse.Namespace(elements=2, bearings='flexible', peer_steps=120, rate=1000.0,
                              jitter=0.3, peer=str(kept))
    return study.ramp_study(PROFILE, args)


def test_summary_has_every_model_and_measure(result):
    assert set(result['summary']) == {'peer', 'streaming', 'streaming, jitter'}
    for name, entry in result['summary'].items():
        for point in POINTS:
            assert 0.0 <= entry[point]['largest_gap'] < 10.0
            assert 390.0 <= entry[point]['at_rpm'] <= 410.0
            if name != 'peer':
                assert 0.0 < entry[point]['rms_vs_peer'] < 10.0
        if name != 'peer':
            assert entry['refused'] == 0
            assert np.isfinite(entry['largest_validity'])


def test_the_kept_peer_run_is_read_back(study, kept, result):
    assert kept.exists()
    args = argparse.Namespace(elements=2, bearings='flexible', peer_steps=120, peer=str(kept))
    again = study.load_or_run_peer(str(kept), PROFILE, args)
    rows = result['rows']['peer']
    assert len(again['time']) > 500
    assert again['info']['wall_s'] == pytest.approx(result['summary']['peer']['wall_s'])
    assert np.all(rows['lever_tip'] > 0)


def test_chart_is_a_png(study, result, tmp_path):
    path = tmp_path / 'ramp.png'
    study.chart(result, PROFILE, path)
    image = matplotlib.image.imread(path)
    assert image.shape[0] > 600 and image.shape[1] > 600
