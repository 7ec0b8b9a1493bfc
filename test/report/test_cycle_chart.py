"""cycle_chart: deflections and joint criteria over crank angle, for any mechanism."""

import json
import math
import pathlib
import subprocess
import sys

from flexlink_ros.cli import main as cli
from flexlink_ros.report.cycle_chart import JOINT_COLOURS, plot_cycle
import numpy as np
from png_checks import has_colour, png_size


def _revolutions(count=3, per_revolution=400):
    """Crank angles over ``count`` revolutions, deflections of tens of um, one NaN row."""
    angles = np.linspace(0.0, 2.0 * math.pi * count, count * per_revolution, endpoint=False)
    lever = np.column_stack([20e-6 * np.sin(angles), 5e-6 * np.cos(2.0 * angles)])
    coupler = np.column_stack([150e-6 * np.cos(angles), 90e-6 * np.sin(angles)])
    criterion = np.column_stack([10.0 + 5.0 * np.sin(angles + k) for k in range(4)]) ** 2
    lever[7] = math.nan          # a skipped sample: left out, not drawn as 0
    return angles, lever, coupler, criterion


def test_the_chart_draws_both_points_and_every_joint(tmp_path):
    angles, lever, coupler, criterion = _revolutions()
    path = plot_cycle(tmp_path / 'sub' / 'cycle.png', angles, lever, coupler, criterion,
                      title='soft linkage', thresholds=(100.0, 1000.0))
    assert png_size(path) == (1000, 900)
    assert has_colour(path, 'tab:blue') and has_colour(path, 'tab:orange')   # dx, dy
    for colour in JOINT_COLOURS:
        assert has_colour(path, colour)


def test_a_model_without_reactions_says_so_instead_of_an_empty_log_axis(tmp_path):
    angles, lever, coupler, _ = _revolutions(count=1)
    path = plot_cycle(tmp_path / 'none.png', angles, lever, coupler, None)
    assert png_size(path) == (1000, 900)
    assert not has_colour(path, 'tab:green') and not has_colour(path, 'tab:red')


def test_replay_and_estimate_do_not_import_matplotlib_until_they_draw():
    code = ('import sys, flexlink_ros.cli.replay, flexlink_ros.cli.estimate; '
            "print(sorted(m for m in sys.modules if m.startswith('matplotlib')))")
    result = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                            timeout=120)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == '[]'


def test_estimate_chart_of_a_linkage_not_in_config(capsys, tmp_path):
    soft = pathlib.Path(__file__).resolve().parents[1] / 'data' / 'soft_linkage.yaml'
    chart = tmp_path / 'soft.png'
    assert cli.main(['estimate', '--mechanism', str(soft), '--rpm', '300', '--seconds', '0.6',
                     '--grid-size', '32', '--cache-dir', str(tmp_path), '--chart', str(chart),
                     '--json']) == 0
    result = json.loads(capsys.readouterr().out)
    assert result['chart'] == str(chart) and png_size(chart) == (1000, 900)
    assert len(result['criterion']) == len(result['crank_deg']) > 100
    assert all(len(row) == 4 for row in result['criterion'])
    assert has_colour(chart, 'tab:red')      # joint O4's criterion is drawn
