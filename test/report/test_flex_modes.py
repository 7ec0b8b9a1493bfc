"""Frozen-frequency and mode-shape charts (report/flex_modes.py) from small computed sweeps."""

import dataclasses

from flexlink_ros.core.mechanism_file import load_mechanism
from flexlink_ros.report import flex_modes
from flexlink_ros.studies import flex_data, flex_frequencies
import numpy as np
from png_checks import has_colour, png_size
import pytest


@pytest.fixture(scope='module')
def mechanism():
    return dataclasses.replace(load_mechanism('cho1992'), elements_per_link=2)


@pytest.fixture(scope='module')
def sweeps(mechanism):
    crank_deg = np.arange(0.0, 360.0, 30.0)
    return {key: flex_frequencies.sweep_case(mechanism, case, crank_deg, 3)
            for key, case in flex_frequencies.paper_frequency_cases().items()}


def test_fig7_draws_three_mode_curves(sweeps, tmp_path):
    path = flex_modes.plot_fig7(sweeps['flex'], tmp_path / 'fig7.png')
    assert path == tmp_path / 'fig7.png'
    assert png_size(path) == (8.0 * flex_modes.DPI, 4.8 * flex_modes.DPI)
    for colour in flex_modes.MODE_COLOURS[:3]:
        assert has_colour(path, colour), colour
    assert not has_colour(path, flex_modes.MODE_COLOURS[3])     # three modes only


@pytest.mark.parametrize('plot, colours', [
    (flex_modes.plot_fig8_10, ('tab:blue', 'tab:cyan', 'tab:red', 'tab:pink', 'grey')),
    (flex_modes.plot_fig11_13, ('tab:blue', 'tab:red', 'tab:purple'))])
def test_mode_panels_draw_every_case(sweeps, tmp_path, plot, colours):
    path = plot(sweeps, tmp_path / 'panels.png')
    assert png_size(path) == (13.0 * flex_modes.DPI, 4.4 * flex_modes.DPI)
    for colour in colours:
        assert has_colour(path, colour), colour


def test_mode_panels_leave_out_missing_cases(sweeps, tmp_path):
    only = {'rigid_crank_kg_30': sweeps['rigid_crank_kg_30']}
    path = flex_modes.plot_fig11_13(only, tmp_path / 'one.png')
    assert has_colour(path, 'tab:blue') and not has_colour(path, 'tab:purple')


def test_mode_shapes_draw_each_link(mechanism, tmp_path):
    shapes = flex_data._mode_shapes(mechanism, 27.0)
    path = flex_modes.plot_mode_shapes(shapes, 27.0, tmp_path / 'shapes.png')
    assert png_size(path) == (13.0 * flex_modes.DPI, 7.0 * flex_modes.DPI)
    for colour in flex_modes.LINK_COLOURS:
        assert has_colour(path, colour, pixels=200), colour
