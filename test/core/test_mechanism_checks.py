"""Mechanism-file checks (core/mechanism_checks.py): unit slips refused, misspelt keys named."""

import copy
import dataclasses
import math
import pathlib
import re

from flexlink_ros.core import mechanism_checks
from flexlink_ros.core.mechanism_file import load_mechanism, mechanism_from_dict
from flexlink_ros.core.options import ModelOptions
from flexlink_ros.core.reduction import mechanism_model
from flexlink_ros.errors import MechanismError
import pytest
import yaml

DATA = pathlib.Path(__file__).resolve().parents[1] / 'data'
LINKAGES = ('packaging_steel', 'soft_aluminium')


def file_data(name):
    """Return the parsed mechanism file of test/data/<name>.yaml."""
    return yaml.safe_load((DATA / f'{name}.yaml').read_text())


def refusal(data):
    """Return the one-line refusal of a mechanism mapping."""
    with pytest.raises(MechanismError) as info:
        mechanism_from_dict(data)
    text = str(info.value)
    assert '\n' not in text
    return text


@pytest.mark.parametrize('name', LINKAGES + ('cho1992', 'kang1990'))
def test_real_linkages_load(name):
    mechanism = load_mechanism(DATA / f'{name}.yaml' if name in LINKAGES else name)
    assert mechanism.name == name


@pytest.mark.parametrize('name', LINKAGES)
def test_one_length_in_mm_in_a_file_names_its_key_not_the_grashof_sum(name):
    """One link in mm in a file: the loader's crank-rocker check spoke first, of a 60 m sum."""
    data = file_data(name)
    data['links']['coupler']['length_m'] *= 1000.0
    text = refusal(data)
    assert re.match(r'links\.coupler\.length_m = \d+: metres expected, was this mm\?', text), \
        text


@pytest.mark.parametrize('name', LINKAGES)
def test_lengths_in_mm_are_refused_naming_the_key_and_the_cause(name):
    data = file_data(name)
    data['ground_length_m'] *= 1000.0
    for link in data['links'].values():
        link['length_m'] *= 1000.0
    text = refusal(data)
    assert re.match(r'ground_length_m = \d+: metres expected, was this mm\?', text), text
    data = file_data(name)
    data['links']['coupler']['length_m'] = 250.0
    data['ground_length_m'] = 240.0
    data['links']['lever']['length_m'] = 180.0
    assert refusal(data).startswith('ground_length_m = 240: metres expected, was this mm?')


def test_the_issues_example_names_the_coupler():
    mechanism = load_mechanism(DATA / 'packaging_steel.yaml')
    crank, coupler, lever = mechanism.links
    wrong = dataclasses.replace(mechanism, links=(
        crank, dataclasses.replace(coupler, length=250.0), lever))
    with pytest.raises(MechanismError) as info:
        mechanism_checks.check_plausible(wrong)
    assert str(info.value) == 'links.coupler.length_m = 250: metres expected, was this mm?'


@pytest.mark.parametrize('name', LINKAGES)
def test_sections_in_mm2_and_mm4_are_refused(name):
    data = file_data(name)
    for link in data['links'].values():
        link['area_m2'] *= 1e6
        link['second_moment_m4'] *= 1e12
    text = refusal(data)
    assert text.startswith('links.crank.second_moment_m4 = ')
    assert 'radius of gyration' in text and 'mm^2 and mm^4' in text
    # one of the two in mm: the shape factor I/A^2 is a million or a trillion off
    data = file_data(name)
    data['links']['coupler']['second_moment_m4'] *= 1e12
    assert re.match(r'links\.coupler\.second_moment_m4 = \S+: I/A\^2 = .* was this mm\^4\?',
                    refusal(data))
    data = file_data(name)
    data['links']['lever']['area_m2'] *= 1e6
    assert re.match(r'links\.lever\.area_m2 = \S+: I/A\^2 = .* was this mm\^2\?', refusal(data))


@pytest.mark.parametrize('key, value, expected', [
    ('youngs_modulus_pa', 210000.0, 'material.youngs_modulus_pa = 210000: Pa expected, was '
     'this MPa or GPa'),
    ('youngs_modulus_pa', 210.0, 'material.youngs_modulus_pa = 210: Pa expected, was this MPa '
     'or GPa'),
    ('density_kg_m3', 7.85, 'material.density_kg_m3 = 7.85: kg/m^3 expected, was this g/cm^3'),
])
def test_material_in_other_units_is_refused(key, value, expected):
    data = file_data('packaging_steel')
    data['material'][key] = value
    assert refusal(data).startswith(expected)


def test_joint_masses_in_grams_bearings_and_gravity_are_refused():
    data = file_data('packaging_steel')
    data['joint_masses_kg']['B'] = 20.0       # 20 g written as 20
    assert refusal(data).startswith('joint_masses_kg.B = 20: ')
    assert 'was this g?' in refusal(data)
    data = file_data('packaging_steel')
    data['bearings']['stiffness_n_m'] = 5.0
    assert refusal(data).startswith('bearings.stiffness_n_m = 5: N/m expected')
    data = file_data('packaging_steel')
    data['gravity_m_s2'] = [0.0, -9810.0]
    assert 'was this mm/s^2?' in refusal(data)
    data = file_data('packaging_steel')
    data['links']['coupler'] = {'length_m': 0.25, 'mass_kg': 0.24, 'inertia_kg_m2': 1250.0}
    assert refusal(data).startswith('links.coupler.inertia_kg_m2 = 1250: ')


@pytest.mark.parametrize('section, key, expected', [
    ('bearings', 'stifness_n_m', 'bearings.stifness_n_m: unknown key (did you mean '
     "'stiffness_n_m'?"),
    ('', 'ground_length', "ground_length: unknown key (did you mean 'ground_length_m'?"),
    ('material', 'youngs_modulus', 'material.youngs_modulus: unknown key (did you mean '
     "'youngs_modulus_pa'?"),
])
def test_a_misspelt_key_names_the_closest_one(section, key, expected):
    data = file_data('packaging_steel')
    target = data[section] if section else data
    right = {'stifness_n_m': 'stiffness_n_m', 'ground_length': 'ground_length_m',
             'youngs_modulus': 'youngs_modulus_pa'}[key]
    target[key] = target.pop(right)
    assert refusal(data).startswith(expected)


def test_a_key_far_from_any_has_no_suggestion():
    data = copy.deepcopy(file_data('packaging_steel'))
    data['colour'] = 'blue'
    text = refusal(data)
    assert text.startswith('colour: unknown key (allowed: ') and 'did you mean' not in text


def test_a_first_frozen_frequency_that_is_not_positive_is_refused():
    with pytest.raises(MechanismError, match=r'first frozen frequency at crank angle 90\.0 deg '
                       r'is 0 Hz, not positive'):
        mechanism_checks.check_first_frequency(0.0, math.pi / 2)
    mechanism_checks.check_first_frequency(1e-3, 0.0)


def test_the_model_build_refuses_a_structure_without_stiffness(tmp_path):
    # A file that passes the load checks cannot make the frozen structure singular; a
    # Mechanism made in code can (zero modulus): the build says so instead of 0 Hz modes.
    mechanism = load_mechanism(DATA / 'soft_aluminium.yaml')
    floppy = dataclasses.replace(mechanism, youngs_modulus=0.0)
    options = ModelOptions.linear(grid_size=8, modes=2, static=0, geometric_stiffness=False)
    with pytest.raises(MechanismError, match='first frozen frequency'):
        mechanism_model.model_for_mechanism(floppy, options, use_cache=False)


def test_a_speed_range_where_the_links_buckle_is_refused_with_the_speed():
    # Cho 1992's strips lose their first frozen frequency to the axial forces near 800 rpm:
    # that speed range was an SVD failure; it is now one line naming the speed.
    options = ModelOptions.linear(grid_size=16, modes=2, static=0, elements_per_link=2,
                                  speed_max=812.0 * math.pi / 30.0)
    with pytest.raises(MechanismError, match=r'and 812 rpm is 0 Hz: the links buckle under '
                       r'their axial forces at that speed; lower the speed range'):
        mechanism_model.model_for_mechanism(load_mechanism('cho1992'), options, use_cache=False)
