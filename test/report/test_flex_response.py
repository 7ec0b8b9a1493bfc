"""Response and truncation charts (report/flex_response.py) from small computed responses."""

import dataclasses

from flexlink_ros.core.fe.linkage import FlexibleLinkage
from flexlink_ros.core.fe.simulate import periodic_response
from flexlink_ros.core.mechanism_file import load_mechanism
from flexlink_ros.core.numerics import RPM
from flexlink_ros.core.options import ModelOptions
from flexlink_ros.report import flex_response
from flexlink_ros.studies import flex_data, flex_truncation
from flexlink_ros.studies.flex_frequencies import BEARINGS, PAPER_RPM
from png_checks import has_colour, png_size
import pytest

DPI = flex_response.DPI


@pytest.fixture(scope='module')
def mechanism():
    return dataclasses.replace(load_mechanism('cho1992'), elements_per_link=2)


@pytest.fixture(scope='module')
def computed(mechanism):
    """Full-order responses and a three-count truncation study per bearings and speed."""
    responses, truncation = {}, {}
    for bearings in BEARINGS:
        model = FlexibleLinkage(mechanism, ModelOptions.full_model(rigid_crank=True,
                                                                   bearings=bearings))
        for rpm in PAPER_RPM:
            run = periodic_response(model, rpm * RPM, 'full', steps=120, points=30)
            responses[bearings, rpm] = run
            study = flex_truncation.truncation_study(model, rpm * RPM, [1, 2, model.size],
                                                     steps=120, points=30, reference=run)
            study['steps'] = 120
            truncation[bearings, rpm] = study
    return responses, truncation


def test_deflected_linkage_draws_the_quarter_turns(mechanism, tmp_path):
    linkage = flex_data._deflected_linkage(mechanism, 1)
    path = flex_response.plot_deflected_linkage(linkage, mechanism, tmp_path / 'linkage.png')
    assert png_size(path) == (12.0 * DPI, 9.0 * DPI)
    assert has_colour(path, 'black')             # the ground pivots


def test_exaggeration_is_a_round_factor_to_five_percent():
    assert flex_response._exaggeration([1.1e-3], 0.4) == 20      # raw 18.2
    assert flex_response._exaggeration([-1.1e-4], 0.4) == 200    # raw 182
    assert flex_response._exaggeration([3e-4], 0.4) == 100       # raw 66.7: next round one
    assert flex_response._exaggeration([0.0], 0.4) == 1000


def test_point_deflections_draw_x_and_y(computed, tmp_path):
    path = flex_response.plot_point_deflections(computed[0], [0, 1], 'Lever tip', 20,
                                                tmp_path / 'tip.png')
    assert png_size(path) == (11.0 * DPI, 7.0 * DPI)
    assert has_colour(path, 'tab:blue', pixels=200) and has_colour(path, 'tab:red', pixels=200)


def test_coupler_path_draws_both_bearing_models(computed, mechanism, tmp_path):
    path = flex_response.plot_coupler_path(computed[0], mechanism, tmp_path / 'path.png')
    assert png_size(path) == (12.0 * DPI, 9.5 * DPI)
    assert has_colour(path, 'tab:blue', pixels=200) and has_colour(path, 'tab:red', pixels=200)


def test_truncation_draws_errors_against_mode_counts(computed, tmp_path):
    path = flex_response.plot_truncation(computed[1], tmp_path / 'truncation.png')
    assert png_size(path) == (12.0 * DPI, 8.0 * DPI)
    assert has_colour(path, 'tab:blue', pixels=200) and has_colour(path, 'tab:red', pixels=200)
