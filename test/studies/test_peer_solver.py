"""Exudyn's solver run for the peer (studies/peer_solver.py): a failure is one line."""

import pathlib

from flexlink_ros.errors import FlexlinkError
from flexlink_ros.studies.peer_exudyn import peer_response
from flexlink_ros.studies.peer_model import exudyn_available
import pytest

DATA = pathlib.Path(__file__).resolve().parents[1] / 'data'


def stiff_springs_on_light_pins(folder):
    """Write the stiff steel linkage with 1e12 N/m bearing springs on 0.1 g pins; its path."""
    text = (DATA / 'packaging_steel.yaml').read_text()
    text = text.replace('stiffness_n_m: 5.0e+7', 'stiffness_n_m: 1.0e+12').replace(
        'O2: 0.02, A: 0.02, B: 0.02, O4: 0.02', 'O2: 0.0001, A: 0.0001, B: 0.0001, O4: 0.0001')
    assert '1.0e+12' in text and '0.0001' in text
    path = folder / 'stiff_springs_light_pins.yaml'
    path.write_text(text)
    return path


@pytest.mark.skipif(not exudyn_available(), reason='exudyn is not installed')
def test_a_solver_failure_is_one_flexlink_error_with_a_hint_and_no_banner(capfd, tmp_path):
    # The stiff steel linkage on bearing springs of 1e12 N/m with 0.1 g pins at 600 rpm, 8
    # elements per link: the peer's implicit steps diverge, also at 8 times the steps.
    with pytest.raises(FlexlinkError) as info:
        peer_response(str(stiff_springs_on_light_pins(tmp_path)), 600.0, elements_per_link=8,
                      bearings='springs', mass_placement='split', revolutions=1,
                      steps_per_revolution=720)
    text = str(info.value)
    assert '\n' not in text and text.startswith('the Exudyn peer failed at 600 rpm')
    assert '"DYNAMIC SOLVER FAILED"' in text and 'hint: ' in text
    assert '--bearings rigid' in text
    assert 'SOLVER FAILED' not in capfd.readouterr().out     # held back from stdout


@pytest.mark.skipif(not exudyn_available(), reason='exudyn is not installed')
def test_a_solve_that_succeeds_keeps_stdout_usable(capfd):
    out = peer_response(str(DATA / 'packaging_steel.yaml'), 600.0, elements_per_link=2,
                        bearings='rigid', revolutions=1, steps_per_revolution=120)
    assert out['lever_tip_dx'].size > 0
    print('still here')
    assert capfd.readouterr().out.endswith('still here\n')
