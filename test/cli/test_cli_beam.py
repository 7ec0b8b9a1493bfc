"""`flexlink beam`: JSON keys, Table 5 through the command line, one-line errors."""

import json

from flexlink_ros.cli import main as cli
from flexlink_ros.core.tmm import roots
import pytest


def _run(capsys, *argv):
    code = cli.main(['beam', *argv])
    captured = capsys.readouterr()
    return code, captured.out, captured.err


@pytest.mark.parametrize('search', roots.SEARCHES)
def test_json_keys_and_table5_value(capsys, search):
    code, out, _ = _run(capsys, '--bc', 'fixed-supported', '--segments', '6', '--method', 'tmm3',
                        '--search', search, '--step', '10', '--modes', '2', '--json')
    assert code == 0
    result = json.loads(out)
    for key in ('frequencies_rad_s', 'iterations', 'exact_rad_s', 'error_percent',
                'iterations_paper_criterion', 'scan_evaluations', 'wall_time_s'):
        assert key in result
    assert len(result['frequencies_rad_s']) == len(result['iterations']) == 2
    assert result['frequencies_rad_s'][0] == pytest.approx(826.462466, abs=5e-7)
    assert result['exact_rad_s'][0] == pytest.approx(826.598073, rel=3e-9)
    assert all(isinstance(count, int) and count > 0 for count in result['iterations'])
    error = 100 * (result['frequencies_rad_s'][1] / result['exact_rad_s'][1] - 1)
    assert result['error_percent'][1] == pytest.approx(error)


def test_fe_has_no_iterations_and_converges(capsys):
    code, out, _ = _run(capsys, '--bc', 'supported', '--method', 'fe', '--segments', '20',
                        '--json')
    result = json.loads(out)
    assert code == 0 and result['iterations'] == [None, None, None]
    assert max(abs(e) for e in result['error_percent']) < 1e-2


def test_text_table(capsys):
    code, out, _ = _run(capsys, '--bc', 'cantilever')
    assert code == 0
    assert '188.452845' in out and 'exact' in out


def test_beam_overrides_scale_as_euler_bernoulli(capsys):
    _, out, _ = _run(capsys, '--bc', 'supported', '--method', 'fe', '--segments', '12',
                     '--modes', '1', '--json')
    base = json.loads(out)['frequencies_rad_s'][0]
    _, out, _ = _run(capsys, '--bc', 'supported', '--method', 'fe', '--segments', '12',
                     '--modes', '1', '--length-m', '0.4', '--thickness-m', '0.003', '--json')
    # omega ~ t / L^2: doubling both halves the frequency
    assert json.loads(out)['frequencies_rad_s'][0] == pytest.approx(base / 2, rel=1e-9)


@pytest.mark.parametrize('argv, name', [
    (['--bc', 'clamped'], '--bc'),
    (['--method', 'tmm4'], '--method'),
    (['--search', 'secant'], '--search'),
    (['--segments', '0'], '--segments'),
    (['--segments', 'six'], '--segments'),
    (['--step', '0'], '--step'),
    (['--step', 'nan'], '--step'),
    (['--modes', '99'], 'modes'),
    (['--method', 'tmm2', '--segments', '1'], 'segments'),
    (['--thickness-m', '-1'], '--thickness-m'),
])
def test_bad_input_exits_nonzero_with_one_line(capsys, argv, name):
    code, out, err = _run(capsys, *argv)
    assert code != 0 and out == ''
    assert len(err.strip().splitlines()) == 1 and name in err
