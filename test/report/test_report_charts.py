"""Charts checked for what a reader sees: names as the node uses them, no overlapping text."""

import itertools

from flexlink_ros.names import JOINT_NAMES
from flexlink_ros.report import criteria
from flexlink_ros.report.estimator import error_vs_cost_figure, plot_error_vs_cost
from matplotlib.backends.backend_agg import FigureCanvasAgg

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
    figure = error_vs_cost_figure(CROWDED, tolerance=0.01)
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


def test_error_vs_cost_png(tmp_path):
    path = plot_error_vs_cost(CROWDED, tmp_path / 'chart.png')
    assert path.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'


def test_criteria_charts_name_the_joints_as_the_node_does():
    assert tuple(criteria.JOINT_TITLE) == JOINT_NAMES
    for name, title in criteria.JOINT_TITLE.items():
        assert title.split(' ')[0] == name
    assert [criteria.JOINT_TITLE[j].split('joint ')[-1][0] for j in ('A', 'B', 'O4')] == \
        ['1', '2', '3']
