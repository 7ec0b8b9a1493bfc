"""Mechanism files: the papers' data load, bad input is rejected naming the field."""

import math
import os
import pathlib
import re
import subprocess
import sys
import tracemalloc

from flexlink_ros.core.mechanism import MAX_ELEMENTS_PER_LINK
from flexlink_ros.core.mechanism_file import (ament_share_directory, find_config,
                                              load_mechanism, MAX_FILE_BYTES, MAX_NAME_CHARS,
                                              MAX_SOURCE_CHARS, MAX_YAML_DEPTH,
                                              mechanism_from_dict, stiffness_damping_from_file)
from flexlink_ros.errors import MechanismError
from flexlink_ros.names import JOINT_NAMES, LINK_NAMES
import pytest
import yaml


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
    (lambda d: d.update(stiffness_damping_s=-1e-4), 'stiffness_damping_s'),
    (lambda d: d.update(stiffness_damping_s=2.0), 'stiffness_damping_s'),
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


# -- hostile files: every bound refuses with the field, quickly, without allocating --------

def _alias_bomb(levels=9, fan_out=9, indent=''):
    """YAML of about 1.5 kB whose aliases expand to 9**9 (387 million) strings when walked."""
    lines = [f'{indent}l0: &l0 ["{"lol" * 350}"]']
    for level in range(1, levels + 1):
        refs = ', '.join([f'*l{level - 1}'] * fan_out)
        lines.append(f'{indent}l{level}: &l{level} [{refs}]')
    return '\n'.join(lines) + '\n'


def _write(tmp_path, text, name='mechanism.yaml'):
    path = tmp_path / name
    path.write_text(text)
    return path


@pytest.mark.parametrize('where', ['top', 'source'])
def test_alias_bomb_is_refused_before_expansion(config_dir, tmp_path, where):
    cho = (config_dir / 'cho1992.yaml').read_text()
    if where == 'top':
        text = _alias_bomb() + cho
    else:   # the free-text field holds the bomb
        text = cho.replace('source: "Cho, Park & Lee (1992), KSME Trans. 16(x), Table 1"',
                           'source:\n' + _alias_bomb(indent='  '))
    assert 'source: "Cho' not in text or where == 'top'
    assert 1000 < len(_alias_bomb()) < 2000
    tracemalloc.start()
    try:
        with pytest.raises(MechanismError, match='aliases are not allowed') as info:
            load_mechanism(_write(tmp_path, text))
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert info.value.field == 'yaml'
    assert peak < 10 * MAX_FILE_BYTES


def test_oversized_file_is_refused_unread(config_dir, tmp_path):
    cho = (config_dir / 'cho1992.yaml').read_text()
    path = _write(tmp_path, cho + '#' * MAX_FILE_BYTES)
    with pytest.raises(MechanismError, match=f'larger than {MAX_FILE_BYTES} bytes'):
        load_mechanism(path)
    assert load_mechanism(_write(tmp_path, cho, 'plain.yaml')).name == 'cho1992'


def test_deep_nesting_is_refused(config_dir, tmp_path):
    text = 'name: ' + '[' * 20000 + ']' * 20000 + '\n'
    with pytest.raises(MechanismError, match=f'nested deeper than {MAX_YAML_DEPTH}'):
        load_mechanism(_write(tmp_path, text))


@pytest.mark.parametrize('edit, field, reason', [
    (lambda d: d.update(elements_per_link=MAX_ELEMENTS_PER_LINK + 1), 'elements_per_link',
     f'1..{MAX_ELEMENTS_PER_LINK}'),
    (lambda d: d.update(elements_per_link=10 ** 6), 'elements_per_link', '1..'),
    (lambda d: d.update(elements_per_link=2.5), 'elements_per_link', 'integer'),
    (lambda d: d.update(source='x' * (MAX_SOURCE_CHARS + 1)), 'source',
     f'at most {MAX_SOURCE_CHARS}'),
    (lambda d: d.update(name='n' * (MAX_NAME_CHARS + 1)), 'name', f'at most {MAX_NAME_CHARS}'),
    (lambda d: d.update(source=['a', 'b']), 'source', 'expected text'),
    (lambda d: d.update(ground_length_m=10 ** 400), 'ground_length_m', 'out of range'),
    (lambda d: d.update(gravity_m_s2=[10 ** 400, 0]), 'gravity_m_s2', 'out of range'),
    (lambda d: d['bearings'].update(joints=['A', 'A']), 'bearings.joints', 'twice'),
    (lambda d: d['bearings'].update(joints='A'), 'bearings.joints', 'list'),
    (lambda d: d.update({7: 'seven'}), '7', 'unknown key'),
])
def test_sizes_and_strings_are_bounded(config_dir, edit, field, reason):
    data = _cho(config_dir)
    edit(data)
    with pytest.raises(MechanismError, match=re.escape(reason)) as info:
        mechanism_from_dict(data)
    assert info.value.field == field


def test_modes_cli_refuses_a_million_elements_in_one_line(config_dir, tmp_path):
    cho = (config_dir / 'cho1992.yaml').read_text()
    path = _write(tmp_path, cho.replace('elements_per_link: 3', 'elements_per_link: 1000000'))
    assert 'elements_per_link: 1000000' in path.read_text()
    for extra in ([], ['--elements-per-link', '1000000']):
        mechanism = path if not extra else config_dir / 'cho1992.yaml'
        done = subprocess.run(
            [sys.executable, '-m', 'flexlink_ros.cli.main', 'modes', '--mechanism', str(mechanism),
             '--crank-deg', '0'] + extra, capture_output=True, text=True, timeout=120)
        assert done.returncode == 2, done.stderr     # a mechanism refused
        lines = done.stderr.strip().splitlines()
        assert len(lines) == 1, done.stderr
        assert 'elements_per_link' in lines[0] and f'1..{MAX_ELEMENTS_PER_LINK}' in lines[0]
        assert 'MemoryError' not in done.stderr and done.stdout == ''


# -- finding a bare name: ament prefixes, this Python's prefix, the source tree --------------

def _ament_prefix(root, name, with_marker=True, with_file=True):
    """Make an install prefix as colcon does: the package marker and share/<pkg>/config."""
    prefix = root / name
    if with_marker:
        marker = prefix / 'share' / 'ament_index' / 'resource_index' / 'packages'
        marker.mkdir(parents=True)
        (marker / 'flexlink_ros').write_text('')
    config = prefix / 'share' / 'flexlink_ros' / 'config'
    config.mkdir(parents=True)
    if with_file:
        (config / 'cho1992.yaml').write_text('name: installed\n')
    return prefix


def test_find_config_takes_the_first_ament_prefix_listing_the_package(tmp_path, monkeypatch):
    unmarked = _ament_prefix(tmp_path, 'unmarked', with_marker=False)
    first = _ament_prefix(tmp_path, 'first')
    second = _ament_prefix(tmp_path, 'second')
    paths = [str(tmp_path / 'missing'), str(unmarked), str(first), str(second)]
    monkeypatch.setenv('AMENT_PREFIX_PATH', os.pathsep.join(paths))
    assert ament_share_directory() == first / 'share' / 'flexlink_ros'
    assert find_config('cho1992') == first / 'share' / 'flexlink_ros' / 'config' / 'cho1992.yaml'
    # What the ament index itself answers (it is not imported by the core).
    packages = pytest.importorskip('ament_index_python.packages')
    assert pathlib.Path(packages.get_package_share_directory('flexlink_ros')) \
        == ament_share_directory()


def test_find_config_falls_back_to_the_prefix_and_the_source_tree(tmp_path, monkeypatch):
    installed = pathlib.Path(sys.prefix) / 'share' / 'flexlink_ros' / 'config' / 'cho1992.yaml'
    source = pathlib.Path(__file__).resolve().parents[2] / 'config' / 'cho1992.yaml'
    expected = installed if installed.exists() else source
    monkeypatch.delenv('AMENT_PREFIX_PATH', raising=False)
    assert ament_share_directory() is None
    assert find_config('cho1992') == expected
    # A listed package without the file: the next places are tried, as before.
    empty = _ament_prefix(tmp_path, 'empty', with_file=False)
    monkeypatch.setenv('AMENT_PREFIX_PATH', str(empty))
    assert find_config('cho1992.yaml') == expected
    with pytest.raises(MechanismError, match='no such file') as info:
        find_config('does_not_exist')
    looked = str(info.value)
    order = [str(empty / 'share' / 'flexlink_ros' / 'config'), str(installed.parent),
             str(source.parent)]
    assert [looked.index(place) for place in order] == sorted(looked.index(p) for p in order)


def test_find_config_returns_an_existing_path_unchanged(config_dir):
    path = config_dir / 'kang1990.yaml'
    assert find_config(str(path)) == path


def test_stiffness_damping_key_gives_the_default_beta_without_changing_the_mechanism(
        config_dir, tmp_path):
    data = _cho(config_dir)
    data['stiffness_damping_s'] = 1e-4
    path = tmp_path / 'damped.yaml'
    path.write_text(yaml.safe_dump(data))
    assert stiffness_damping_from_file(path) == 1e-4
    assert stiffness_damping_from_file('cho1992') == 0.0
    # beta is a model option, not part of the Mechanism (nor of its key): same mechanism.
    assert load_mechanism(path) == load_mechanism('cho1992')
    assert load_mechanism(path).key() == load_mechanism('cho1992').key()
    data['stiffness_damping_s'] = 'abc'
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(MechanismError, match='stiffness_damping_s'):
        stiffness_damping_from_file(path)


def documented_keys():
    """Every key of docs/mechanism-file.md's key table, <link> and <joint> expanded."""
    text = (pathlib.Path(__file__).resolve().parents[2] / 'docs' / 'mechanism-file.md'
            ).read_text()
    table = text.split('## Every key', 1)[1].split('\n## ', 1)[0]
    keys = set()
    for line in table.splitlines():
        cells = line.split('|')
        if len(cells) < 3 or not cells[1].strip().startswith('`'):
            continue
        for key in re.findall(r'`([^`]+)`', cells[1]):
            for link in LINK_NAMES:
                for joint in JOINT_NAMES:
                    keys.add(key.replace('<link>', link).replace('<joint>', joint))
    return keys


def loader_keys():
    """Every leaf key the loader accepts, dotted as the file nests it."""
    from flexlink_ros.core import mechanism_file as loader

    sections = {'material': loader._MATERIAL_KEYS, 'bearings': loader._BEARING_KEYS,
                'input_shaft': loader._SHAFT_KEYS, 'spring': loader._SPRING_KEYS,
                'joint_masses_kg': set(JOINT_NAMES),
                **{f'links.{link}': loader._LINK_KEYS for link in LINK_NAMES}}
    keys = {key for key in loader._TOP_KEYS if key not in sections and key != 'links'}
    for section, leaves in sections.items():
        keys |= {f'{section}.{leaf}' for leaf in leaves}
    return keys


def test_the_mechanism_file_reference_lists_exactly_the_keys_the_loader_accepts():
    assert documented_keys() == loader_keys()
