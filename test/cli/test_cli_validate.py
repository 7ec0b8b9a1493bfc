"""
`flexlink validate` (cli/validate.py): the real command at a reduced size (4 elements per link).

One speed as JSON with a chart and a peer cache, the same as text from the cache, a two-speed
sweep where the validity flag turns, and the one-line errors (no speed, no exudyn).
"""

import json
import pathlib
import struct
import subprocess
import sys

from flexlink_ros.cli import main as cli
from flexlink_ros.studies.peer_model import exudyn_available
import pytest

needs_exudyn = pytest.mark.skipif(not exudyn_available(),
                                  reason="exudyn is not installed (pip install '.[peer]')")

SMALL = ('--elements-per-link', '4', '--no-gravity', '--bearings', 'rigid')


def png_size(path):
    """Width and height [px] from a PNG file's header; asserts it is a PNG."""
    data = path.read_bytes()
    assert data[:8] == b'\x89PNG\r\n\x1a\n' and data[12:16] == b'IHDR'
    return struct.unpack('>II', data[16:24])


def _run(capsys, *argv):
    code = cli.main(['validate', *argv])
    captured = capsys.readouterr()
    return code, captured.out, captured.err


@pytest.fixture(scope='module')
def cache(tmp_path_factory):
    return tmp_path_factory.mktemp('peer-cache')


@needs_exudyn
def test_one_speed_as_json_then_as_text_from_the_cache(capsys, cache, tmp_path):
    png = tmp_path / 'validate.png'
    code, out, err = _run(capsys, '--peer', 'exudyn', '--rpm', '391', *SMALL, '--cache',
                          str(cache), '--chart', str(png), '--json')
    assert code == 0
    # progress goes to stderr (a plain line at the end when it is not a terminal)
    assert 'validate: 100%' in err and '1/1' in err
    result = json.loads(out)
    (record,) = result['records']
    assert result['peer'] == 'exudyn' and result['flag_turns'] == []
    assert 'series' not in record and record['rpm'] == 391.0
    models = record['models']
    assert set(models) == {'linear', 'second_order', 'dynamic'}
    # rigid bearings: the lever tip is second order; the dynamic pass fixes the coupler
    assert models['linear']['lever_tip_dy']['p2p_error'] < -0.9
    assert abs(models['second_order']['lever_tip_dy']['p2p_error']) < 0.1
    assert (record['point_rms_error']['dynamic']['coupler_mid']
            < 0.5 * record['point_rms_error']['second_order']['coupler_mid'])
    width, height = png_size(png)
    assert width > 1000 and height > 300
    assert len(list(cache.iterdir())) == 1
    code, text, _ = _run(capsys, '--rpm', '391', *SMALL, '--cache', str(cache))
    assert code == 0 and len(list(cache.iterdir())) == 1
    lines = text.splitlines()
    assert lines[0].startswith('391 rpm, rigid bearings, gravity off, 4 elements per link')
    peer = lines[2].split()
    assert peer[:4] == ['Exudyn', 'peer', 'p2p', '[um]'] and len(peer) == 8
    tip = models['linear']['lever_tip_dx']['peer_p2p'] * 1e6
    assert float(peer[4]) == pytest.approx(tip, abs=0.051)   # the same peer run, reused
    labels = [line[:30].strip() for line in lines[3:12]]
    assert labels[0] == 'linear p2p [um]' and labels[3] == 'linear + 2nd order p2p [um]'
    assert labels[8] == '+ dynamic pass rel RMS'
    # rigid bearings and crank: the flexible crank moves the lever tip hundreds of times as much
    assert lines[-1].startswith('crank: ') and 'not checked' in lines[-1]
    assert lines[-2].startswith('validity indicator') and lines[-2].endswith('valid')


@needs_exudyn
def test_sweep_shows_where_the_flag_turns(capsys, cache, tmp_path):
    png = tmp_path / 'sweep.png'
    code, out, _ = _run(capsys, '--sweep', '269:405:136', *SMALL, '--cache', str(cache),
                        '--chart', str(png))
    assert code == 0
    lines = out.splitlines()
    rows = {line.split()[0]: line.split() for line in lines[2:4]}
    assert rows['269'][-2:] == ['yes', 'yes']        # valid, second order within targets
    assert rows['405'][-2:] == ['NO', 'NO']          # flagged, and off the peer
    assert lines[4] == 'flag turns: NOT valid from 405 rpm (after 269)'
    assert lines[-1] == f'chart: {png}' and png_size(png)[1] > 500


def test_no_speed_is_a_one_line_error(capsys):
    if not exudyn_available():
        pytest.skip('exudyn is not installed')
    code, out, err = _run(capsys, '--no-gravity')
    assert code == 1 and out == ''
    assert err.strip() == ('flexlink validate: error: give crank speeds with --rpm R [R ...] '
                           'or --sweep START:STOP:STEP (the mechanism file has no '
                           'crank_speed_rpm)')


def test_without_exudyn_the_error_names_the_extra():
    code = ('import sys; sys.modules["exudyn"] = None\n'
            'from flexlink_ros.cli import main\n'
            'sys.exit(main.main(["validate", "--rpm", "269"]))\n')
    run = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                         timeout=120)
    assert run.returncode == 1 and run.stdout == ''
    assert run.stderr.startswith('flexlink validate: error: the Exudyn peer is not installed')
    assert "pip install '.[peer]'" in run.stderr and len(run.stderr.splitlines()) == 1


@needs_exudyn
def test_a_peer_failure_is_one_line_with_a_hint_and_no_traceback(tmp_path):
    """1e12 N/m bearing springs on 0.1 g pins at 600 rpm: the peer's solver fails."""
    text = (pathlib.Path(__file__).resolve().parents[1] / 'data' / 'packaging_steel.yaml'
            ).read_text().replace('stiffness_n_m: 5.0e+7', 'stiffness_n_m: 1.0e+12').replace(
        'O2: 0.02, A: 0.02, B: 0.02, O4: 0.02', 'O2: 0.0001, A: 0.0001, B: 0.0001, O4: 0.0001')
    assert '1.0e+12' in text and '0.0001' in text
    mechanism = tmp_path / 'stiff_springs_light_pins.yaml'
    mechanism.write_text(text)
    done = subprocess.run([sys.executable, '-m', 'flexlink_ros.cli', 'validate', '--mechanism',
                           str(mechanism), '--bearings', 'flexible', '--rpm', '600',
                           '--revolutions', '1'], capture_output=True, text=True, timeout=300)
    assert done.returncode == 1 and done.stdout == ''      # Exudyn's banner held back
    assert 'Traceback' not in done.stderr
    last = done.stderr.strip().splitlines()[-1]
    assert last.startswith('flexlink validate: error: the Exudyn peer failed at 600 rpm '
                           '(8 elements per link, springs bearings, 5760 steps a revolution) '
                           '"DYNAMIC SOLVER FAILED"')
    assert 'hint: ' in last and '--bearings rigid' in last


@needs_exudyn
def test_the_peer_is_damped_with_the_asked_stiffness_damping(capsys):
    """`--stiffness-damping B` damps the peer with B too, not with its default 1e-4 s."""
    tiny = ('--rpm', '391', '--elements-per-link', '2', '--no-gravity', '--revolutions', '2',
            '--bearings', 'flexible', '--json')
    p2p = {}
    for beta in (3e-4, 1e-4):
        code, out, _ = _run(capsys, *tiny, '--stiffness-damping', f'{beta:g}')
        assert code == 0
        (record,) = json.loads(out)['records']
        assert record['settings']['beta_s'] == beta
        assert record['peer_beta_s'] == beta           # what the peer ran with
        assert record['damping'] == f'beta {beta:g} s'
        p2p[beta] = record['peer_p2p']['coupler_mid_dy']
    # the two peers differ: three times the damping changes the start transient's decay
    assert abs(p2p[3e-4] / p2p[1e-4] - 1.0) > 1e-3


@needs_exudyn
def test_nonlinear_compares_both_full_orders_and_the_streaming_estimate(capsys, tmp_path):
    """`--nonlinear`: linear and nonlinear full order, streaming estimate, damped as the peer."""
    tiny = ('--rpm', '391', '--elements-per-link', '2', '--no-gravity', '--revolutions', '2',
            '--bearings', 'flexible', '--stiffness-damping', '3e-4', '--nonlinear')
    code, out, _ = _run(capsys, *tiny, '--json')
    assert code == 0
    result = json.loads(out)
    (record,) = result['records']
    assert result['model'] == 'nonlinear' and record['peer_beta_s'] == 3e-4
    assert set(record['models']) == {'linear', 'nonlinear', 'streaming'}
    assert set(record['point_rms_error']['streaming']) == {'lever_tip', 'coupler_mid'}
    assert record['streaming']['refused'] == 0 and record['streaming']['samples'] > 0
    assert set(record['streaming_targets_met']) == {'lever_tip', 'coupler_mid'}
    assert record['spectral_radius'] < 1.0 and len(record['floquet_moduli']) == 4
    lines = _run(capsys, *tiny)[1].splitlines()
    assert lines[0].startswith('391 rpm, flexible bearings, gravity off, 2 elements per link')
    assert lines[-3].startswith('streaming within 10 % RMS: lever tip ')
    assert any(line.startswith('streaming vector rel RMS  lever tip ') for line in lines)
    assert lines[-2].startswith('Floquet multipliers |mu| ')
    assert lines[-1].startswith('nonlinear validity: largest element rotation ')
    code, out, err = _run(capsys, *tiny, '--chart', str(tmp_path / 'x.png'))
    assert code == 1 and out == '' and '--chart' in err and not (tmp_path / 'x.png').exists()
