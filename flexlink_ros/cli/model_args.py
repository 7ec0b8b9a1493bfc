"""
The model flags every model subcommand shares, and the options and model they give.

``simulate``/``modes`` (full-order FE) and ``estimate``/``plan``/``replay``
(reduced model) take the same spellings: ``--mechanism``, ``--rigid-crank`` /
``--flexible-crank``, ``--bearings {flexible,rigid}``, ``--elements-per-link N`` and
``--no-geometric-stiffness``; ``--order {1,2}`` (default 2: the linear outputs plus the
second-order motion of the bent links; 1: the paper's linear KED) where the outputs are
published (simulate and the estimator's subcommands), and for the estimator's
``--second-order {quasi-static,dynamic}`` (simulate has its own, for the full-order method).
Every default is the default model's (:class:`core.options.ModelOptions`, the node's too):
flexible crank, flexible bearings, 4 elements per link, order 2; the speed range and the
stiffness damping default to the mechanism file's. ``--elements`` is accepted where it was
(simulate, modes) as a deprecated spelling of ``--elements-per-link``.
"""

import argparse
import sys

from .progress import OnDemandProgress
from ..core.criteria_thresholds import suggest_thresholds
from ..core.mechanism_file import read_mechanism_file
from ..core.numerics import RPM
from ..core.options import DEFAULT_SPEED_MAX, ModelOptions, SECOND_ORDER_PASSES, speed_range
from ..core.reduction import mechanism_model
from ..ros import parameters as node_params

BEARINGS = ('flexible', 'rigid')
# Output order of the published deflections; the flag's default is the default model's.
ORDERS = (1, 2)
DEFAULT_MODEL = ModelOptions()
# The prefix of the model build's progress on stderr.
BUILD_LABEL = 'building the model (cached afterwards)'


class DeprecatedAlias(argparse.Action):
    """
    Store a value like the option it is an old spelling of, and say so on stderr.

    Parameters
    ----------
    option_strings : list of str
        The old spelling(s).
    dest : str
        The destination of the preferred option.
    preferred : str
        The preferred spelling, named in the note.
    **kwargs
        Further arguments of :class:`argparse.Action` (type, help, ...).

    """

    def __init__(self, option_strings, dest, preferred, **kwargs):
        super().__init__(option_strings, dest, **kwargs)
        self.preferred = preferred

    def __call__(self, parser, namespace, values, option_string=None):
        """Store ``values`` and print the deprecation note."""
        print(f'flexlink: {option_string} is deprecated, use {self.preferred}', file=sys.stderr)
        setattr(namespace, self.dest, values)


def add_model_arguments(parser, elements_alias=False):
    """
    Add the shared model flags, their defaults the default model's.

    Parameters
    ----------
    parser : argparse.ArgumentParser
        A subcommand's parser.
    elements_alias : bool
        Also accept the deprecated ``--elements``.

    """
    parser.add_argument('--mechanism', default='cho1992',
                        help='mechanism YAML file or bare name (default: %(default)s)')
    crank = parser.add_mutually_exclusive_group()
    crank.add_argument('--rigid-crank', dest='rigid_crank', action='store_true',
                       default=DEFAULT_MODEL.rigid_crank,
                       help='treat the crank as rigid: crank pin A is a fixed point of the '
                       "frozen structure (the paper's Figs 20-22 case)")
    crank.add_argument('--flexible-crank', dest='rigid_crank', action='store_false',
                       help='model the crank as a flexible beam (default)')
    parser.add_argument('--bearings', choices=BEARINGS, default=DEFAULT_MODEL.bearings,
                        help='revolute bearings: flexible (the springs of the mechanism file, '
                        'Eq. 23) or rigid (exact pins) (default: %(default)s)')
    parser.add_argument('--elements-per-link', type=int, default=None, metavar='N',
                        help='beam elements per link (default: '
                        f'{DEFAULT_MODEL.elements_per_link})')
    if elements_alias:
        parser.add_argument('--elements', dest='elements_per_link', type=int,
                            action=DeprecatedAlias, preferred='--elements-per-link',
                            default=argparse.SUPPRESS, help=argparse.SUPPRESS)
    parser.add_argument('--no-geometric-stiffness', action='store_true',
                        help='leave out the geometric stiffness of the axial forces (A.4)')


def add_stiffness_damping_argument(parser):
    """Add ``--stiffness-damping BETA_S`` (simulate, estimate, plan, replay)."""
    parser.add_argument('--stiffness-damping', type=float, default=None, metavar='BETA_S',
                        help='stiffness-proportional damping beta [s] on the link-frame strain '
                        'rates and c = beta k on the bearing springs, added to the modal '
                        "damping ratio (to match the Exudyn peer's beta alone set that ratio "
                        'to 0: damping_ratio in the mechanism file, or --damping-ratio 0 for '
                        "simulate) (default: the mechanism file's stiffness_damping_s, else 0)")


def elements_per_link(args):
    """Beam elements per link: ``--elements-per-link``, else the default model's."""
    value = getattr(args, 'elements_per_link', None)
    return DEFAULT_MODEL.elements_per_link if value is None else value


def crank_rpm(given, mechanism, flag='--rpm', fallback=None):
    """
    Return the crank speed [rpm]: the flag's value, else the file's crank_speed_rpm.

    Parameters
    ----------
    given : float or None
        The flag's value (None: not given).
    mechanism : Mechanism
        The mechanism (its ``crank_speed``, from the file's ``crank_speed_rpm``).
    flag : str
        The flag's spelling, named in the refusal.
    fallback : float or None
        The speed where neither is given (None: refused with one line).

    """
    if given is not None:
        return float(given)
    if mechanism.crank_speed is not None:
        return mechanism.crank_speed / RPM
    if fallback is not None:
        return float(fallback)
    raise ValueError(f'give `{flag}`: the mechanism file {mechanism.name!r} has no '
                     'crank_speed_rpm')


def stiffness_damping(args, file_beta=None):
    """Beta [s]: ``--stiffness-damping``, else the mechanism file's, else 0 (flag > file)."""
    value = getattr(args, 'stiffness_damping', None)
    if value is None:
        return read_mechanism_file(args.mechanism)[1] if file_beta is None else file_beta
    if not value >= 0.0 or value == float('inf'):
        raise ValueError(f'`--stiffness-damping` must be >= 0 [s], got {value!r}')
    return float(value)


def add_order_argument(parser):
    """
    Add ``--order {1,2}``: the linear KED outputs, or plus their second-order part.

    Parameters
    ----------
    parser : argparse.ArgumentParser
        A subcommand's parser.

    """
    parser.add_argument('--order', type=int, choices=ORDERS, default=DEFAULT_MODEL.order,
                        help='1: the linear KED outputs of the paper; 2: plus the '
                        "second-order motion of the bent links' chord shortening "
                        '(default: %(default)s)')


def add_second_order_argument(parser):
    """Add ``--second-order {quasi-static,dynamic}`` (the estimator's; node model.second_order)."""
    parser.add_argument('--second-order', choices=SECOND_ORDER_PASSES, default=None,
                        help='how order 2 is computed: quasi-static (the chord shortening of '
                        'the linear shapes) or dynamic (also the inertia of the second-order '
                        'motion: a second reduced state per sample, on a larger basis by '
                        'default, about +20 us per sample; the lever tip and coupler '
                        'mid-point) (default: quasi-static)')


def add_reduced_arguments(parser):
    """
    Add the flags of the reduced model and its input: sizes, sample rate, cache, JSON.

    Parameters
    ----------
    parser : argparse.ArgumentParser
        A subcommand's parser.

    """
    parser.add_argument('--modes', type=int,
                        help='basis directions from frozen modes (default: by bearings and '
                        'crank model)')
    parser.add_argument('--static', type=int,
                        help='basis directions from static responses (default: by bearings '
                        'and crank model)')
    parser.add_argument('--grid-size', type=int,
                        help=f'crank-angle grid points (default: {DEFAULT_MODEL.grid_size})')
    parser.add_argument('--soft-modes', type=int, metavar='P',
                        help='the estimator steps the P lowest modes of the reduced model '
                        '(a smooth basis at a checked spectral gap; refused without a gap '
                        'there); -1 (default): the smallest P at a usable gap, or all r '
                        'coordinates where there is none; 0: all r coordinates')
    parser.add_argument('--rate-hz', type=float, default=1000.0,
                        help='sample rate [Hz] (default: %(default)s)')
    parser.add_argument('--cache-dir', default=None,
                        help='model cache directory (default: ~/.cache/flexlink_ros)')
    parser.add_argument('--no-cache', action='store_true', help='build without the cache')
    parser.add_argument('--json', action='store_true', help='print one JSON object')


def add_estimator_arguments(parser, second_order=True):
    """
    Add the flags of the estimator's subcommands (estimate, plan, replay; the estimator benchmark).

    Parameters
    ----------
    parser : argparse.ArgumentParser
        A subcommand's parser.
    second_order : bool
        Also ``--second-order`` (not on plan, whose reference is quasi-static).

    """
    add_model_arguments(parser)
    add_stiffness_damping_argument(parser)
    add_order_argument(parser)
    if second_order:
        add_second_order_argument(parser)
    add_reduced_arguments(parser)


def model_options(args, read=None, **overrides):
    """
    Build the reduced model's options from the command-line arguments, with overrides.

    Without flags the default model (:class:`core.options.ModelOptions`, as the node); sizes
    not given are the defaults for the chosen bearing and crank models
    (core.options.DEFAULT_SIZES). The speed range is ``--rpm-max`` with a 5 % margin where
    given, else the mechanism file's (:func:`core.options.speed_range`); the file is read once.

    Parameters
    ----------
    args : argparse.Namespace
        Parsed flags of :func:`add_estimator_arguments`.
    read : tuple, optional
        ``--mechanism``'s file as :func:`core.mechanism_file.read_mechanism_file` gave it
        (Mechanism, ``stiffness_damping_s``), when the caller has read it.
    **overrides
        Fields set whatever the flags say.

    Returns
    -------
    ModelOptions

    """
    mechanism, file_beta = read_mechanism_file(args.mechanism) if read is None else read
    values = {'rigid_crank': bool(args.rigid_crank), 'bearings': args.bearings,
              'geometric_stiffness': not args.no_geometric_stiffness,
              'elements_per_link': elements_per_link(args),
              'speed_max': speed_range(mechanism.crank_speed)}
    for name in ('modes', 'static', 'grid_size', 'order', 'soft_modes', 'second_order'):
        value = getattr(args, name, None)
        if value is not None:
            values[name] = value
    if getattr(args, 'rpm_max', None):
        values['speed_max'] = max(DEFAULT_SPEED_MAX, 1.05 * args.rpm_max * RPM)
    values['stiffness_damping'] = stiffness_damping(args, file_beta)
    values.update(overrides)
    return ModelOptions(**values)


def add_chart_argument(parser):
    """Add ``--chart PNG`` (replay, estimate): deflections and criteria over crank angle."""
    parser.add_argument('--chart', metavar='PNG',
                        help='also draw the deflections and joint criteria over crank angle '
                        'into this PNG')


def criterion_thresholds(mechanism=None):
    """
    Return the charts' WARN and ERROR criterion levels [rad/(s N)] and what they are.

    A mechanism file with a ``crank_speed_rpm``: its own cycle's at that speed, the levels
    ``flexlink plan --params-out`` gives the node (:func:`core.criteria_thresholds.
    suggest_thresholds`); the paper's 100 / 1000 mean nothing for another machine. Otherwise
    the node's defaults.

    Returns
    -------
    (float, float, str)

    """
    if mechanism is not None and mechanism.crank_speed:
        found = suggest_thresholds(mechanism, mechanism.crank_speed)
        return found['warn'], found['error'], f"this linkage's cycle at {found['rpm']:.4g} rpm"
    values = node_params.defaults()
    return (values['diagnostics.criterion_warn'], values['diagnostics.criterion_error'],
            'node default')


def load_model(mechanism, options, args):
    """
    Load the cached (or freshly built) reduced model for the command line.

    A build shows its percentage on stderr (:class:`.progress.OnDemandProgress`); a cached
    model loads silently.

    Parameters
    ----------
    mechanism : Mechanism
        The mechanism.
    options : ModelOptions
        The model's options.
    args : argparse.Namespace
        Parsed flags (``--cache-dir``, ``--no-cache``).

    Returns
    -------
    ReducedModel

    """
    with OnDemandProgress(BUILD_LABEL) as progress:
        return mechanism_model.model_for_mechanism(mechanism, options, cache_dir=args.cache_dir,
                                                   use_cache=not args.no_cache, progress=progress)
