"""Node parameter table: defaults valid, bad values rejected with a reason."""

import pathlib
import subprocess
import sys

from flexlink_ros.core.mechanism_file import find_config, read_mechanism_source
from flexlink_ros.core.options import ModelOptions
from flexlink_ros.ros import parameters as node_params
from flexlink_ros.ros.node_model import load_node_model
import pytest
import yaml


# Node parameter -> the ModelOptions field it sets (the parameter's default is that field's).
MODEL_FIELDS = {'model.grid_size': 'grid_size', 'model.elements_per_link': 'elements_per_link',
                'model.rigid_crank': 'rigid_crank', 'model.bearings': 'bearings',
                'model.geometric_stiffness': 'geometric_stiffness', 'model.order': 'order',
                'model.soft_modes': 'soft_modes', 'model.second_order': 'second_order'}


def test_the_parameter_defaults_are_the_default_model_defined_once():
    default = ModelOptions()
    for name, field in MODEL_FIELDS.items():
        assert node_params.SPECS[name].default == getattr(default, field), name
    assert node_params.model_options(node_params.defaults()) == default
    assert node_params.default_model_options() == default
    # "from the file" and "the planned sizes" are markers, not a second definition
    assert node_params.defaults()['damping_ratio'] == -1.0
    assert node_params.defaults()['model.speed_max_rpm'] == 0.0


def test_defaults_are_valid():
    values = node_params.defaults()
    assert node_params.validate_all(values) is values


@pytest.mark.parametrize('name, value, fragment', [
    ('markers.exaggeration', -0.5, '>= 0'),   # 0: the derived default
    ('damping_ratio', -0.1, '>= 0'),
    ('damping_ratio', float('nan'), 'finite'),
    ('qos.reliability', 'sometimes', 'one of'),
    ('model.bearings', 'magnetic', 'one of'),
    ('qos.depth', 2.5, 'type int'),
    ('qos.depth', True, 'type int'),
    ('frame_id', 3, 'type str'),
    ('no.such.parameter', 1, 'unknown'),
    ('frame_id', '', 'frame_id must not be empty'),
    ('model.order', 0, '>= 1'),
    ('model.order', 3, '<= 2'),
    ('model.order', 1.5, 'type int'),
])
def test_bad_values_give_reasons(name, value, fragment):
    reason = node_params.validate_parameter(name, value, node_params.defaults())
    assert reason is not None and fragment in reason


def test_model_order_accepts_1_and_2_and_reaches_the_model_options():
    for order in (1, 2):
        assert node_params.validate_parameter('model.order', order) is None
        assert node_params.default_model_options(order=order).order == order
    spec = node_params.SPECS['model.order']
    assert (spec.default, spec.low, spec.high, spec.read_only) == (2, 1, 2, True)
    assert 'linear' in spec.description


def test_integer_accepted_for_float():
    assert node_params.validate_parameter('damping_ratio', 0) is None


def test_warn_threshold_cannot_exceed_error():
    current = node_params.defaults()
    reason = node_params.validate_parameter('diagnostics.criterion_warn', 5000.0, current)
    assert 'must not exceed' in reason
    with pytest.raises(ValueError, match='criterion_warn'):
        node_params.validate_all(dict(current, **{'diagnostics.criterion_error': 1.0}))


def test_markdown_table_lists_every_parameter():
    table = node_params.markdown_table()
    for spec in node_params.PARAMETERS:
        assert f'`{spec.name}`' in table


def _flatten(tree, prefix=''):
    for key, value in tree.items():
        if isinstance(value, dict):
            yield from _flatten(value, f'{prefix}{key}.')
        else:
            yield f'{prefix}{key}', value


def test_params_file_equals_the_code_defaults():
    # `ros2 run` without --params-file must behave as with config/flexlink_node.yaml.
    path = pathlib.Path(__file__).resolve().parents[2] / 'config' / 'flexlink_node.yaml'
    shipped = dict(_flatten(yaml.safe_load(path.read_text())['/**']['ros__parameters']))
    assert shipped == node_params.defaults()


def test_markdown_table_escapes_pipes_inside_cells():
    for row in node_params.markdown_table().splitlines():
        assert row.replace('\\|', '').count('|') == 5, row


def test_running_the_node_page_parameter_table_is_current():
    page = pathlib.Path(__file__).resolve().parents[2] / 'docs' / 'running-the-node.md'
    assert node_params.markdown_table() in page.read_text()


@pytest.mark.parametrize('name, limit', [
    ('frame_id', node_params.NAME_MAX_BYTES), ('crank_joint', node_params.NAME_MAX_BYTES),
    ('input_topic', node_params.NAME_MAX_BYTES), ('mechanism', node_params.PATH_MAX_BYTES),
    ('record.path', node_params.PATH_MAX_BYTES), ('model.cache_dir', node_params.PATH_MAX_BYTES),
])
def test_string_parameters_have_a_length_bound(name, limit):
    assert node_params.validate_parameter(name, 'x' * limit) is None
    reason = node_params.validate_parameter(name, 'x' * (limit + 1))
    assert reason == f'{name} must be at most {limit} bytes, got {limit + 1}'
    # Bytes, not characters: a two-byte character counts twice.
    assert 'at most' in node_params.validate_parameter(name, '\u00e9' * (limit // 2 + 1))


def test_every_string_parameter_is_bounded():
    for spec in node_params.PARAMETERS:
        if isinstance(spec.default, str):
            assert spec.max_bytes is not None, spec.name


def test_every_run_time_parameter_says_how_it_takes_effect():
    # test_node.py::test_run_time_parameters_take_effect changes each of these on a running
    # node; a new parameter that is not read-only must join both lists.
    writable = {spec.name for spec in node_params.PARAMETERS if not spec.read_only}
    assert writable == set(node_params.RUN_TIME_EFFECT)


def test_empty_crank_joint_is_refused():
    assert 'must not be empty' in node_params.validate_parameter('crank_joint', '')


def test_node_help_lists_every_parameter():
    done = subprocess.run([sys.executable, '-m', 'flexlink_ros.ros.node', '--help'],
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    listed = [line.split()[0] for line in done.stdout.splitlines() if line.startswith('  ')]
    assert [spec.name for spec in node_params.PARAMETERS] == [
        name for name in listed if name in {spec.name for spec in node_params.PARAMETERS}]
    assert 'diagnostics.hardware_id (default ' in done.stdout


def test_stiffness_damping_parameter_beats_the_mechanism_file(tmp_path):
    values = node_params.defaults()
    assert values['model.stiffness_damping'] == -1.0      # -1: the mechanism file's value
    assert node_params.model_options(values).stiffness_damping == 0.0
    assert node_params.model_options(values, 2e-4).stiffness_damping == 2e-4
    for beta in (0.0, 1e-4):
        values['model.stiffness_damping'] = beta
        assert node_params.model_options(values, 2e-4).stiffness_damping == beta
    assert node_params.validate_parameter('model.stiffness_damping', 1e-4) is None
    assert '>= -1' in node_params.validate_parameter('model.stiffness_damping', -2.0)
    assert '<= 1' in node_params.validate_parameter('model.stiffness_damping', 2.0)
    assert '[s]' in node_params.SPECS['model.stiffness_damping'].description


def test_node_model_takes_the_mechanism_files_stiffness_damping(tmp_path):
    damped = tmp_path / 'damped.yaml'
    damped.write_text(pathlib.Path(find_config('cho1992')).read_text()
                      + 'stiffness_damping_s: 2.0e-4\n')
    values = {**node_params.defaults(), 'mechanism': str(damped), 'model.rigid_crank': True,
              'model.grid_size': 16, 'model.modes': 2, 'model.static': 0,
              'model.elements_per_link': 2, 'model.cache_dir': str(tmp_path)}
    model, options, _ = load_node_model(values, lambda note: None)
    assert options.stiffness_damping == 2e-4
    assert model.info['options']['stiffness_damping'] == 2e-4
    values['model.stiffness_damping'] = 0.0
    _, options, _ = load_node_model(values, lambda note: None)
    assert options.stiffness_damping == 0.0


def test_node_model_is_built_from_the_bytes_the_node_read_once(tmp_path):
    """The model is built from the bytes the recording names, whatever the file says later."""
    linkage = tmp_path / 'linkage.yaml'
    text = pathlib.Path(find_config('cho1992')).read_text()
    linkage.write_text(text + 'stiffness_damping_s: 2.0e-4\n')
    source = read_mechanism_source(str(linkage))
    linkage.write_text(text)        # changed after the node's one read: no longer damped
    values = {**node_params.defaults(), 'mechanism': str(linkage), 'model.rigid_crank': True,
              'model.grid_size': 16, 'model.modes': 2, 'model.static': 0,
              'model.elements_per_link': 2, 'model.cache_dir': str(tmp_path)}
    _, options, _ = load_node_model(values, lambda note: None, source=source)
    assert options.stiffness_damping == 2e-4 and source == (linkage, linkage.read_bytes()
                                                            + b'stiffness_damping_s: 2.0e-4\n')
    assert load_node_model(values, lambda note: None)[1].stiffness_damping == 0.0   # read now


def test_soft_modes_defaults_to_the_smallest_usable_gap_and_reaches_the_model_options():
    spec = node_params.SPECS['model.soft_modes']
    assert (spec.default, spec.low, spec.read_only) == (-1, -1, True)
    assert node_params.default_model_options().soft_modes == -1
    assert node_params.default_model_options(soft_modes=0).soft_modes == 0
    assert node_params.validate_parameter('model.soft_modes', -2) is not None
    assert 'spectral gap' in spec.description


def test_node_model_warns_when_the_soft_basis_finds_no_gap(tmp_path):
    values = {**node_params.defaults(), 'model.rigid_crank': True, 'model.grid_size': 16,
              'model.elements_per_link': 2, 'model.cache_dir': str(tmp_path)}
    seen = {}
    for bearings, modes, static in (('rigid', 4, 2), ('flexible', 16, 2)):
        values.update({'model.bearings': bearings, 'model.modes': modes,
                       'model.static': static})
        warnings = []
        model, _, notes = load_node_model(values, warnings.append)
        seen[model.info['soft']['used']] = notes
        assert notes == warnings
        if model.info['soft']['used']:
            assert model.step_size < model.size and notes == []
        else:
            assert notes == [f'stepping all {model.size} coordinates: '
                             f'{model.info["soft"]["reason"]}']
            assert 'spectral gap' in notes[0]
    assert set(seen) == {True, False}
    values['model.soft_modes'] = 0                  # off on purpose: nothing to warn about
    assert load_node_model(values, lambda note: None)[2] == []


def test_second_order_parameter_selects_the_dynamic_pass():
    values = node_params.defaults()
    assert values['model.second_order'] == 'quasi-static'
    assert node_params.model_options(values) == node_params.default_model_options()
    assert 'second_order' not in node_params.model_options(values).cache_fields()
    values.update({'model.second_order': 'dynamic', 'model.rigid_crank': True,
                   'model.bearings': 'rigid'})
    options = node_params.model_options(values)
    assert options.second_order == 'dynamic' and (options.modes, options.static) == (8, 4)
    assert node_params.validate_parameter('model.second_order', 'full') is not None
    assert node_params.validate_parameter('model.second_order', 'dynamic') is None


def test_nonlinear_switch_takes_yamls_booleans_for_on_and_off():
    # A params file's unquoted `nonlinear: off` and `-p model.nonlinear:=on` reach the node
    # as YAML 1.1 booleans.
    assert node_params.defaults()['model.nonlinear'] == 'auto'
    parsed = yaml.safe_load('nonlinear: off')['nonlinear']
    assert parsed is False
    for value in ('auto', 'on', 'off', True, False):
        assert node_params.validate_parameter('model.nonlinear', value) is None
    values = node_params.validate_all({**node_params.defaults(), 'model.nonlinear': parsed})
    assert values['model.nonlinear'] == 'off'
    assert node_params.validate_all({**node_params.defaults(),
                                     'model.nonlinear': True})['model.nonlinear'] == 'on'
    reason = node_params.validate_parameter('model.nonlinear', 'yes')
    assert reason == "model.nonlinear must be one of auto, on, off, got 'yes'"
    assert 'must be of type str' in node_params.validate_parameter('model.nonlinear', 1)


def test_node_model_reads_the_mechanism_file_once_and_takes_its_damping_ratio(
        tmp_path, monkeypatch):
    from flexlink_ros.core import mechanism_file

    text = pathlib.Path(find_config('cho1992')).read_text()
    damped = tmp_path / 'damped.yaml'
    damped.write_text(text.replace('damping_ratio: 0.02', 'damping_ratio: 0.05')
                      + 'stiffness_damping_s: 1.0e-4\ncrank_speed_rpm: 560.0\n')
    reads = []
    read = mechanism_file.read_yaml_bounded
    monkeypatch.setattr(mechanism_file, 'read_yaml_bounded',
                        lambda *args, **kwargs: reads.append(args) or read(*args, **kwargs))
    values = {**node_params.defaults(), 'mechanism': str(damped), 'model.rigid_crank': True,
              'model.grid_size': 16, 'model.modes': 2, 'model.static': 0,
              'model.elements_per_link': 2, 'model.cache_dir': str(tmp_path)}
    model, options, _ = load_node_model(values, lambda note: None)
    assert len(reads) == 1
    # damping_ratio -1 (the default) is the file's, as model.stiffness_damping -1 is
    assert model.zeta == 0.05 and options.stiffness_damping == 1e-4
    # the speed range from the file's crank speed with its margin
    assert options.speed_max == pytest.approx(1.25 * 560.0 * 3.141592653589793 / 30.0)
    values['damping_ratio'] = 0.03
    assert load_node_model(values, lambda note: None)[0].zeta == 0.03


@pytest.mark.parametrize('name, tiny, floor', [
    ('record.max_bytes', 1, 1 << 20), ('record.max_duration_s', 0.001, 1.0)])
def test_split_settings_below_the_floor_are_refused_with_the_reason(name, tiny, floor):
    """A split every message would leave the recorder splitting instead of writing."""
    reason = node_params.validate_parameter(name, tiny)
    assert reason is not None and f'{name} must be 0 (no split) or at least' in reason
    assert 'each split' in reason
    just_below = floor - 1 if isinstance(tiny, int) else floor * 0.999
    assert node_params.validate_parameter(name, just_below) is not None
    assert node_params.validate_parameter(name, type(tiny)(floor)) is None
    assert node_params.validate_parameter(name, type(tiny)(0)) is None     # never split
