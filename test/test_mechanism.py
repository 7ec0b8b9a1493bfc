"""Mechanism files: the papers' data load, bad input is rejected naming the field."""

import math

import pytest
import yaml

from flexlink_ros.core.errors import MechanismError
from flexlink_ros.core.mechanism import load_mechanism, mechanism_from_dict


def _cho(config_dir):
    return yaml.safe_load((config_dir / 'cho1992.yaml').read_text())


def test_papers_tables_load():
    cho = load_mechanism('cho1992')
    assert cho.lengths == (0.238, 0.0785, 0.262, 0.240)
    assert cho.is_flexible
    assert cho.links[1].mass == pytest.approx(7718.0 * 0.14406e-4 * 0.262)
    assert cho.gravity == (0.0, -9.81)
    kang = load_mechanism('kang1990')
    assert not kang.is_flexible
    assert kang.links[1].inertia == pytest.approx(0.3406 * 0.1524 ** 2 / 12)
    assert kang.crank_speed == pytest.approx(900 * 2 * math.pi / 60)


@pytest.mark.parametrize('edit, field', [
    (lambda d: d['links']['coupler'].update(length_m=-0.2), 'links.coupler.length_m'),
    (lambda d: d['links']['crank'].update(area_m2=0.0), 'links.crank.area_m2'),
    (lambda d: d['material'].update(youngs_modulus_pa=-1.0), 'material.youngs_modulus_pa'),
    (lambda d: d['joint_masses_kg'].update(A=-0.01), 'joint_masses_kg.A'),
    (lambda d: d.update(colour='red'), 'colour'),
    (lambda d: d['links']['lever'].update(thickness=1.0), 'links.lever.thickness'),
    (lambda d: d['links'].pop('lever'), 'links.lever'),
    (lambda d: d.update(branch='sideways'), 'branch'),
    (lambda d: d.update(elements_per_link=0), 'elements_per_link'),
    (lambda d: d['bearings'].update(joints=['O2', 'Q']), 'bearings.joints'),
    (lambda d: d.update(gravity_m_s2=[0.0]), 'gravity_m_s2'),
])
def test_bad_fields_are_named(config_dir, edit, field):
    data = _cho(config_dir)
    edit(data)
    with pytest.raises(MechanismError) as info:
        mechanism_from_dict(data)
    assert info.value.field == field


def test_non_grashof_is_rejected_with_the_reason(config_dir):
    data = _cho(config_dir)
    data['links']['coupler']['length_m'] = 0.45  # s + l = 0.5285 > p + q = 0.478
    with pytest.raises(MechanismError, match='Grashof'):
        mechanism_from_dict(data)


def test_crank_must_be_shortest(config_dir):
    data = _cho(config_dir)
    data['links']['crank']['length_m'] = 0.25
    with pytest.raises(MechanismError, match='shorter than the crank'):
        mechanism_from_dict(data)


def test_change_point_is_rejected(config_dir):
    data = _cho(config_dir)
    # s + l = p + q exactly: 0.0785 + 0.262 = 0.238 + 0.1025
    data['links']['lever']['length_m'] = 0.1025
    with pytest.raises(MechanismError, match='change-point'):
        mechanism_from_dict(data)


def test_missing_file_is_a_clear_error():
    with pytest.raises(MechanismError, match='no such file'):
        load_mechanism('does_not_exist.yaml')


def test_key_changes_with_any_field():
    import dataclasses
    cho = load_mechanism('cho1992')
    assert cho.key() == load_mechanism('cho1992').key()
    assert cho.key() != dataclasses.replace(cho, damping_ratio=0.03).key()
