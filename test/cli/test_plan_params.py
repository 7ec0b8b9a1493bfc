"""
`flexlink plan --params-out` (cli/plan_params.py): the node's parameters file of a choice.

The file round-trips to the same model options, and a real node started with it as it is
streams a stiff linkage's model without static directions (the plan's "static = 0" kind)
with its estimator status OK, not a permanent WARN of the error indicator.
"""

import math
import os
import pathlib
import sys

from flexlink_ros.core.options import ModelOptions
from flexlink_ros.ros import parameters as node_params
from node_runs import stream_node_with_driver, write_small_plan_params
import pytest
import yaml

DATA = pathlib.Path(__file__).resolve().parents[1] / 'data'
# A small model of the stiff linkage without static directions: outputs carried by the
# residual correction, so its error indicator is far above the node's default WARN level.
CHOICE = ModelOptions(modes=8, static=0, grid_size=64, rigid_crank=True, elements_per_link=3,
                      speed_max=1.05 * 600.0 * math.pi / 30.0, soft_modes=0)


@pytest.mark.parametrize('options', [
    CHOICE, ModelOptions(), ModelOptions.linear(bearings='rigid', stiffness_damping=1e-4),
    ModelOptions(order=2, second_order='dynamic', rigid_crank=True, bearings='rigid')])
def test_the_parameters_give_the_node_the_same_model(options):
    values = {**node_params.defaults(), **node_params.model_parameters(options)}
    again = node_params.model_options(values)
    assert again.speed_max == pytest.approx(options.speed_max, rel=1e-12)
    assert again == ModelOptions(**{**vars(options), 'speed_max': again.speed_max})
    # the file's default range is written as 0: the node then builds the very same options
    # (the same cache key), not one a rounding away
    file_speed = options.speed_max / 1.25 if options.speed_max > 65.0 else None
    values = {**node_params.defaults(),
              **node_params.model_parameters(options, file_speed)}
    assert values['model.speed_max_rpm'] == 0.0
    assert node_params.model_options(values, file_crank_speed=file_speed) == options


def test_the_file_is_a_ros_parameters_file_with_floats_written_as_floats(tmp_path):
    values = {'mechanism': str(DATA / 'packaging_steel.yaml'),
              **node_params.model_parameters(CHOICE), 'diagnostics.criterion_warn': 3000,
              'diagnostics.criterion_error': 6000.0}
    text = node_params.params_file_text(values, 'made by a test\nsecond line')
    assert text.startswith('# made by a test\n# second line\n/**:\n  ros__parameters:\n')
    nested = yaml.safe_load(text)['/**']['ros__parameters']
    assert nested['model']['static'] == 0 and nested['model']['bearings'] == 'flexible'
    assert 'criterion_warn: 3000.0' in text     # a YAML integer for a float is refused
    with pytest.raises(ValueError, match='model.order'):
        node_params.params_file_text({'model.order': 3})


def test_a_real_node_takes_the_file_as_it_is_and_its_estimator_is_not_stuck_at_warn(
        tmp_path):
    cache = tmp_path / 'cache'
    params = tmp_path / 'plan.yaml'
    values = write_small_plan_params(params, DATA / 'packaging_steel.yaml', CHOICE, cache,
                                     rpm_max=600.0, tolerance=0.05)
    assert values['diagnostics.error_indicator_warn'] > 0.05     # calibrated on the model
    bag = tmp_path / 'bag'
    levels = run_node(tmp_path, params, bag, cache)
    assert levels and levels[-1] == 0, levels       # OK once streaming
    assert all(level == 0 for level in levels[1:]), levels


def run_node(tmp_path, params, bag, cache):
    """Run the node with ``params`` on the crank driver at 600 rpm; estimator levels."""
    from rosbags.highlevel import AnyReader

    env = dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path), PYTHONUNBUFFERED='1')
    node = [sys.executable, '-m', 'flexlink_ros.ros.node', '--ros-args', '--params-file',
            str(params), '-p', 'record.enabled:=true', '-p', f'record.path:={bag}',
            '-p', f'model.cache_dir:={cache}']
    driver = [sys.executable, '-m', 'flexlink_ros.ros.crank_driver', '--ros-args', '-p',
              'speed_rpm:=600.0']
    # three diagnostics periods of streaming
    stream_node_with_driver(node, driver, tmp_path / 'node.log', env, stream_s=3.5)
    levels = []
    with AnyReader([bag]) as reader:
        for connection, _, raw in reader.messages():
            if connection.topic == '/diagnostics':
                message = reader.deserialize(raw, connection.msgtype)
                for item in message.status:
                    values = {kv.key: kv.value for kv in item.values}
                    if item.name.endswith('estimator') and \
                            values.get('samples_in_period', '0') != '0':
                        levels.append(int.from_bytes(item.level, 'little')
                                      if isinstance(item.level, bytes) else int(item.level))
    return levels
