"""`flexlink kinematics`, `criteria`, `design-spring`: JSON interface, Table 2, errors."""

import json
import math
import pathlib

from flexlink_ros.cli import main as cli
import pytest


def _run(capsys, *argv):
    code = cli.main(list(argv))
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def test_criteria_json_interface_and_table_2_with_the_paper_spring(capsys, config_dir):
    code, out, _ = _run(capsys, 'criteria', '--mechanism', str(config_dir / 'kang1990.yaml'),
                        '--spring', '20', '279.14', '--grid-deg', '1', '--scan-points', '1800',
                        '--json')
    assert code == 0
    result = json.loads(out)
    assert set(result['joints']) == {'O2', 'A', 'B', 'O4'}
    for joint in result['joints'].values():
        for key in ('max_ratio', 'max_ratio_on_grid', 'at_crank_deg', 'min_force_n'):
            assert isinstance(joint[key], float)
        assert joint['max_ratio'] >= joint['max_ratio_on_grid']
        assert 0.0 <= joint['at_crank_deg'] < 360.0
    for joint, printed in {'A': 15.80, 'B': 22.44, 'O4': 22.03}.items():
        assert result['joints'][joint]['max_ratio_on_grid'] == pytest.approx(printed, rel=1e-3)
    assert result['spring']['theta0_deg'] == pytest.approx(279.14)


def test_criteria_text_rpm_and_bare_name(capsys):
    code, out, _ = _run(capsys, 'criteria', '--mechanism', 'kang1990', '--rpm', '450',
                        '--scan-points', '720')
    assert code == 0 and '450 rpm' in out and 'B (2)' in out
    # no gravity or spring: R ~ w^2 and dF/dt ~ w^3, so gamma_dot ~ w and the ratio ~ 1/w
    code, out, _ = _run(capsys, 'criteria', '--mechanism', 'kang1990', '--rpm', '450',
                        '--scan-points', '720', '--json')
    slow = json.loads(out)
    code, out, _ = _run(capsys, 'criteria', '--mechanism', 'kang1990', '--scan-points', '720',
                        '--json')
    fast = json.loads(out)
    for joint in ('O2', 'A', 'B', 'O4'):
        assert slow['joints'][joint]['max_ratio'] == pytest.approx(
            2.0 * fast['joints'][joint]['max_ratio'], rel=1e-6)


def test_kinematics_json(capsys):
    code, out, _ = _run(capsys, 'kinematics', '--mechanism', 'kang1990', '--crank-deg',
                        '0:360:90', '--json')
    assert code == 0
    result = json.loads(out)
    assert result['crank_deg'] == [0.0, 90.0, 180.0, 270.0]
    assert set(result['links']) == {'crank', 'coupler', 'lever'}
    a = complex(result['joints']['A']['x_m'][1], result['joints']['A']['y_m'][1])
    assert a == pytest.approx(0.0381j, abs=1e-15)
    assert len(result['dead_centres_deg']) == 2
    low, high = result['transmission_extremes_deg']
    assert 0 < low < min(result['transmission_angle_deg']) + 1e-9 and high < 180


def test_design_spring_json_small_budget(capsys):
    code, out, _ = _run(capsys, 'design-spring', '--mechanism', 'kang1990', '--maxiter', '8',
                        '--popsize', '6', '--json')
    assert code == 0
    result = json.loads(out)
    for key in ('k_nm_per_rad', 'theta0_deg', 'objective', 'paper_objective'):
        assert isinstance(result[key], float)
    assert result['feasible'] and result['objective'] < result['paper_objective']
    assert result['paper_objective'] == pytest.approx(60.30, abs=0.01)
    assert 0.0 <= result['k_nm_per_rad'] <= 20.0 and math.isfinite(result['theta0_deg'])


@pytest.mark.parametrize('argv, message', [
    (['criteria', '--grid-deg', '0'], 'grid-deg'),
    (['criteria', '--spring', '-1', '200'], 'spring'),
    (['criteria', '--rpm', 'fast'], 'rpm'),
    (['criteria', '--mechanism', 'no_such_mechanism'], 'no such file'),
    (['kinematics', '--crank-deg', '0:1'], 'crank-deg'),
    (['design-spring', '--theta0-max-deg', '-5'], 'theta0-max-deg'),
])
def test_bad_input_gives_one_line_error(capsys, argv, message):
    code, out, err = _run(capsys, *argv)
    # a mechanism file refused (here: not found) ends with 2, other bad input with 1
    assert code == (2 if '--mechanism' in argv else 1) and out == ''
    assert message in err and len(err.strip().splitlines()) == 1


def test_criteria_suggests_thresholds_for_a_machine_of_its_own(capsys):
    mechanism = pathlib.Path(__file__).resolve().parents[1] / 'data' / 'packaging_steel.yaml'
    assert cli.main(['criteria', '--mechanism', str(mechanism), '--suggest-thresholds',
                     '--json']) == 0
    found = json.loads(capsys.readouterr().out)['thresholds']
    assert found['rpm'] == pytest.approx(600.0) and found['warn'] < found['error']
    assert [j for j, v in found['joints'].items() if not v['used']] == ['B']
    assert cli.main(['criteria', '--mechanism', str(mechanism), '--suggest-thresholds']) == 0
    text = capsys.readouterr().out
    assert f'  diagnostics.criterion_warn: {found["warn"]:.6g}\n' in text
    assert 'B: its reaction falls to 0.18 % of its RMS' in text
