"""
Parameters of flexlink_node: one table for declaration, documentation and validation.

The table is plain data so tests and the README generator use it without rclpy. The node turns
each entry into a declared parameter with a descriptor (description, range, read-only flag) and
validates runtime changes with :func:`validate_parameter`.
"""

import dataclasses
import math
from typing import Optional

import yaml

from ..core.options import (DEFAULT_SPEED_MAX, ModelOptions, PLANNED_TOLERANCE, SPEED_MARGIN,
                            speed_range)
from ..core.validity import VALIDITY_THRESHOLD
from ..io.recorder_files import MIN_SPLIT_BYTES, MIN_SPLIT_DURATION_S, split_refusal


@dataclasses.dataclass(frozen=True)
class ParameterSpec:
    """
    One node parameter.

    Parameters
    ----------
    name : str
        Parameter name (dots group them in YAML).
    default : bool, int, float or str
        Default value; its Python type is the parameter's type.
    description : str
        What it does, with its unit.
    low, high : float or None
        Inclusive range for numbers.
    choices : tuple of str or None
        Allowed values for strings.
    read_only : bool
        True if it can only be set at start-up (changing it needs a rebuilt model).
    max_bytes : int or None
        Longest accepted string (UTF-8 bytes); every string parameter has one.
    switch : bool
        A string choice with 'on' and 'off' that also takes booleans: YAML 1.1, which ROS
        params files and ``-p name:=value`` follow, reads an unquoted on / off as true /
        false (:func:`switch_value`).

    """

    name: str
    default: object
    description: str
    low: Optional[float] = None
    high: Optional[float] = None
    choices: Optional[tuple] = None
    read_only: bool = False
    max_bytes: Optional[int] = None
    switch: bool = False


# The default model, defined once (core.options): the model.* defaults are its fields.
DEFAULT_MODEL = ModelOptions()
NAME_MAX_BYTES = 256    # frame, joint and topic names
PATH_MAX_BYTES = 4096   # file and directory paths (PATH_MAX on Linux)
PARAMETERS = (
    ParameterSpec('mechanism', 'cho1992',
                  'Mechanism file path, or a name looked up in share/flexlink_ros/config',
                  read_only=True, max_bytes=PATH_MAX_BYTES),
    ParameterSpec('crank_joint', 'crank', 'Name of the crank joint in the input JointState',
                  max_bytes=NAME_MAX_BYTES),
    ParameterSpec('input_topic', 'joint_states', 'JointState topic carrying the crank',
                  read_only=True, max_bytes=NAME_MAX_BYTES),
    ParameterSpec('model.tolerance', PLANNED_TOLERANCE,
                  'Relative RMS error the default sizes were planned for; a smaller value '
                  'warns that `flexlink plan` should choose the model.* sizes',
                  low=1e-4, high=0.5, read_only=True),
    ParameterSpec('model.modes', 0, 'Basis directions from frozen modes; 0 = the planned '
                  'default for the bearing model', low=0, high=80, read_only=True),
    ParameterSpec('model.static', -1, 'Basis directions from static load responses; -1 = the '
                  'planned default', low=-1, high=20, read_only=True),
    ParameterSpec('model.grid_size', DEFAULT_MODEL.grid_size,
                  'Crank-angle grid points of the precomputed tables', low=8, high=4096,
                  read_only=True),
    ParameterSpec('model.elements_per_link', DEFAULT_MODEL.elements_per_link,
                  "Beam elements per link; 0 = the mechanism file's value", low=0, high=40,
                  read_only=True),
    ParameterSpec('model.rigid_crank', DEFAULT_MODEL.rigid_crank,
                  'Treat the crank as rigid (its pin A fixed)', read_only=True),
    ParameterSpec('model.bearings', DEFAULT_MODEL.bearings,
                  'Revolute bearings: flexible springs or rigid', choices=('flexible', 'rigid'),
                  read_only=True, max_bytes=NAME_MAX_BYTES),
    ParameterSpec('model.geometric_stiffness', DEFAULT_MODEL.geometric_stiffness,
                  'Include geometric stiffness from the rigid-body axial forces',
                  read_only=True),
    ParameterSpec('model.stiffness_damping', -1.0,
                  'Stiffness-proportional damping beta [s] on the link-frame strain rates and '
                  'c = beta k on the bearing springs, added to damping_ratio (set that to 0 '
                  "for beta alone, as the Exudyn peer); -1 = the mechanism file's "
                  'stiffness_damping_s (0 if none)', low=-1.0, high=1.0, read_only=True),
    ParameterSpec('model.order', DEFAULT_MODEL.order, "Order of the outputs: 1 = the paper's "
                  'linear KED; 2 = plus '
                  "the second-order motion of the bent links' chord shortening (lever tip, "
                  'coupler mid-point, markers)', low=1, high=2, read_only=True),
    ParameterSpec('model.soft_modes', DEFAULT_MODEL.soft_modes, 'The estimator steps the p '
                  'lowest modes of the reduced model (a smooth basis at a checked spectral '
                  'gap); -1 = the smallest p at a usable gap, or all coordinates where there '
                  'is none (logged); 0 = all coordinates; p > 0 = exactly p (refused without '
                  'a gap there)',
                  low=-1, high=1000, read_only=True),
    ParameterSpec('model.second_order', DEFAULT_MODEL.second_order, 'How order 2 is computed: '
                  'quasi-static (the chord shortening of the linear shapes) or dynamic (also '
                  'the inertia of that motion: a second reduced state per sample, on a larger '
                  'basis by default; about +20 us per sample; the lever tip and coupler '
                  'mid-point, the markers stay quasi-static)',
                  choices=('quasi-static', 'dynamic'), read_only=True,
                  max_bytes=NAME_MAX_BYTES),
    ParameterSpec('model.speed_max_rpm', 0.0, 'Largest |crank speed| the model serves [rpm]; '
                  'faster samples are clipped to it (counted, logged and flagged); 0 = the '
                  f"mechanism file's crank_speed_rpm times {SPEED_MARGIN:g}, at least "
                  f'{int(DEFAULT_SPEED_MAX * 30.0 / math.pi)} rpm', low=0.0, high=1e5,
                  read_only=True),
    ParameterSpec('model.nonlinear', 'auto', 'The lever-tip and coupler-mid deflections '
                  'from the geometrically nonlinear model (true through resonance, about 6-10 '
                  'times the linear update): on, off, or auto = on only if the linear '
                  "model's validity indicator says it is not valid somewhere in the model's "
                  'speed range (a ramp scan at start-up, logged); criteria and markers stay '
                  "the linear model's", choices=('auto', 'on', 'off'), read_only=True,
                  max_bytes=NAME_MAX_BYTES, switch=True),
    ParameterSpec('model.cache_dir', '', 'Directory of precomputed-model cache files '
                  '(empty: ~/.cache/flexlink_ros)', read_only=True, max_bytes=PATH_MAX_BYTES),
    ParameterSpec('model.warm_start', True,
                  "Start from the periodic steady state at the first sample's speed"),
    ParameterSpec('damping_ratio', -1.0, 'Modal damping ratio of every frozen mode; -1 = the '
                  "mechanism file's damping_ratio", low=-1.0, high=1.0, read_only=True),
    ParameterSpec('frame_id', 'linkage_ground', 'Frame of the ground (O2 at its origin, '
                  'x towards O4) for deflections and markers', max_bytes=NAME_MAX_BYTES),
    ParameterSpec('markers.exaggeration', 0.0,
                  'Scale applied to elastic deflections in the deformed-linkage markers; 0 = '
                  "the smallest of 1, 2, 5, 10, ... that draws the model's expected peak "
                  "deflection as 5 % of the coupler's length (logged at start)",
                  low=0.0, high=1e6),
    ParameterSpec('markers.points_per_link', 9, 'Points drawn along each deformed link',
                  low=2, high=200),
    ParameterSpec('markers.every_n', 10,
                  'Publish markers on every n-th sample (RViz/Foxglove need far less than 1 kHz)',
                  low=1, high=100000),
    ParameterSpec('diagnostics.criterion_warn', 100.0,
                  'WARN when |dgamma/dt|/R of a joint exceeds this [rad/(s N)]',
                  low=0.0, high=1e9),
    ParameterSpec('diagnostics.criterion_error', 1000.0,
                  'ERROR when |dgamma/dt|/R of a joint exceeds this [rad/(s N)]',
                  low=0.0, high=1e9),
    ParameterSpec('diagnostics.stale_input_s', 0.5,
                  'ERROR when no valid input arrived for this long [s]', low=0.001, high=3600.0),
    ParameterSpec('diagnostics.min_rate_hz', 50.0,
                  'WARN when the input rate falls below this [Hz]', low=0.0, high=1e6),
    ParameterSpec('diagnostics.error_indicator_warn', 0.05,
                  "WARN when the estimator's error indicator exceeds this (relative)",
                  low=0.0, high=10.0),
    ParameterSpec('diagnostics.nonlinearity_warn', VALIDITY_THRESHOLD,
                  "WARN when the period's nonlinearity (validity) indicator exceeds this "
                  '(the linear estimate is not valid above it)', low=0.01, high=100.0),
    ParameterSpec('diagnostics.period_s', 1.0, 'Period of /diagnostics [s]',
                  low=0.01, high=60.0),
    ParameterSpec('diagnostics.hardware_id', 'flexlink',
                  'hardware_id of every /diagnostics status (the status names carry the '
                  'fully qualified node name)', max_bytes=NAME_MAX_BYTES),
    ParameterSpec('record.enabled', False, 'Record input and outputs to MCAP',
                  read_only=True),
    ParameterSpec('record.path', '', 'MCAP file or directory (empty: ./flexlink_<time>)',
                  read_only=True, max_bytes=PATH_MAX_BYTES),
    ParameterSpec('record.max_bytes', 0, 'Split the recording at this size (0: never; '
                  'else at least 1 MiB) [B]', low=0, high=2 ** 62, read_only=True),
    ParameterSpec('record.max_duration_s', 0.0,
                  'Split the recording after this duration (0: never; else at least 1 s) [s]',
                  low=0.0, high=1e7, read_only=True),
    ParameterSpec('qos.depth', 1000, 'History depth of the input subscription and outputs '
                  "(1 s at 1 kHz: room for the warm start's pause)",
                  low=1, high=100000, read_only=True),
    ParameterSpec('qos.reliability', 'reliable', 'Reliability of input and outputs',
                  choices=('reliable', 'best_effort'), read_only=True,
                  max_bytes=NAME_MAX_BYTES),
)

SPECS = {spec.name: spec for spec in PARAMETERS}
# Every parameter that is not read-only, and how a run-time change takes effect in the node.
RUN_TIME_EFFECT = {
    'crank_joint': 'the next message is searched for the new name',
    'model.warm_start': 'the next reset starts warm or static',
    'frame_id': 'the next outputs carry the new frame',
    'markers.exaggeration': 'the next markers',
    'markers.points_per_link': 'the next markers (encoder rebuilt)',
    'markers.every_n': 'the next markers',
    'diagnostics.criterion_warn': 'the next /diagnostics and markers',
    'diagnostics.criterion_error': 'the next /diagnostics and markers',
    'diagnostics.stale_input_s': 'the next /diagnostics',
    'diagnostics.min_rate_hz': 'the next /diagnostics',
    'diagnostics.error_indicator_warn': 'the next /diagnostics',
    'diagnostics.nonlinearity_warn': 'the next /diagnostics',
    'diagnostics.period_s': 'the diagnostics timer is restarted with the new period',
    'diagnostics.hardware_id': 'the next /diagnostics',
}


def validate_parameter(name, value, current=None):
    """
    Check one parameter value; return None if acceptable, else the reason as a sentence.

    Parameters
    ----------
    name : str
        Parameter name.
    value : object
        Proposed value.
    current : dict or None
        Current values of all parameters, for checks that relate two of them.

    """
    spec = SPECS.get(name)
    if spec is None:
        return f'unknown parameter {name!r}'
    if spec.switch:
        value = switch_value(value)
    expected = type(spec.default)
    if expected is float and isinstance(value, int) and not isinstance(value, bool):
        value = float(value)
    if not isinstance(value, expected) or (expected is int and isinstance(value, bool)):
        return f'{name} must be of type {expected.__name__}, got {type(value).__name__}'
    if isinstance(value, float) and not math.isfinite(value):
        return f'{name} must be finite, got {value}'
    if spec.low is not None and value < spec.low:
        return f'{name} must be >= {spec.low:g}, got {value}'
    if spec.high is not None and value > spec.high:
        return f'{name} must be <= {spec.high:g}, got {value}'
    if spec.max_bytes is not None and len(value.encode('utf-8', 'replace')) > spec.max_bytes:
        return (f'{name} must be at most {spec.max_bytes} bytes, got '
                f'{len(value.encode("utf-8", "replace"))}')
    if name == 'damping_ratio' and value < 0.0 and value != -1.0:
        return f"damping_ratio must be >= 0, or -1 for the mechanism file's, got {value}"
    if name in ('crank_joint', 'frame_id') and not value:
        return f'{name} must not be empty'
    if spec.choices is not None and value not in spec.choices:
        return f'{name} must be one of {", ".join(spec.choices)}, got {value!r}'
    if name == 'record.max_bytes':
        return split_refusal(name, value, MIN_SPLIT_BYTES, f'{MIN_SPLIT_BYTES} (1 MiB)')
    if name == 'record.max_duration_s':
        return split_refusal(name, value, MIN_SPLIT_DURATION_S, f'{MIN_SPLIT_DURATION_S:g} s')
    if name in ('diagnostics.criterion_warn', 'diagnostics.criterion_error') and current:
        warn = value if name.endswith('warn') else current.get('diagnostics.criterion_warn')
        error = value if name.endswith('error') else current.get('diagnostics.criterion_error')
        if warn is not None and error is not None and warn > error:
            return (f'diagnostics.criterion_warn ({warn:g}) must not exceed '
                    f'diagnostics.criterion_error ({error:g})')
    return None


def switch_value(value):
    """Return a switch parameter's value as its string: True -> 'on', False -> 'off'."""
    if isinstance(value, bool):
        return 'on' if value else 'off'
    return value


def validate_all(values):
    """
    Validate a full mapping of parameter values; raise ValueError with every reason.

    Returns ``values`` with the switches' booleans as their strings (:func:`switch_value`).
    """
    reasons = [reason for name, value in values.items()
               if (reason := validate_parameter(name, value, values)) is not None]
    if reasons:
        raise ValueError('; '.join(reasons))
    for name, value in values.items():
        if name in SPECS and SPECS[name].switch:
            values[name] = switch_value(value)
    return values


def defaults():
    """Map every parameter name to its default value."""
    return {spec.name: spec.default for spec in PARAMETERS}


def parameter_help(specs):
    """
    Return the ``--help`` text of a node's parameters: name, default, range and description.

    Parameters
    ----------
    specs : sequence of ParameterSpec
        The node's parameter table.

    """
    lines = ['parameters (--ros-args -p name:=value, or --params-file FILE):']
    for spec in specs:
        allowed = (f' [{", ".join(spec.choices)}]' if spec.choices else
                   f' [{spec.low:g} .. {spec.high:g}]' if spec.low is not None else '')
        lines.append(f'  {spec.name} (default {spec.default!r}){allowed}: {spec.description}')
    return '\n'.join(lines)


def markdown_table():
    """Write the parameters as a markdown table (README)."""
    rows = ['| parameter | default | range / choices | description |', '|---|---|---|---|']
    for spec in PARAMETERS:
        if spec.choices:
            allowed = ', '.join(spec.choices)
        elif spec.low is not None:
            allowed = f'{spec.low:g} … {spec.high:g}'
        else:
            allowed = ''
        ro = ' (start-up only)' if spec.read_only else ''
        description = spec.description.replace('|', '\\|')   # a bare | splits the cell
        rows.append(f'| `{spec.name}` | `{spec.default!r}` | {allowed} | '
                    f'{description}{ro} |')
    return '\n'.join(rows)


def model_options(values, file_stiffness_damping=0.0, file_crank_speed=None):
    """
    Select the modelling options by parameter values.

    Parameters
    ----------
    values : dict
        Parameter name -> value (:data:`PARAMETERS`).
    file_stiffness_damping : float
        The mechanism file's ``stiffness_damping_s`` [s], used where
        ``model.stiffness_damping`` is negative (-1: not set).
    file_crank_speed : float or None
        The mechanism file's crank speed [rad/s], the speed range's default
        (:func:`core.options.speed_range`) where ``model.speed_max_rpm`` is 0.

    Returns
    -------
    core.options.ModelOptions

    """
    modes = values['model.modes'] or None   # 0: the planned default for the bearing model
    static = None if values['model.static'] < 0 else values['model.static']
    beta = values.get('model.stiffness_damping', -1.0)
    return ModelOptions(modes=modes, static=static, grid_size=values['model.grid_size'],
                        elements_per_link=values['model.elements_per_link'] or None,
                        rigid_crank=values['model.rigid_crank'],
                        bearings=values['model.bearings'],
                        geometric_stiffness=values['model.geometric_stiffness'],
                        speed_max=speed_range(file_crank_speed,
                                              values.get('model.speed_max_rpm', 0.0)),
                        stiffness_damping=file_stiffness_damping if beta < 0 else beta,
                        order=values['model.order'],
                        soft_modes=values.get('model.soft_modes', DEFAULT_MODEL.soft_modes),
                        second_order=values.get('model.second_order',
                                                DEFAULT_MODEL.second_order))


def default_model_options(**overrides):
    """
    Give the default model options with ``model.*`` parameters overridden by keyword.

    Without overrides :class:`core.options.ModelOptions` (the node's parameters take their
    defaults from it). Sizes left at their defaults are resolved for the overridden bearing
    and crank models (core.options.DEFAULT_SIZES).
    """
    values = defaults()
    for name, value in overrides.items():
        key = f'model.{name}'
        if key not in values:
            raise ValueError(f'unknown model option {name!r}')
        values[key] = value
    return model_options(values)


def model_parameters(options, file_crank_speed=None):
    """
    Give the ``model.*`` parameter values that make the node build ``options``.

    The inverse of :func:`model_options`: ``model_options({**defaults(), **these},
    file_crank_speed=...)`` is ``options`` again (beta as itself; the speed range as 0 where
    it is the file's default, so the node finds the same cached model, else in rpm).

    Parameters
    ----------
    options : core.options.ModelOptions
        A model (the plan's choice).
    file_crank_speed : float or None
        The mechanism file's crank speed [rad/s].

    """
    default_range = options.speed_max == speed_range(file_crank_speed)
    return {'model.modes': options.modes, 'model.static': options.static,
            'model.grid_size': options.grid_size,
            'model.elements_per_link': options.elements_per_link or 0,
            'model.rigid_crank': options.rigid_crank, 'model.bearings': options.bearings,
            'model.geometric_stiffness': options.geometric_stiffness,
            'model.stiffness_damping': float(options.stiffness_damping),
            'model.order': options.order, 'model.soft_modes': options.soft_modes,
            'model.second_order': options.second_order,
            'model.speed_max_rpm': 0.0 if default_range
            else float(options.speed_max) * 30.0 / math.pi}


def params_file_text(values, comment=''):
    """
    Write parameter values as a ``/**: ros__parameters:`` file the node reads as it is.

    Parameters
    ----------
    values : dict
        Parameter name -> value (validated here; floats keep a decimal point).
    comment : str
        Lines put first as YAML comments.

    """
    validate_all({**defaults(), **values})
    nested = {}
    for name, value in values.items():
        *groups, leaf = name.split('.')
        target = nested
        for group in groups:
            target = target.setdefault(group, {})
        target[leaf] = float(value) if type(SPECS[name].default) is float else value
    body = yaml.safe_dump({'/**': {'ros__parameters': nested}}, sort_keys=False)
    header = ''.join(f'# {line}\n' for line in comment.splitlines())
    return header + body
