"""The configurations timed side by side, and their chart (benchmarks/estimator_bench.py)."""

import dataclasses
import itertools
import math

import estimator_bench
from flexlink_ros.core.mechanism_file import load_mechanism
from flexlink_ros.core.options import ModelOptions
from flexlink_ros.core.reduction import mechanism_model
from flexlink_ros.core.reduction import reference as reduction_reference
from flexlink_ros.studies.synthetic import synthetic_signal
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.colors import to_rgba
import pytest
from toy_system import toy_model, toy_reference

# A bench's configurations as they come: a few us apart, errors within a decade, long labels.
CROWDED = [
    {'label': 'default', 'default': True, 'us_per_sample': 6.1,
     'error_coupler_mid': 4.1e-3, 'error_lever_tip': 2.2e-3},
    {'label': '20 modes + 2 static', 'us_per_sample': 5.2,
     'error_coupler_mid': 9.5e-3, 'error_lever_tip': 6.0e-3},
    {'label': '28 modes + 2 static', 'us_per_sample': 7.4,
     'error_coupler_mid': 4.0e-3, 'error_lever_tip': 2.1e-3},
    {'label': 'no static', 'us_per_sample': 5.9,
     'error_coupler_mid': 4.3e-3, 'error_lever_tip': 2.4e-3},
    {'label': 'grid 64', 'us_per_sample': 6.0,
     'error_coupler_mid': 1.2e-2, 'error_lever_tip': 8.0e-3},
    {'label': 'grid 256', 'us_per_sample': 6.2,
     'error_coupler_mid': 4.1e-3, 'error_lever_tip': 2.2e-3},
]


@pytest.fixture
def toy(monkeypatch):
    monkeypatch.setattr(mechanism_model, 'model_for_mechanism', toy_model)
    monkeypatch.setattr(reduction_reference, 'reference_response', toy_reference)
    monkeypatch.setattr(estimator_bench, 'reference_cpu_per_second', lambda *args: 1.0)


def test_bench_table_and_chart(toy, tmp_path):
    linear = ModelOptions.linear
    configurations = [('default', linear(modes=4, static=2, grid_size=32)),
                      ('small', linear(modes=2, static=0, grid_size=32))]
    calls = []
    result = estimator_bench.run_bench(None, None, seconds=0.3, configurations=configurations,
                                       progress=lambda *call: calls.append(call),
                                       nonlinear=False)
    rows = result['configurations']
    # every step reported before it runs, counted up to the total: 2 builds, 3 timing
    # rounds, 2 error rows, the full-order CPU, then the end
    assert [done for done, _, _ in calls] == list(range(9))
    assert {total for _, total, _ in calls} == {8} and calls[-1][2] == 'done'
    assert [what for _, _, what in calls[:3]] == ['building default', 'building small',
                                                  'timing round 1 of 3']
    estimator_bench.plot_error_vs_cost(rows, tmp_path / 'chart.png')
    assert [row['label'] for row in rows] == ['default', 'small']
    assert rows[0]['default'] and rows[0]['offline_samples_per_s'] > 0
    assert rows[0]['error_coupler_mid'] < rows[1]['error_coupler_mid']
    assert (tmp_path / 'chart.png').read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'
    assert result['cpu_ratio'] > 0
    # the numpy step timed beside the compiled one; each target judged from the figures
    assert result['numpy_step']['us_per_sample'] > 0
    assert result['numpy_step']['offline_samples_per_s'] > 0
    targets = {t['name']: t for t in result['targets']}
    assert targets['update median']['met'] == (rows[0]['us_per_sample'] <= 10.0)
    assert targets['offline']['met'] == (rows[0]['offline_samples_per_s'] >= 100_000.0)
    assert targets['CPU vs full order at 1 kHz']['met'] == (result['cpu_ratio'] >= 100.0)
    lines = estimator_bench.bench_lines(result)
    assert lines[1].startswith('default ') and lines[2].startswith('small ')
    assert lines[3].startswith('default, numpy step')


def test_targets_are_judged_from_the_default_configuration():
    fast = {'us_per_sample': 10.0, 'offline_samples_per_s': 100_000.0}
    slow = {'us_per_sample': 10.5, 'offline_samples_per_s': 99_999.0}
    met = estimator_bench.bench_targets({'configurations': [fast, slow], 'cpu_ratio': 100.0})
    assert [t['name'] for t in met] == ['update median', 'offline', 'CPU vs full order at 1 kHz']
    assert all(t['met'] for t in met)
    missed = estimator_bench.bench_targets({'configurations': [slow, fast], 'cpu_ratio': None})
    assert not any(t['met'] for t in missed)
    assert missed[0]['value'] == 10.5 and missed[1]['unit'] == 'samples/s'


def test_the_nonlinear_model_is_timed_against_the_linear_update_in_the_same_rounds():
    mechanism = dataclasses.replace(load_mechanism('cho1992'), elements_per_link=2)
    options = ModelOptions.linear(bearings='flexible', grid_size=32, elements_per_link=2)
    model = mechanism_model.model_for_mechanism(mechanism, options)
    timing = estimator_bench.nonlinear_timing(mechanism, options, model,
                                              synthetic_signal(391.0, 0.3, 1000.0), rounds=2)
    assert timing['refused'] == 0 and timing['newton_per_sample'] >= 1.0
    assert timing['ratio'] == timing['us_per_sample'] / timing['linear_us_per_sample']
    assert 0.0 < timing['us_per_sample'] <= timing['us_per_sample_p99']
    assert timing['offline_samples_per_s'] > 0 and timing['size'] > 0
    assert timing['damping'].startswith('beta')
    targets = {t['name']: t for t in estimator_bench.bench_targets(
        {'configurations': [{'us_per_sample': 5.0, 'offline_samples_per_s': 1e5}],
         'cpu_ratio': 100.0, 'nonlinear': timing})}
    assert targets['nonlinear update vs linear']['met'] == (timing['ratio'] <= 10.0)
    assert targets['nonlinear offline']['met'] == (timing['offline_samples_per_s'] >= 1e4)
    assert not math.isnan(targets['nonlinear update vs linear']['value'])


def visible_texts(figure):
    """Draw ``figure``; the window extents of its visible, non-empty texts."""
    canvas = FigureCanvasAgg(figure)
    canvas.draw()
    renderer = canvas.get_renderer()
    hidden = set()      # tick labels of ticks outside the view: set up but not drawn
    for axes in figure.axes:
        for axis in (axes.xaxis, axes.yaxis):
            low, high = sorted(axis.get_view_interval())
            for tick in axis.get_major_ticks() + axis.get_minor_ticks():
                if not low <= tick.get_loc() <= high:
                    hidden.update((id(tick.label1), id(tick.label2)))
    texts = [t for t in figure.findobj(match=lambda a: hasattr(a, 'get_text')
                                       and hasattr(a, 'get_window_extent'))
             if t.get_visible() and t.get_text().strip() and id(t) not in hidden]
    # findobj may reach a text twice (the legend keeps its texts in two containers)
    boxes = {}
    for text in texts:
        box = text.get_window_extent(renderer)
        boxes[text.get_text(), round(box.x0), round(box.y0)] = box
    return [(key[0], box) for key, box in boxes.items()]


def test_error_vs_cost_names_every_configuration_once_with_no_text_overlapping_or_clipped():
    figure = estimator_bench.error_vs_cost_figure(CROWDED, tolerance=0.01)
    texts = visible_texts(figure)
    width, height = figure.canvas.get_width_height()
    for text, box in texts:
        assert box.x0 >= 0 and box.y0 >= 0 and box.x1 <= width and box.y1 <= height, text
    for (first, a), (second, b) in itertools.combinations(texts, 2):
        assert not a.overlaps(b), (first, second)
    labels = [text for text, _ in texts]
    for config in CROWDED:
        assert labels.count(config['label']) == 1, config['label']
    assert 'tolerance 0.01' in labels


def _marker_colours(figure):
    """Return the face colours (RGBA tuples) of every scatter marker drawn in ``figure``."""
    return {tuple(colour) for axes in figure.axes for collection in axes.collections
            for colour in collection.get_facecolor()}


def test_error_vs_cost_marks_the_default(tmp_path):
    marked = estimator_bench.error_vs_cost_figure(CROWDED[:2], tolerance=0.01)
    assert to_rgba('tab:red') in _marker_colours(marked)
    assert to_rgba('tab:blue') in _marker_colours(marked)
    plain = estimator_bench.error_vs_cost_figure(CROWDED[1:2])
    assert to_rgba('tab:red') not in _marker_colours(plain)     # no default: no red star
    path = estimator_bench.plot_error_vs_cost(CROWDED, tmp_path / 'cost.png', tolerance=0.01)
    assert path.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'
