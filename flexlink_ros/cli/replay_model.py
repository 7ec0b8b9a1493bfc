"""
The model ``flexlink replay`` runs: the one the recording says made it, or the flags'.

A recording made by the node (or by ``replay --out``) carries its mechanism file, damping
ratio and resolved model options (:mod:`io.provenance`); replay takes them by default, so its
estimates are the node's. A model flag or ``--mechanism`` given on the command line that
differs from the recorded value is used, with one note saying so. A recording that names no
model (``ros2 bag record``, ``flexlink mcap-record``, an older version) needs ``--mechanism``
and is refused without it (:class:`MissingModel`, exit code 2).
"""

from .model_args import model_options
from ..core.mechanism_file import load_mechanism, read_mechanism_file, read_mechanism_source, \
    stiffness_damping_from_file
from ..core.options import ModelOptions
from ..io.provenance import mechanism_bytes, provenance_entries, ProvenanceError, \
    read_provenance

# Flags whose default must be told from a value given (their real defaults are kept aside).
DEFERRED_FLAGS = ('mechanism', 'rigid_crank', 'bearings', 'order', 'no_geometric_stiffness',
                  'joint')
# ModelOptions field -> (flag, value of the parsed flags; None where the flag was not given).
FLAG_FIELDS = {
    'rigid_crank': ('--rigid-crank/--flexible-crank', lambda a: a.rigid_crank),
    'bearings': ('--bearings', lambda a: a.bearings),
    'elements_per_link': ('--elements-per-link', lambda a: a.elements_per_link),
    'geometric_stiffness': ('--no-geometric-stiffness',
                            lambda a: False if a.no_geometric_stiffness else None),
    'stiffness_damping': ('--stiffness-damping', lambda a: a.stiffness_damping),
    'order': ('--order', lambda a: a.order),
    'second_order': ('--second-order', lambda a: a.second_order),
    'modes': ('--modes', lambda a: a.modes),
    'static': ('--static', lambda a: a.static),
    'grid_size': ('--grid-size', lambda a: a.grid_size),
    'soft_modes': ('--soft-modes', lambda a: a.soft_modes),
}
PRODUCER = 'flexlink replay'


class MissingModel(ValueError):
    """The recording names no model and no ``--mechanism`` was given (exit code 2)."""


def defer_model_defaults(parser):
    """
    Make the model flags' defaults None, so a flag given can be told from its default.

    The real defaults are kept in ``args.flag_defaults`` for a recording that names no model.
    """
    kept = {name: parser.get_default(name) for name in DEFERRED_FLAGS}
    parser.set_defaults(flag_defaults=kept, **dict.fromkeys(DEFERRED_FLAGS))
    for action in parser._actions:   # the help says where the default now comes from
        if action.dest in kept and action.help and '%(default)s' in action.help:
            action.help = action.help.replace(
                '%(default)s', f"the recording's, else {kept[action.dest]}")


def replay_model(args):
    """
    Choose the mechanism and model options of a replay; say where they came from.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed flags of ``flexlink replay`` (after :func:`defer_model_defaults`);
        ``joint`` and ``no_warm_start`` are set from the recording where not given.

    Returns
    -------
    mechanism : Mechanism
    options : ModelOptions
    notes : list of str
        One line per flag that overrides the recording, or why the flags' model is used.
    provenance : dict
        What the replay's own output records (:func:`io.provenance.provenance_entries`).

    Raises
    ------
    MissingModel
        The recording names no model and ``--mechanism`` is missing.
    io.provenance.ProvenanceError
        The recording's record cannot be used and ``--mechanism`` is missing.

    """
    try:
        recorded = read_provenance(args.input)
    except ProvenanceError as exc:
        if args.mechanism is None:
            raise
        recorded, broken = None, f'{exc}; using --mechanism {args.mechanism} and the flags'
    else:
        broken = None
    args.recorded_provenance = recorded
    if recorded is None or not recorded.has_model:
        return _flags_model(args, recorded, broken)
    notes = []
    mechanism, raw, file_beta = _recorded_mechanism(args, recorded, notes)
    values = dict(recorded.model_options)
    if file_beta is not None and args.stiffness_damping is None:
        values['stiffness_damping'] = file_beta
    for field, (flag, read) in FLAG_FIELDS.items():
        given = read(args)
        if given is not None and given != values.get(field):
            notes.append(f"{flag} {given} differs from the recording's {values.get(field)}: "
                         f'using {given}')
            values[field] = given
    options = ModelOptions(**values)
    _recorded_estimator(args, recorded, notes)
    provenance = provenance_entries(PRODUCER, mechanism=raw[0], options=options,
                                    damping_ratio=mechanism.damping_ratio,
                                    crank_joint=args.joint, warm_start=not args.no_warm_start,
                                    raw=raw[1])
    return mechanism, options, notes, provenance


def _recorded_mechanism(args, recorded, notes):
    """Return the recorded mechanism, or ``--mechanism``'s where it differs (and its beta)."""
    recorded_raw = recorded.mechanism_yaml.encode('utf-8')
    if args.mechanism is None:
        return recorded.mechanism(), (recorded.mechanism_file, recorded_raw), None
    path, raw = mechanism_bytes(args.mechanism)
    if raw == recorded_raw:
        return recorded.mechanism(), (recorded.mechanism_file, recorded_raw), None
    notes.append(f"--mechanism {args.mechanism} differs from the recording's "
                 f'{recorded.mechanism_file}: using {path} (its damping and stiffness damping)')
    return load_mechanism(path, raw=raw), (str(path), raw), stiffness_damping_from_file(
        path, raw=raw)


def _recorded_estimator(args, recorded, notes):
    """Take the recorded crank joint and warm start where the flags say nothing."""
    if args.joint is None:
        args.joint = recorded.crank_joint
    elif args.joint != recorded.crank_joint:
        notes.append(f"--joint {args.joint} differs from the recording's "
                     f'{recorded.crank_joint}: using {args.joint}')
    if args.no_warm_start and recorded.warm_start:
        notes.append('--no-warm-start differs from the recording (warm start): using a static '
                     'start')
    args.no_warm_start = args.no_warm_start or not recorded.warm_start


def with_flag_defaults(args):
    """Return the parsed flags with the deferred ones at their real defaults if not given."""
    filled = dict(vars(args))
    for name, default in args.flag_defaults.items():
        if filled.get(name) is None:
            filled[name] = default
    return type(args)(**filled)


def _flags_model(args, recorded, broken):
    """Return the flags' model, for a recording that names none (``--mechanism`` needed)."""
    if args.mechanism is None:
        made = '' if recorded is None else f' (made by {recorded.producer} {recorded.version})'
        raise MissingModel(f'{args.input} does not say which mechanism and model made it{made}:'
                           ' give --mechanism FILE (and the model flags it was run with)')
    filled = with_flag_defaults(args)
    args.joint = filled.joint
    # Read once: the model and the provenance describe the same bytes.
    path, raw = read_mechanism_source(args.mechanism)
    mechanism, file_beta = read_mechanism_file(path, raw)
    options = model_options(filled, read=(mechanism, file_beta))
    notes = [broken or f'the recording names no model: using --mechanism {args.mechanism} '
             'and the flags']
    provenance = provenance_entries(PRODUCER, mechanism=str(path.resolve()), options=options,
                                    damping_ratio=mechanism.damping_ratio,
                                    crank_joint=args.joint, warm_start=not args.no_warm_start,
                                    raw=raw)
    return mechanism, options, notes, provenance
