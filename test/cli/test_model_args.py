"""The model flags every model subcommand shares: spellings, choices, defaults, help."""

import pathlib

from flexlink_ros.cli import main as cli
from flexlink_ros.cli import model_args, replay_model
from flexlink_ros.core.mechanism_file import find_config, load_mechanism
from flexlink_ros.core.options import ModelOptions
import pytest

# Each model subcommand with the arguments it requires.
MODEL_COMMANDS = {'estimate': ['--rpm', '391'], 'plan': ['--rpm-max', '391'],
                  'replay': ['bag'], 'simulate': [], 'modes': []}
# One default model (core.options.ModelOptions): the same bearings everywhere.
DEFAULT_BEARINGS = dict.fromkeys(MODEL_COMMANDS, ModelOptions().bearings)


def parse(*argv):
    """Parse ``argv`` with the parser of its subcommand (replay: with the flags' defaults)."""
    args = cli.build_parser(list(argv)).parse_args(list(argv))
    # replay defers its model flags' defaults to the recording's; these are the fallbacks
    return replay_model.with_flag_defaults(args) if argv[0] == 'replay' else args


@pytest.mark.parametrize('command', sorted(MODEL_COMMANDS))
def test_every_model_subcommand_accepts_the_shared_flags(command):
    required = MODEL_COMMANDS[command]
    args = parse(command, *required, '--mechanism', 'kang1990', '--rigid-crank',
                 '--bearings', 'flexible', '--elements-per-link', '3',
                 '--no-geometric-stiffness')
    assert (args.mechanism, args.rigid_crank, args.bearings, args.elements_per_link,
            args.no_geometric_stiffness) == ('kang1990', True, 'flexible', 3, True)
    args = parse(command, *required, '--flexible-crank', '--bearings', 'rigid')
    assert (args.rigid_crank, args.bearings) == (False, 'rigid')


@pytest.mark.parametrize('command', sorted(MODEL_COMMANDS))
def test_defaults_are_the_default_model_and_shown_in_help(command, capsys):
    args = parse(command, *MODEL_COMMANDS[command])
    # plan: neither crank flag leaves the crank model to the plan (None); elsewhere flexible
    rigid_crank = None if command == 'plan' else False
    assert (args.mechanism, args.rigid_crank, args.bearings, args.elements_per_link,
            args.no_geometric_stiffness) == ('cho1992', rigid_crank, DEFAULT_BEARINGS[command],
                                             None, False)
    with pytest.raises(SystemExit):
        parse(command, '--help')
    text = ' '.join(capsys.readouterr().out.split())
    recorded = "the recording's, else " if command == 'replay' else ''
    assert f'(default: {recorded}{DEFAULT_BEARINGS[command]})' in text
    assert f'(default: {recorded}cho1992)' in text and '{flexible,rigid}' in text


@pytest.mark.parametrize('command', ['simulate', 'modes'])
def test_elements_is_a_deprecated_spelling_of_elements_per_link(command, capsys):
    old = parse(command, '--elements', '3')
    assert 'flexlink: --elements is deprecated, use --elements-per-link' in \
        capsys.readouterr().err
    new = parse(command, '--elements-per-link', '3')
    assert capsys.readouterr().err == ''
    assert old == new and new.elements_per_link == 3
    assert '--elements ' not in cli.build_parser([command]).format_help()


@pytest.mark.parametrize('command', ['estimate', 'plan', 'replay', 'simulate'])
def test_stiffness_damping_flag_beats_the_file_beats_zero(command, tmp_path, capsys):
    required = MODEL_COMMANDS[command]
    damped = tmp_path / 'damped.yaml'
    damped.write_text(pathlib.Path(find_config('cho1992')).read_text()
                      + 'stiffness_damping_s: 2.0e-4\n')
    assert model_args.stiffness_damping(parse(command, *required)) == 0.0
    assert model_args.stiffness_damping(
        parse(command, *required, '--mechanism', str(damped))) == 2e-4
    args = parse(command, *required, '--mechanism', str(damped), '--stiffness-damping', '0')
    assert model_args.stiffness_damping(args) == 0.0
    args = parse(command, *required, '--stiffness-damping', '1e-4')
    assert model_args.stiffness_damping(args) == 1e-4
    if command != 'simulate':
        assert model_args.model_options(args).stiffness_damping == 1e-4
    with pytest.raises(ValueError, match='--stiffness-damping'):
        model_args.stiffness_damping(parse(command, *required, '--stiffness-damping', '-1'))
    with pytest.raises(SystemExit):
        parse(command, '--help')
    text = ' '.join(capsys.readouterr().out.split())
    assert '--stiffness-damping BETA_S' in text and 'stiffness_damping_s' in text


def test_modes_has_no_stiffness_damping_flag():
    assert '--stiffness-damping' not in cli.build_parser(['modes']).format_help()


@pytest.mark.parametrize('command', ['estimate', 'plan', 'replay'])
def test_soft_modes_flag_reaches_the_model_options_and_is_documented(command, capsys):
    required = MODEL_COMMANDS[command]
    assert model_args.model_options(parse(command, *required)).soft_modes == -1
    for value in (0, 16):
        args = parse(command, *required, '--soft-modes', str(value))
        assert model_args.model_options(args).soft_modes == value
    with pytest.raises(SystemExit):
        parse(command, '--help')
    text = ' '.join(capsys.readouterr().out.split())
    assert '--soft-modes P' in text and 'spectral gap' in text


@pytest.mark.parametrize('command', ['estimate', 'replay'])
def test_second_order_flag_of_the_estimator_commands(command):
    required = MODEL_COMMANDS[command]
    # the default: quasi-static, the options (and the model's cache key) as without the flag
    default = model_args.model_options(parse(command, *required))
    assert default.second_order == 'quasi-static'
    assert model_args.model_options(parse(command, *required, '--second-order',
                                          'quasi-static')) == default
    dynamic = model_args.model_options(parse(command, *required, '--second-order', 'dynamic',
                                             '--rigid-crank', '--bearings', 'rigid'))
    assert dynamic.second_order == 'dynamic' and (dynamic.modes, dynamic.static) == (8, 4)
    with pytest.raises(SystemExit):
        parse(command, *required, '--second-order', 'full')


def test_plan_and_simulate_keep_their_second_order_meaning():
    # plan compares against a quasi-static reference: no flag; simulate's is its own
    assert '--second-order' not in cli.build_parser(['plan']).format_help()
    args = parse('simulate', '--second-order', 'quasi-static')
    assert args.second_order == 'quasi-static'
    assert parse('simulate').second_order is None      # dynamic where it applies


@pytest.mark.parametrize('command', ['estimate', 'replay'])
def test_the_estimator_commands_build_the_default_model_without_flags(command):
    assert model_args.model_options(parse(command, *MODEL_COMMANDS[command])) == ModelOptions()


@pytest.mark.parametrize('command', ['simulate', 'modes', 'estimate', 'plan', 'replay'])
def test_every_model_command_defaults_to_the_default_models_physics(command):
    args = parse(command, *MODEL_COMMANDS[command])
    default = ModelOptions()
    crank = None if command == 'plan' else default.rigid_crank   # plan: its choice
    assert (args.rigid_crank, args.bearings) == (crank, default.bearings)
    assert model_args.elements_per_link(args) == default.elements_per_link
    assert getattr(args, 'order', default.order) == default.order


SLOW = str(pathlib.Path(__file__).resolve().parents[1] / 'data' / 'slow_heavy_steel.yaml')


def test_the_charts_draw_the_linkages_own_criterion_thresholds_not_the_papers():
    """
    A 60 rpm linkage's charts drew the paper's WARN 100 / ERROR 1000, 12 times its cycle.

    Its own (what ``plan --params-out`` gives the node): 1.5 and 3 times the cycle's largest
    criterion, joint B's 8.56 rad/(s N) at 108 deg by an independent Newton-Euler hand solution.
    """
    warn, error, note = model_args.criterion_thresholds(load_mechanism(SLOW))
    assert (warn, error) == pytest.approx((1.5 * 8.559, 3.0 * 8.559), rel=2e-3)
    assert '60 rpm' in note
    # a file without crank_speed_rpm: the node's defaults, said so
    warn, error, note = model_args.criterion_thresholds(load_mechanism('cho1992'))
    assert (warn, error) == (100.0, 1000.0) and 'node default' in note
