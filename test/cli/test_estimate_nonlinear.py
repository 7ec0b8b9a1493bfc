"""``flexlink estimate --nonlinear`` (cli/estimate_nonlinear.py): the real linkage, 2 elements."""

import dataclasses
import json
import math

from flexlink_ros.cli import main as cli
from flexlink_ros.cli.estimate_nonlinear import choose_nonlinear
from flexlink_ros.core.fe.linkage import FlexibleLinkage
from flexlink_ros.core.fe.nonlinear_response import nonlinear_response
from flexlink_ros.core.mechanism_file import load_mechanism
from flexlink_ros.core.options import ModelOptions
import numpy as np


def test_auto_chooses_the_nonlinear_model_only_where_the_linear_one_is_not_valid():
    valid = {'indicator_max': 0.1, 'valid': True, 'threshold': 0.5}
    invalid = {'indicator_max': 56.0, 'valid': False, 'threshold': 0.5}
    unknown = {'indicator_max': None, 'valid': None, 'threshold': 0.5}
    assert choose_nonlinear('auto', valid)[0] is False
    use, why = choose_nonlinear('auto', invalid)
    assert use is True and '56' in why and 'not valid' in why
    assert choose_nonlinear('auto', unknown)[0] is False
    assert choose_nonlinear('on', valid)[0] is True
    assert choose_nonlinear('off', invalid)[0] is False


def test_estimate_nonlinear_on_follows_the_nonlinear_full_order(tmp_path, capsys):
    rpm = 391.0
    code = cli.main(['estimate', '--rpm', str(rpm), '--rigid-crank', '--bearings', 'flexible',
                     '--elements-per-link', '2', '--stiffness-damping', '1e-4',
                     '--nonlinear', 'on', '--seconds', '2.5', '--json',
                     '--cache-dir', str(tmp_path)])
    assert code in (0, None)
    result = json.loads(capsys.readouterr().out)
    assert result['model_choice'] == {'nonlinear': True, 'why': 'asked for (--nonlinear on)'}
    assert result['nonlinear']['refused_samples'] == 0
    mech = dataclasses.replace(load_mechanism('cho1992'), elements_per_link=2)
    model = FlexibleLinkage(mech, ModelOptions.full_model(rigid_crank=True, bearings='flexible'))
    speed = rpm * math.pi / 30.0
    reference = nonlinear_response(model, speed, steps=720, points=720, zeta=0.0, beta=1e-4)
    angles = np.radians(result['crank_deg'])
    mine = np.column_stack([result['lever_tip']['dx_m'], result['lever_tip']['dy_m'],
                            result['coupler_mid']['dx_m'], result['coupler_mid']['dy_m']])
    grid = np.mod(reference.crank_angle, 2 * math.pi)
    ref = np.column_stack([np.interp(angles, grid, reference.outputs[:, c], period=2 * math.pi)
                           for c in range(4)])
    for points in (slice(0, 2), slice(2, 4)):
        error = math.sqrt(((mine[:, points] - ref[:, points]) ** 2).sum(axis=1).mean()
                          / (ref[:, points] ** 2).sum(axis=1).mean())
        assert error < 0.03, error
    # the linear estimate is kept beside it, and differs at this speed
    linear = np.array(result['linear']['coupler_mid']['dx_m'])
    assert linear.shape == mine[:, 2].shape and np.abs(linear - mine[:, 2]).max() > 1e-4
