"""`flexlink modes` and `flexlink simulate`: JSON keys, consistency with the core, errors."""

import json

from flexlink_ros.cli import main as cli
from flexlink_ros.core import validity
import numpy as np
import pytest


def _run(capsys, *argv):
    code = cli.main(list(argv))
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def test_modes_json(capsys):
    code, out, _ = _run(capsys, 'modes', '--crank-deg', '0:360:90', '--count', '2',
                        '--rigid-crank', '--bearings', 'rigid', '--elements-per-link', '3',
                        '--no-geometric-stiffness', '--json')
    assert code == 0
    result = json.loads(out)
    assert result['crank_deg'] == [0.0, 90.0, 180.0, 270.0]
    freqs = np.array(result['frequencies_hz'])
    assert freqs.shape == (4, 2)
    # coupler and lever pinned-pinned bending (the paper's 34 and 41 Hz)
    assert 34.0 < freqs[:, 0].min() < 35.0 and 40.5 < freqs[:, 1].max() < 41.5
    assert result['dominant_link'][0] == ['coupler', 'lever']
    assert result['range_hz']['min'] == pytest.approx(freqs.min(axis=0).tolist())
    assert result['options']['rigid_crank'] is True


def test_modes_shapes_and_flexible_bearings(capsys):
    code, out, _ = _run(capsys, 'modes', '--crank-deg', '27', '--count', '3', '--bearings',
                        'flexible', '--no-geometric-stiffness', '--elements', '2', '--shapes',
                        '--json')
    assert code == 0
    result = json.loads(out)
    shapes = np.array(result['shapes']['deflection_per_unit_modal_m'])
    assert shapes.shape == (1, 3, 3, 17, 2)
    assert np.all(np.abs(shapes).reshape(3, -1).max(axis=1) > 0)


def test_simulate_json_and_modal_equals_full_with_all_modes(capsys):
    common = ('simulate', '--rpm', '269', '--rigid-crank', '--no-geometric-stiffness',
              '--bearings', 'rigid', '--elements', '1', '--points-per-rev', '12',
              '--steps-per-rev', '120', '--json')
    code, out, _ = _run(capsys, *common)
    assert code == 0
    full = json.loads(out)
    assert len(full['crank_deg']) == 12 and full['crank_deg'][1] == pytest.approx(30.0)
    for point in ('lever_tip', 'coupler_mid'):
        assert len(full[point]['dx_m']) == len(full[point]['dy_m']) == 12
    assert full['wall_s'] > 0 and full['floquet_spectral_radius'] < 1
    dofs = full['options']['dofs']
    code, out, _ = _run(capsys, *common, '--method', 'modal', '--modes', str(dofs))
    modal = json.loads(out)
    np.testing.assert_allclose(modal['coupler_mid']['dy_m'], full['coupler_mid']['dy_m'],
                               rtol=1e-9, atol=1e-15)


def test_simulate_convergence_check(capsys):
    code, out, _ = _run(capsys, 'simulate', '--rigid-crank', '--no-geometric-stiffness',
                        '--bearings', 'rigid', '--elements', '1', '--points-per-rev', '10',
                        '--steps-per-rev', '160',
                        '--check-convergence', '--json')
    assert code == 0
    conv = json.loads(out)['convergence']
    assert conv['steps'] == [40, 80, 160] and conv['reference_steps'] == 640
    assert conv['max_error_m'][2] < conv['max_error_m'][1] < conv['max_error_m'][0]


@pytest.mark.parametrize('argv, message', [
    (('modes', '--count', 'x', '--no-geometric-stiffness'), '--count'),
    (('simulate', '--method', 'modal', '--no-geometric-stiffness'), '--modes'),
    (('simulate', '--rpm', '-5'), '--rpm'),
    (('simulate', '--steps-per-rev', '100', '--points-per-rev', '30',
      '--no-geometric-stiffness'), 'multiple'),
])
def test_bad_input_is_one_line_error(capsys, argv, message):
    code, out, err = _run(capsys, *argv)
    assert code == 1 and out == ''
    assert message in err and err.count('\n') == 1


def test_unknown_bearings_are_refused_with_the_choices(capsys):
    """--bearings takes its choices from the parser (as estimate/plan/bench/replay)."""
    with pytest.raises(SystemExit) as exit_info:
        cli.main(['modes', '--bearings', 'elastic'])
    _, err = capsys.readouterr()
    assert exit_info.value.code == 2
    assert '--bearings' in err and "'flexible', 'rigid'" in err


def test_simulate_with_stiffness_damping(capsys):
    """--stiffness-damping reaches the full order: reported, and it damps the response."""
    common = ('simulate', '--rpm', '269', '--rigid-crank', '--bearings', 'flexible',
              '--elements', '2', '--points-per-rev', '12', '--steps-per-rev', '120',
              '--damping-ratio', '0', '--json')
    runs = {}
    for beta in ('0', '1e-4'):
        code, out, _ = _run(capsys, *common, '--stiffness-damping', beta)
        assert code == 0
        runs[beta] = json.loads(out)
    assert runs['1e-4']['stiffness_damping_s'] == 1e-4
    assert runs['0']['stiffness_damping_s'] == 0.0
    assert runs['1e-4']['floquet_spectral_radius'] < runs['0']['floquet_spectral_radius']
    code, out, _ = _run(capsys, *common[:-1], '--stiffness-damping', '1e-4')
    assert code == 0 and 'stiffness damping 0.0001 s' in out


def test_simulate_json_says_whether_the_linear_response_is_valid(capsys):
    """The validity indicator over the revolution: valid at 269 rpm, not at 405 (rigid)."""
    summaries = {}
    for rpm in ('269', '405'):
        code, out, _ = _run(capsys, 'simulate', '--rpm', rpm, '--rigid-crank', '--bearings',
                            'rigid', '--elements-per-link', '4', '--points-per-rev', '60',
                            '--json')
        assert code == 0
        summaries[rpm] = json.loads(out)['nonlinearity']
    assert summaries['269']['valid'] is True and summaries['405']['valid'] is False
    assert (summaries['269']['indicator_max'] < validity.VALIDITY_THRESHOLD
            < summaries['405']['indicator_max'])
    assert summaries['405']['threshold'] == validity.VALIDITY_THRESHOLD
    code, out, _ = _run(capsys, 'simulate', '--rpm', '405', '--rigid-crank', '--bearings',
                        'rigid', '--elements-per-link', '4', '--points-per-rev', '60')
    assert 'linear estimate NOT valid' in out


def test_simulate_order_1_is_linear_and_order_2_adds_the_second_order(capsys):
    # Rigid bearings: joint B (the lever tip) moves mostly by the links' chord shortening.
    common = ('simulate', '--rpm', '391', '--rigid-crank', '--bearings', 'rigid',
              '--elements-per-link', '2', '--points-per-rev', '24', '--steps-per-rev', '240',
              '--json')
    runs = {}
    for order in ('1', '2'):
        code, out, _ = _run(capsys, *common, '--order', order)
        assert code == 0
        runs[order] = json.loads(out)
        assert runs[order]['order'] == int(order)
    linear, second = runs['1'], runs['2']
    assert 'linear_peak_to_peak_m' not in linear
    assert second['linear_peak_to_peak_m'] == linear['peak_to_peak_m']
    tip = {k: np.hypot(*(np.array(r['lever_tip'][c]) for c in ('dx_m', 'dy_m')))
           for k, r in runs.items()}
    assert np.ptp(tip['2']) > 3.0 * np.ptp(tip['1'])
    # The coupler mid-point moves mostly linearly: order 2 changes it by a few per cent.
    mid = [np.ptp(r['coupler_mid']['dy_m']) for r in (linear, second)]
    assert mid[1] == pytest.approx(mid[0], rel=0.1) and mid[1] != mid[0]
    with pytest.raises(SystemExit):
        _run(capsys, *common, '--order', '3')
    assert 'invalid choice' in capsys.readouterr().err


def test_simulate_order_2_is_the_dynamic_pass_for_the_full_order(capsys):
    """Full order: the dynamic second-order pass by default; quasi-static on request."""
    common = ('simulate', '--rpm', '391', '--rigid-crank', '--bearings', 'rigid',
              '--elements-per-link', '2', '--points-per-rev', '24', '--steps-per-rev', '240',
              '--json')
    runs = {}
    for kind in (None, 'quasi-static'):
        code, out, _ = _run(capsys, *common, *(('--second-order', kind) if kind else ()))
        assert code == 0
        runs[kind] = json.loads(out)
    assert runs[None]['second_order'] == 'dynamic'
    assert runs['quasi-static']['second_order'] == 'quasi-static'
    assert runs[None]['linear_peak_to_peak_m'] == runs['quasi-static']['linear_peak_to_peak_m']
    dynamic, quasi = (np.array(runs[k]['coupler_mid']['dy_m']) for k in (None, 'quasi-static'))
    # the pass adds the inertia of the second-order motion: a change, not a new response
    assert 0.0 < np.abs(dynamic - quasi).max() < 0.2 * np.ptp(quasi)
    code, out, err = _run(capsys, 'simulate', '--rpm', '391', '--rigid-crank', '--bearings',
                          'rigid', '--elements-per-link', '2', '--method', 'modal', '--modes',
                          '4', '--points-per-rev', '24', '--steps-per-rev', '240',
                          '--second-order', 'dynamic')
    assert code != 0 and 'full-order linear state' in err
