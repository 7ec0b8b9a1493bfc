"""
`flexlink simulate --nonlinear` (cli/simulate_nonlinear.py): the real command at a small size.

JSON against the core's nonlinear_response, the text report, and the refused flags.
"""

import json
import math

from flexlink_ros.cli import main as cli
from flexlink_ros.cli.flex import build_model
from flexlink_ros.core.fe.nonlinear_response import nonlinear_response
from flexlink_ros.core.fe.nonlinear_validity import orbit_rotations
from flexlink_ros.core.fe.simulate import periodic_response
import numpy as np
import pytest

SMALL = ('simulate', '--nonlinear', '--rpm', '391', '--rigid-crank', '--bearings', 'flexible',
         '--elements-per-link', '2', '--damping-ratio', '0', '--stiffness-damping', '1e-4',
         '--steps-per-rev', '240', '--points-per-rev', '60')


def _run(capsys, *argv):
    code = cli.main(list(argv))
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def test_json_is_the_cores_nonlinear_orbit(capsys):
    code, out, _ = _run(capsys, *SMALL, '--json')
    assert code == 0
    result = json.loads(out)
    args = cli.build_parser(list(SMALL)).parse_args(list(SMALL))
    _, model = build_model(args)
    speed = 391.0 * math.pi / 30.0
    kwargs = {'steps': 240, 'points': 60, 'zeta': 0.0}
    linear = periodic_response(model, speed, **kwargs)
    core = nonlinear_response(model, speed, **kwargs)
    np.testing.assert_allclose(result['coupler_mid']['dy_m'], core.outputs[:, 3], rtol=0,
                               atol=1e-9 * np.abs(core.outputs).max())
    p2p = result['peak_to_peak_m']
    np.testing.assert_allclose(p2p['lever_tip'] + p2p['coupler_mid'], core.peak_to_peak,
                               rtol=1e-6)
    lin = result['linear_peak_to_peak_m']
    np.testing.assert_allclose(lin['lever_tip'] + lin['coupler_mid'], linear.peak_to_peak,
                               rtol=1e-12)
    assert abs(p2p['coupler_mid'][1] / lin['coupler_mid'][1] - 1.0) > 0.1   # near resonance
    multipliers = np.array(result['floquet_multipliers'])
    assert multipliers.shape == (8, 2)
    moduli = np.hypot(multipliers[:, 0], multipliers[:, 1])
    assert moduli[0] == pytest.approx(result['floquet_spectral_radius'])
    assert np.all(np.diff(moduli) <= 1e-12) and moduli[0] < 1.0
    newton = result['newton_iterations_per_step']
    assert 2.0 <= newton['mean'] <= newton['max'] <= 10
    assert result['model'] == 'nonlinear' and result['stiffness_damping_s'] == 1e-4
    assert result['strain'] == 'corotational'
    assert result['nonlinear_validity']['rotation_frame'] == 'chord'
    assert result['periodicity'] < 1e-8 and result['step_cpu_s'] > 0.0
    assert len(result['crank_deg']) == 60
    validity = result['nonlinear_validity']
    assert validity['max_element_rotation_rad'] == pytest.approx(
        orbit_rotations(model, core).max(), rel=1e-6)
    assert 0.01 < validity['max_element_rotation_rad'] < 0.5         # bent, in the resonance
    moduli_all = np.abs(core.floquet_multipliers)
    assert validity['fold_distance'] >= 1.0 - moduli_all.max() - 1e-12
    assert validity['valid'] == (validity['indicator'] < 1.0)


def test_text_report(capsys):
    code, out, _ = _run(capsys, *SMALL)
    assert code == 0
    lines = out.splitlines()
    assert lines[0].startswith('cho1992 at 391 rpm, nonlinear full order (corotational '
                               'strain), 18 DOFs')
    assert lines[1].startswith('peak-to-peak [mm]: lever tip dX')
    assert lines[2].startswith('  linear full order: lever tip dX')
    assert lines[3].startswith('Floquet multipliers |mu|') and lines[3].endswith('stable)')
    assert lines[4].startswith('Newton ') and 'ms per step' in lines[4]
    assert lines[5].startswith('nonlinear validity indicator ') and 'element rotation' in lines[5]
    assert 'against its chord' in lines[5]


@pytest.mark.parametrize('extra, message', [(('--method', 'modal', '--modes', '4'), 'full'),
                                            (('--second-order', 'dynamic'), 'second-order')])
def test_flags_without_meaning_are_refused(capsys, extra, message):
    code, out, err = _run(capsys, *SMALL, *extra)
    assert code == 1 and out == ''
    assert err.startswith('flexlink simulate: error: ') and message in err
