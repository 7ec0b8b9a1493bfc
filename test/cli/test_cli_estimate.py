"""flexlink estimate / plan, on the synthetic system of toy_system.py."""

import dataclasses
import json
import math
import subprocess
import sys

from flexlink_ros.cli import main as cli
from flexlink_ros.cli.model_args import BUILD_LABEL
from flexlink_ros.cli.plan_table import plan_table
from flexlink_ros.core import options as core_options, validity
from flexlink_ros.core.mechanism_file import load_mechanism
from flexlink_ros.core.numerics import relative_rms, RPM
from flexlink_ros.core.reduction import mechanism_model
from flexlink_ros.core.reduction import reference as reduction_reference
from flexlink_ros.report.estimator import plot_estimate
from flexlink_ros.ros import parameters as node_params
from flexlink_ros.studies import plan, synthetic
import numpy as np
import pytest
from toy_system import toy_model, toy_reference


@pytest.fixture
def toy(monkeypatch):
    monkeypatch.setattr(mechanism_model, 'model_for_mechanism', toy_model)
    monkeypatch.setattr(reduction_reference, 'reference_response', toy_reference)


def test_synthetic_signal_and_last_revolution():
    stamps, angles, speeds = synthetic.synthetic_signal(391.0, 1.0, 1000.0, jitter=0.3)
    steps = np.diff(stamps) * 1e-9
    assert np.all(steps > 0.7e-3 - 1e-9) and np.all(steps < 1.3e-3 + 1e-9)
    np.testing.assert_allclose(angles, 391.0 * RPM * stamps * 1e-9)
    mask = synthetic.last_revolution(stamps, 391.0)
    swept = (angles[mask][-1] - angles[mask][0]) * 180 / math.pi
    assert 358.0 < swept <= 360.0


def test_estimate_json(toy, capsys):
    code = cli.main(['estimate', '--rpm', '391', '--seconds', '0.5', '--rate-hz', '1000',
                     '--jitter', '0.3', '--grid-size', '32', '--json'])
    assert code == 0
    result = json.loads(capsys.readouterr().out)
    assert set(result) >= {'crank_deg', 'lever_tip', 'coupler_mid', 'us_per_sample_median'}
    degrees = np.array(result['crank_deg'])
    assert len(degrees) > 100 and np.all((degrees >= 0) & (degrees < 360))
    assert len(result['lever_tip']['dx_m']) == len(degrees)
    assert result['us_per_sample_median'] > 0.0


def test_estimate_matches_the_reference_over_the_last_revolution(toy):
    for jitter in (0.0, 0.3):
        model = toy_model(None, core_options.ModelOptions.linear(modes=4, static=2, grid_size=32))
        result = synthetic.run_estimate(model, 391.0, seconds=0.4, jitter=jitter)
        angles = np.radians(result['crank_deg'])
        ref = toy_reference(None, None, 391.0 * RPM, angles)
        for key in ('lever_tip', 'coupler_mid'):
            estimate = np.column_stack([result[key]['dx_m'], result[key]['dy_m']])
            assert relative_rms(estimate, ref[key]) < 0.01


def test_plan_picks_the_first_candidate_within_tolerance(toy, monkeypatch):
    monkeypatch.setattr(plan, 'plan_candidates', lambda base, grids=None: [
        core_options.ModelOptions.linear(modes=1, static=0, grid_size=32),
        core_options.ModelOptions.linear(modes=4, static=2, grid_size=32),
        core_options.ModelOptions.linear(modes=6, static=3, grid_size=32)])
    base = core_options.ModelOptions.linear()
    result = plan.run_plan(None, base, 391.0, 0.01, physics=[base], scene=base)
    assert result['choice'] is not None and result['choice']['options']['modes'] == 4
    # the physics stage builds the generous size (the last candidate); the size stage
    # bisects the smaller ones, listed from small to large
    stages = [row['stage'] for row in result['alternatives']]
    assert stages == ['physics', 'size', 'size']
    assert result['alternatives'][0]['options']['modes'] == 6
    first = result['alternatives'][1]
    assert first['options']['modes'] == 1 and not first['meets_tolerance']
    assert first['error_coupler_mid'] > 0.01 or first['error_lever_tip'] > 0.01
    assert all(row['us_per_sample'] > 0 for row in result['alternatives'])
    assert result['alternatives'][0]['physics_error_coupler_mid'] == 0.0
    assert 'choice: ' in plan_table(result)
    # every built size tried its soft basis sizes cheapest first, up to the first in budget
    for row in result['alternatives']:
        tried = row['soft_tried']
        assert [t['step_size'] for t in tried] == sorted(t['step_size'] for t in tried)
        within = [max(t['error_coupler_mid'], t['error_lever_tip']) <= 0.01 for t in tried]
        if any(within):
            assert within.index(True) == len(tried) - 1
            assert row['soft_modes'] == row['options']['soft_modes'] == tried[-1]['soft_modes']
        else:     # every gap and all r coordinates tried; the most accurate kept
            assert tried[-1]['soft_modes'] == 0 and tried[-1]['step_size'] == row['size']
        assert row['error_coupler_mid'] in [t['error_coupler_mid'] for t in tried]


def test_plan_on_cho1992_compares_every_physics_with_the_scene(config_dir, monkeypatch):
    """
    Plan Cho 1992 with rigid bearings at 391 rpm.

    Reduced cost: a 4-element scene, three physics candidates, three sizes. Measured: the
    3-element physics error is 0.62 % (coupler) / 0.67 % (lever); without geometric
    stiffness the coupler moves by 67 %; a rigid crank misses the lever tip (which only moves
    through the crank's bending: 99.7 %); the chosen 8 + 4 model is 0.20 % off its own full
    order on the coupler but 0.74 % off the scene.
    """
    mechanism = load_mechanism(config_dir / 'cho1992.yaml')
    sizes = [(4, 2, 64), (8, 4, 128), (16, 4, 128)]
    monkeypatch.setattr(plan, 'plan_candidates', lambda base, grids=None: [
        dataclasses.replace(base, modes=m, static=s, grid_size=g) for m, s, g in sizes])
    base = core_options.ModelOptions.linear(bearings='rigid', elements_per_link=4,
                                            speed_max=1.05 * 391.0 * RPM)
    scene = plan.scene_options(mechanism, base)
    physics = [dataclasses.replace(scene, elements_per_link=3, rigid_crank=True),
               dataclasses.replace(scene, elements_per_link=3, geometric_stiffness=False),
               dataclasses.replace(scene, elements_per_link=3)]
    result = plan.run_plan(mechanism, base, 391.0, 0.03, speeds_rpm=[391.0], physics=physics)
    reference = result['reference']['options']
    assert (reference['rigid_crank'], reference['geometric_stiffness'],
            reference['elements_per_link'], reference['bearings']) == (False, True, 4, 'rigid')
    rows = {(row['stage'], row['options']['rigid_crank'],
             row['options']['geometric_stiffness'],
             row['options']['modes'] if row['size'] else None): row
            for row in result['alternatives']}
    rigid_crank = rows['physics', True, True, None]
    no_geometric = rows['physics', False, False, None]
    chosen_physics = rows['physics', False, True, 16]
    assert rigid_crank['physics_error_lever_tip'] > 0.5 and not rigid_crank['meets_tolerance']
    assert no_geometric['physics_error_coupler_mid'] > 0.3
    assert no_geometric['physics_error_coupler_mid'] > \
        20.0 * chosen_physics['physics_error_coupler_mid']
    assert chosen_physics['physics_error_coupler_mid'] < 0.015
    choice = result['choice']
    assert choice is not None and choice['stage'] == 'size'
    assert (choice['options']['elements_per_link'], choice['options']['rigid_crank'],
            choice['options']['modes'], choice['options']['static']) == (3, False, 8, 4)
    assert choice['error_coupler_mid'] <= 0.03 and choice['error_lever_tip'] <= 0.03
    # its error is measured against the scene, not against its own full-order model
    assert choice['error_coupler_mid'] > 2.0 * choice['truncation_error_coupler_mid']
    smaller = rows['size', False, True, 4]
    assert not smaller['meets_tolerance']


def test_estimate_without_the_fe_model_fails_cleanly(capsys, tmp_path):
    code = cli.main(['estimate', '--rpm', '391', '--seconds', '0.1', '--cache-dir',
                     str(tmp_path)])
    captured = capsys.readouterr()
    if code == 0:  # the FE model is in this checkout
        assert 'lever tip' in captured.out
    else:
        assert code == 1 and 'estimate: error:' in captured.err


def test_plot_estimate(tmp_path):
    angles = np.linspace(0, 360, 50, endpoint=False)
    curve = np.column_stack([np.sin(np.radians(angles)), np.cos(np.radians(angles))]) * 1e-3
    path = plot_estimate(angles, {'lever_tip': curve, 'coupler_mid': curve},
                         {'lever_tip': curve * 1.01, 'coupler_mid': curve}, tmp_path / 'e.png')
    assert path.read_bytes()[:4] == b'\x89PNG'


def test_the_reports_default_model_is_the_nodes():
    assert core_options.ModelOptions() == node_params.default_model_options()


@pytest.mark.parametrize('flags, fixed', [
    ([], {}),
    (['--rigid-crank'], {'rigid_crank': True}),
    (['--flexible-crank', '--no-geometric-stiffness'],
     {'rigid_crank': False, 'geometric_stiffness': False})])
def test_plan_keeps_the_crank_and_geometric_stiffness_the_user_fixed(toy, monkeypatch, capsys,
                                                                     flags, fixed):
    monkeypatch.setattr(plan, 'plan_candidates', lambda base, grids=None: [
        dataclasses.replace(base, modes=m, static=s, grid_size=32) for m, s in ((1, 0), (4, 2))])
    code = cli.main(['plan', '--rpm-max', '391', '--bearings', 'rigid', '--json', *flags])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    result = json.loads(captured.out)       # one JSON object: progress went to stderr
    assert result['fixed'] == fixed
    # the reference stays the richest model of the scene whatever was fixed
    reference = result['reference']['options']
    assert (reference['rigid_crank'], reference['geometric_stiffness']) == (False, True)
    tried = {(row['options']['rigid_crank'], row['options']['geometric_stiffness'])
             for row in result['alternatives']}
    assert tried and all(all(dict(zip(('rigid_crank', 'geometric_stiffness'), physics))[k]
                             == v for k, v in fixed.items()) for physics in tried)
    if not fixed:   # free: both crank models screened (the toy's physics all agree)
        assert result['alternatives'][0]['options']['rigid_crank']
    # not a terminal: plain progress lines, the last at 100 %
    last = captured.err.strip().splitlines()[-1]
    assert last.startswith('plan: 100%') and 'step' in last


def test_plan_says_when_the_fixed_choices_leave_no_candidate(toy, monkeypatch, capsys):
    monkeypatch.setattr(plan, 'plan_candidates', lambda base, grids=None: [
        dataclasses.replace(base, modes=1, static=0, grid_size=32)])
    assert cli.main(['plan', '--rpm-max', '391', '--bearings', 'rigid', '--tolerance', '1e-9',
                     '--rigid-crank']) == 0
    out = capsys.readouterr().out
    assert 'fixed in every candidate: rigid crank yes' in out
    assert 'choice: none of the candidates meets the tolerance; leave out the fixed' in out


def test_estimate_json_says_whether_the_estimate_is_valid(capsys, tmp_path):
    """The real model (rigid crank and bearings, small): valid at 269 rpm, not at 405."""
    summaries = {}
    for rpm in ('269', '405'):
        code = cli.main(['estimate', '--rpm', rpm, '--seconds', '1.5', '--bearings', 'rigid',
                         '--rigid-crank', '--elements-per-link', '4', '--grid-size', '64',
                         '--cache-dir', str(tmp_path), '--json'])
        assert code == 0
        summaries[rpm] = json.loads(capsys.readouterr().out)['nonlinearity']
    assert summaries['269']['valid'] is True and summaries['405']['valid'] is False
    assert (summaries['269']['indicator_max'] < validity.VALIDITY_THRESHOLD
            < summaries['405']['indicator_max'])
    assert summaries['269']['threshold'] == validity.VALIDITY_THRESHOLD


def test_estimate_json_says_the_order_and_order_2_moves_the_lever_tip(capsys, tmp_path):
    # Cho 1992, rigid crank and bearings (the lever tip moves mostly by second order).
    common = ['estimate', '--rpm', '391', '--seconds', '0.4', '--rigid-crank', '--bearings',
              'rigid', '--grid-size', '32', '--cache-dir', str(tmp_path), '--json']
    runs = {}
    for order in (1, 2):
        assert cli.main(common + ['--order', str(order)]) == 0
        runs[order] = json.loads(capsys.readouterr().out)
        assert runs[order]['order'] == order
    p2p = {order: np.ptp(np.array(run['lever_tip']['dy_m'])) for order, run in runs.items()}
    assert p2p[2] > 3.0 * p2p[1]
    models = [p for p in tmp_path.glob('*.npz') if not p.stem.endswith(('-nonlinearity', '-soft'))]
    assert len(models) == 2       # one model per order


def test_estimate_shows_the_model_build_on_stderr_only_when_it_builds(tmp_path):
    command = [sys.executable, '-m', 'flexlink_ros.cli.main', 'estimate', '--rpm', '200',
               '--seconds', '0.2', '--grid-size', '32', '--json', '--cache-dir', str(tmp_path)]
    cold = subprocess.run(command, capture_output=True, text=True, timeout=300)
    assert cold.returncode == 0, cold.stderr
    assert json.loads(cold.stdout)['samples'] > 0            # stdout: the JSON alone
    lines = [line for line in cold.stderr.splitlines() if line.startswith(BUILD_LABEL)]
    assert len(lines) >= 2                                    # the start, then the end
    assert ' 100%' in lines[-1] and lines[-1].endswith('model built')
    assert ' 100%' not in lines[0]
    warm = subprocess.run(command, capture_output=True, text=True, timeout=300)
    assert warm.returncode == 0, warm.stderr
    assert json.loads(warm.stdout)['samples'] == json.loads(cold.stdout)['samples']
    assert BUILD_LABEL not in warm.stderr and '%' not in warm.stderr   # cached: silent


def test_estimate_soft_modes_flag_chooses_the_step_and_refuses_below_the_gap(capsys, tmp_path):
    # Cho 1992's rigid-crank scene with bearing springs (16 + 2), grid 32: one model file
    # the linear estimate's soft step is compared: --nonlinear off (auto would report the
    # nonlinear model's deflections at this speed)
    common = ['estimate', '--rpm', '391', '--seconds', '0.3', '--rigid-crank', '--grid-size',
              '32', '--cache-dir', str(tmp_path), '--json', '--nonlinear', 'off']
    runs = {}
    for soft_modes in ('-1', '0'):
        assert cli.main(common + ['--soft-modes', soft_modes]) == 0
        runs[soft_modes] = json.loads(capsys.readouterr().out)
    chosen = runs['-1']['soft']
    assert chosen['used'] and 0 < chosen['size'] < 18 and chosen['gap_ratio'] >= 3.0
    assert runs['0']['soft'] == {'used': False, 'reason': 'off'}
    # the same crank angles, different steps (at grid 32 the 18-coordinate step is 28 % off
    # the full order at 391 rpm, the soft one 0.4 %: soft_basis_study.steady_error)
    assert runs['-1']['crank_deg'] == runs['0']['crank_deg']
    assert runs['-1']['coupler_mid']['dx_m'] != runs['0']['coupler_mid']['dx_m']
    models = [p for p in tmp_path.glob('*.npz') if not p.stem.endswith(('-nonlinearity', '-soft'))]
    assert len(models) == 1
    # a size below the gap is refused, with the reason
    assert cli.main(common + ['--soft-modes', '2']) == 1
    assert 'no spectral gap after mode 2' in capsys.readouterr().err


def test_estimate_second_order_dynamic_has_its_model_and_moves_the_coupler(capsys, tmp_path):
    # Cho 1992, rigid crank and bearings, small: the dynamic pass is an opt-in of its own model
    common = ['estimate', '--rpm', '391', '--seconds', '0.5', '--rigid-crank', '--bearings',
              'rigid', '--grid-size', '32', '--elements-per-link', '3', '--cache-dir',
              str(tmp_path), '--json']
    runs = {}
    for flags in ([], ['--second-order', 'quasi-static'], ['--second-order', 'dynamic']):
        assert cli.main(common + flags) == 0
        runs[tuple(flags)] = json.loads(capsys.readouterr().out)
    quasi, dynamic = runs[()], runs[('--second-order', 'dynamic')]
    assert quasi['second_order'] == 'quasi-static' and dynamic['second_order'] == 'dynamic'
    assert runs[('--second-order', 'quasi-static')]['coupler_mid'] == quasi['coupler_mid']
    p2p = [np.ptp(np.array(run['coupler_mid']['dy_m'])) for run in (quasi, dynamic)]
    assert 1e-3 < abs(p2p[1] / p2p[0] - 1.0) < 0.2, p2p
    models = [p for p in tmp_path.glob('*.npz') if not p.stem.endswith(('-nonlinearity', '-soft'))]
    assert len(models) == 2       # quasi-static (the default key) and dynamic
    assert cli.main(common + ['--order', '1', '--second-order', 'dynamic']) == 1
    assert "'dynamic' needs `order` 2" in capsys.readouterr().err
