"""Beam charts (report/beam.py) from small computed tables of the Kim & Moon beam."""

from flexlink_ros.core.tmm import beams
from flexlink_ros.report import beam as beam_report
from flexlink_ros.studies import beam_check
from png_checks import has_colour, png_size
import pytest

BEAM = beams.UniformBeam.kim_moon()


@pytest.fixture(scope='module')
def errors():
    return beam_check.error_table(BEAM, segment_counts=(2, 4, 8, 12, 16))


def _method_colours(path):
    return {method: has_colour(path, style[1])
            for method, style in beam_report.METHOD_STYLE.items()}


def test_error_chart_draws_every_method(errors, tmp_path):
    path = beam_report.plot_errors(errors, BEAM, tmp_path / 'errors.png')
    assert png_size(path)[0] > 500
    assert all(_method_colours(path).values()), _method_colours(path)


def test_frequency_chart_draws_every_method(tmp_path):
    table = beam_check.frequency_table(BEAM, max_segments=6)
    path = beam_report.plot_frequencies(table, BEAM, tmp_path / 'frequencies.png',
                                        max_segments=6)
    assert png_size(path)[0] > 500
    assert all(_method_colours(path).values()), _method_colours(path)


def test_speed_chart_draws_every_method(tmp_path):
    table = beam_check.timing_table(BEAM, segment_counts=(6, 12), repeats=1, modes=1)
    path = beam_report.plot_speed(table, tmp_path / 'speed.png')
    assert png_size(path)[0] > 500
    assert all(_method_colours(path).values()), _method_colours(path)


def test_iteration_chart_renders(tmp_path):
    table = beam_check.iteration_table(BEAM)
    path = beam_report.plot_iterations(table, tmp_path / 'iterations.png')
    width, height = png_size(path)
    assert width > 500 and height > 300
