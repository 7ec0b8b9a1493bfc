"""
The `flexlink` command-line tool: one script, one small module per group of subcommands.

Every subcommand prints human-readable text, or one JSON object on stdout with ``--json``,
and exits non-zero with a one-line reason on bad input: 2 for a mechanism file refused (its
key, value and the likely cause), 1 otherwise. ``main(argv=None)`` only parses.
"""

import argparse
import gc
import importlib
import json
import math
import os
import sys

from .. import __version__
from ..errors import FlexlinkError


# Each subcommand and the module that registers it (``register(subparsers)``). Only the chosen
# command's module is imported: importing every group costs about a second (beam and FE).
COMMANDS = {
    'beam': 'flexlink_ros.cli.beam',
    'demo': 'flexlink_ros.cli.demo',
    'estimate': 'flexlink_ros.cli.estimate',
    'fleet': 'flexlink_ros.cli.fleet',
    'plan': 'flexlink_ros.cli.estimate',
    'modes': 'flexlink_ros.cli.flex',
    'simulate': 'flexlink_ros.cli.flex',
    'mcap-info': 'flexlink_ros.cli.mcap',
    'mcap-recover': 'flexlink_ros.cli.mcap',
    'mcap-record': 'flexlink_ros.cli.mcap_record',
    'reindex': 'flexlink_ros.cli.reindex',
    'replay': 'flexlink_ros.cli.replay',
    'report': 'flexlink_ros.cli.report',
    'kinematics': 'flexlink_ros.cli.rigid',
    'criteria': 'flexlink_ros.cli.rigid',
    'design-spring': 'flexlink_ros.cli.rigid',
    'validate': 'flexlink_ros.cli.validate',
}
# A subcommand's function takes the parsed args and returns an exit code.
COMMAND_MODULES = tuple(dict.fromkeys(COMMANDS.values()))


def emit(result, text, as_json):
    """
    Print a result as one JSON object or as text; return exit code 0.

    Parameters
    ----------
    result : dict
        What ``--json`` prints (numpy values and non-finite floats made JSON-safe).
    text : str
        What is printed otherwise.
    as_json : bool
        Whether to print ``result`` as JSON.

    """
    if as_json:
        print(json.dumps(_jsonable(result)))
    else:
        print(text)
    return 0


def _jsonable(value):
    """Convert numpy scalars/arrays and non-finite floats to JSON-safe values."""
    if hasattr(value, 'tolist'):
        value = value.tolist()
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def degree_range(text):
    """
    Parse 'START:STOP:STEP' (degrees, STOP excluded) or a comma list into a list of floats.

    Parameters
    ----------
    text : str
        The argument as given.

    """
    try:
        if ':' in text:
            start, stop, step = (float(part) for part in text.split(':'))
            if step <= 0:
                raise ValueError
            count = int(math.floor((stop - start) / step + 1e-9))
            values = [start + k * step for k in range(max(count, 0))]
            if not values:
                raise ValueError
            return values
        return [float(part) for part in text.split(',')]
    except ValueError:
        raise argparse.ArgumentTypeError(
            f'expected START:STOP:STEP in degrees or a comma list, got {text!r}') from None


def _command_module(argv):
    """Return the module that registers the command in ``argv``, or None (option or unknown)."""
    if not argv or argv[0].startswith('-'):
        return None
    return COMMANDS.get(argv[0])


def split_ros_args(argv):
    """
    Split ``argv`` into the tool's arguments and the ROS arguments, as rclpy does.

    Every ``--ros-args`` starts a section of ROS arguments that ends at a lone ``--`` or at
    the end; those sections go to rclpy (remappings, ``__ns``), the rest to the parser.

    Returns
    -------
    tool_args, ros_args : list of str

    """
    tool_args, ros_args, in_ros = [], [], False
    for arg in argv:
        if arg == '--ros-args':
            in_ros = True
        elif in_ros and arg == '--':
            in_ros = False
        elif in_ros:
            ros_args.append(arg)
        else:
            tool_args.append(arg)
    return tool_args, ros_args


def build_parser(argv=None):
    """
    Build the argument parser with every registered subcommand.

    Parameters
    ----------
    argv : list of str, optional
        With it, only the module of its subcommand is imported and registered when it can be
        told (the parse of ``argv`` is the same).

    Returns
    -------
    argparse.ArgumentParser

    """
    parser = argparse.ArgumentParser(
        prog='flexlink',
        description='Flexible four-bar linkage: kinematics, joint criteria, beam and FE '
                    'models, streaming estimator, ROS 2 node and MCAP tools.')
    parser.add_argument('--version', action='version', version=f'%(prog)s {__version__}')
    subparsers = parser.add_subparsers(dest='command', metavar='COMMAND')
    subparsers.required = True
    only = _command_module(argv) if argv is not None else None
    for name in (COMMAND_MODULES if only is None else (only,)):
        importlib.import_module(name).register(subparsers)
    return parser


def main(argv=None):
    """
    Run the `flexlink` script: parse ``argv`` and run the chosen command.

    Parameters
    ----------
    argv : list of str, optional
        The arguments (default: ``sys.argv[1:]``).

    Returns
    -------
    int
        The exit code.

    """
    argv, ros_args = split_ros_args(sys.argv[1:] if argv is None else list(argv))
    parser = build_parser(argv)
    args = parser.parse_args(argv)
    if ros_args and not getattr(args, 'takes_ros_args', False):
        parser.error(f'`flexlink {args.command}` takes no --ros-args')
    args.ros_args = ros_args
    try:
        return args.func(args)
    except BrokenPipeError:
        # The reader went away (`flexlink ... | head`): stop quietly, as Unix tools do.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 141
    except (FlexlinkError, ValueError) as exc:
        print(f'flexlink {args.command}: error: {exc}', file=sys.stderr)
        return getattr(exc, 'exit_code', 1)
    except OSError as exc:   # a missing or unreadable file, a full disk: said in one line
        print(f'flexlink {args.command}: error: {exc}', file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        return 130


def run():
    """
    Run :func:`main` as the `flexlink` script does and exit with its code.

    The objects left are frozen out of the garbage collector first: the interpreter's last
    collections then skip them, which makes leaving about 60 ms shorter after a replay
    (nothing is lost: files and handlers close and flush as before).
    """
    code = main()
    gc.freeze()
    sys.exit(code)


if __name__ == '__main__':
    run()
