"""The Exudyn model of the peer (studies/peer_model.py): its checks and joint conventions."""

from flexlink_ros.core.kinematics import solve_kinematics
from flexlink_ros.core.mechanism_file import load_mechanism
from flexlink_ros.errors import FlexlinkError
from flexlink_ros.studies import peer_exudyn as peer
from flexlink_ros.studies import peer_model
from flexlink_ros.studies.peer_model import build_peer, solver_settings
import numpy as np
import pytest

needs_exudyn = pytest.mark.skipif(
    not peer_model.exudyn_available(),
    reason=f'exudyn is not installed (pip install {peer.EXUDYN_REQUIREMENT}, '
           'requirements-test.txt)')

ELEMENTS = 4


@pytest.fixture(scope='module')
def mech():
    return load_mechanism('cho1992')


def test_missing_exudyn_raises_flexlink_error(monkeypatch):
    # exudyn is imported once, at the top of peer_model: simulate a failed import there
    monkeypatch.setattr(peer_model, 'exudyn', None)
    monkeypatch.setattr(peer_model, 'EXUDYN_IMPORT_ERROR', "No module named 'exudyn'")
    with pytest.raises(FlexlinkError, match='exudyn'):
        build_peer('cho1992', 269.0)
    with pytest.raises(FlexlinkError, match='exudyn'):
        peer.peer_static('cho1992')


@needs_exudyn
@pytest.mark.parametrize('kwargs', [{'bearings': 'loose'}, {'mass_placement': 'lever'},
                                    {'elements_per_link': 0}, {'beta_s': -1.0}])
def test_bad_arguments(mech, kwargs):
    with pytest.raises(ValueError):
        build_peer(mech, 269.0, **kwargs)


@needs_exudyn
def test_joints_follow_the_package_conventions(mech):
    """Crank pin A on its circle (counter-clockwise from O2->O4), B shared, O4 fixed."""
    import exudyn

    rpm, theta0 = 269.0, 0.7
    model = build_peer(mech, rpm, elements_per_link=ELEMENTS, start_angle=theta0)
    end = 0.3 * 60.0 / rpm   # 0.3 revolution
    settings = solver_settings(exudyn, end, 216, 0.9, end)
    assert exudyn.SolveDynamic(model.mbs, settings)

    def where(node):
        return complex(*model.mbs.GetNodeOutput(node, exudyn.OutputVariableType.Position)[:2])
    theta = theta0 + model.omega * end
    rigid = solve_kinematics(mech, np.array([theta]))
    assert abs(where(model.nodes[1][0]) - rigid.joints['A'][0]) < 1e-9
    assert abs(where(model.nodes[1][-1]) - where(model.nodes[2][-1])) < 1e-9
    assert abs(where(model.nodes[2][0]) - mech.ground_length) < 1e-9
    # the elastic deflection of B stays in micrometres: the peer runs on the open branch
    assert abs(where(model.nodes[2][-1]) - rigid.joints['B'][0]) < 1e-4
