"""
Reduced models of a mechanism: the full-order pieces from the FE model, built or cached.

:func:`model_for_mechanism` loads a verified cache file (:mod:`.store`) or builds the model
from the frozen system of core/fe/linkage.py on the crank-angle grid, the modal damping of its
frozen modes and the rigid-body joint reactions of core/dynamics.py.
"""

import dataclasses
import logging

import numpy as np
import scipy   # scipy.linalg loads on first use: a replay from the cache never needs it

from . import second_order_dynamic_tables, second_order_tables, store
from .basis import FrozenSamples
from .build import reduce_samples
from .build_progress import BuildProgress
from .cache_location import cache_file
from .model import ReducedModel
from .nonlinearity_tables import nonlinearity_tables, NONLINEARITY_VERSION
from .soft_tables import soft_tables, SOFT_TABLES_VERSION
from .. import dynamics
from ..fe import linkage as assembly
from ..fe.stiffness_damping import stiffness_damping_terms
from ..options import MODEL_VERSION, ModelOptions
from ...errors import FlexlinkError

LOGGER = logging.getLogger(__name__)

# Points per beam element where link shapes are tabulated (3 elements: 10 points per link).
SHAPE_POINTS_PER_ELEMENT = 3


def model_key(mechanism, options):
    """Cache key of a mechanism's reduced model (hex)."""
    # {'criteria': True} keeps the keys of models cached when the reactions were optional.
    return store.cache_key('reduced-model', MODEL_VERSION, mechanism.key(),
                           options.cache_fields(), {'criteria': True})


def model_for_mechanism(mechanism, options=None, cache_dir=None, use_cache=True, progress=None):
    """
    Return the reduced model of a mechanism: from a verified cache file, or built (and cached).

    Parameters
    ----------
    mechanism : Mechanism
        The linkage.
    options : ModelOptions or None
        Model options (None: the defaults).
    cache_dir : str, Path or None
        Cache directory (None: core.reduction.store.default_cache_dir()); read and written only if
        trusted (:mod:`.cache_location`), the files named there whatever the mechanism's
        name says.
    use_cache : bool
        False builds without reading or writing a cache.
    progress : callable or None
        ``progress(done, total, what)`` while a model is built (not called on a cache hit);
        see :class:`.build_progress.BuildProgress`.

    Returns
    -------
    ReducedModel

    """
    options = options or ModelOptions()
    key = model_key(mechanism, options)
    directory = None
    if use_cache:
        directory = store.usable_cache_dir(store.default_cache_dir() if cache_dir in (None, '')
                                           else cache_dir)

    def build():
        return build_model(mechanism, options, progress).to_arrays()

    def place(suffix):
        return None if directory is None else cache_file(directory, mechanism.name, key, suffix)

    arrays, meta, _ = store.load_or_build(place('.npz'), key, build, directory)
    model = with_nonlinearity(ReducedModel.from_arrays(arrays, meta), mechanism, options,
                              (place('-nonlinearity.npz'), directory), key)
    suffix = soft_cache_suffix(options.soft_modes)
    return with_soft_basis(model, options.soft_modes,
                           (None if suffix is None else place(suffix), directory), key)


def cached_model_values(mechanism, options, cache_dir, use_cache, name, build):
    """
    Return arrays derived from a mechanism's model, cached in a file beside the model's.

    For what costs more to compute than to read (the split replay's decay rate: eigenvalues
    at every grid angle). ``name`` ends the file's name (``-<name>.npz``) and enters its key
    with the model's key; ``build()`` returns the dict of arrays. Built, not cached, where the
    model is not (``use_cache`` False or an untrusted directory).
    """
    key = store.cache_key(name, model_key(mechanism, options))
    directory = None
    if use_cache:
        directory = store.usable_cache_dir(store.default_cache_dir() if cache_dir in (None, '')
                                           else cache_dir)
    path = (None if directory is None
            else cache_file(directory, mechanism.name, model_key(mechanism, options),
                            f'-{name}.npz'))
    arrays, _, _ = store.load_or_build(path, key, lambda: (build(), {}), directory)
    return dict(arrays)


def build_model(mechanism, options, progress=None):
    """
    Precompute the reduced model of a mechanism (full-order pieces from core/fe/linkage.py).

    ``progress(done, total, what)``, if given, follows the build (:mod:`.build_progress`).
    """
    tracker = BuildProgress(progress, options.grid_size)
    samples = tracker.follow(frozen_samples_for(mechanism, options))
    angles = 2.0 * np.pi * np.arange(options.grid_size) / options.grid_size
    forces, criteria_source = reaction_pieces(mechanism, angles)
    model = reduce_samples(samples, options.modes, options.static, options.speed_max,
                           mechanism.damping_ratio, forces=forces,
                           info={'options': options.cache_fields(),
                                 'mechanism': mechanism.name, 'criteria': criteria_source})
    if options.order == 2:
        linkage = assembly.FlexibleLinkage(fe_mechanism(mechanism, options), options)
        model = dataclasses.replace(model, second_order=second_order_tables.build_tables(
            linkage, model.basis, options.grid_size))
        if options.second_order == 'dynamic':
            model = dataclasses.replace(
                model, dynamic_second_order=second_order_dynamic_tables.build_tables(
                    linkage, model.basis, options.grid_size))
    tracker.finish()
    return model


def with_nonlinearity(model, mechanism, options, place, key):
    """
    Return the model with the validity indicator's tables (:mod:`.nonlinearity_tables`).

    Cached in a file of their own beside the model's (``place``: the file and the cache
    directory, or None twice: built, not cached), keyed by the model's key and
    :data:`NONLINEARITY_VERSION`: the model's own file and key are those of a model without
    the tables.
    """
    def build():
        linkage = assembly.FlexibleLinkage(fe_mechanism(mechanism, options), options)
        samples = frozen_samples_for(mechanism, options)
        return nonlinearity_tables(linkage, samples, model, options.speed_max), {}

    path, root = place
    arrays, _, _ = store.load_or_build(
        path, store.cache_key('nonlinearity-tables', NONLINEARITY_VERSION, key), build, root)
    return dataclasses.replace(model, nonlinearity=arrays)


def soft_cache_suffix(soft_modes):
    """End of the name of a model's soft-basis tables' cache file (None: no tables)."""
    if soft_modes == 0:
        return None
    return f'-soft{soft_modes if soft_modes > 0 else ""}.npz'


def with_soft_basis(model, soft_modes, place=(None, None), key=None):
    """
    Return the model with the soft-basis step tables (:mod:`.soft_tables`), as asked.

    The tables (eigenproblems, a matrix logarithm and exponentials at every grid node: most of
    a cached model's load) are cached in a file of their own beside the model's (``place``:
    the file and the cache directory, or None twice: built, not cached), keyed by the model's
    ``key``, :data:`.soft_tables.SOFT_TABLES_VERSION` and ``soft_modes``.

    ``soft_modes`` as :class:`~core.options.ModelOptions` takes it: -1 uses the smallest
    usable gap, or none (with the reason in ``info['soft']``); p > 0 refuses a model without
    a gap there (FlexlinkError); 0 leaves the model as it is. A model with the dynamic
    second-order pass keeps all its coordinates (the pass steps a second reduced state
    beside them: core/estimation/second_order_dynamic_step.py).
    """
    if soft_modes == 0 or model.dynamic_second_order is not None:
        reason = 'off' if soft_modes == 0 else 'the dynamic second-order pass'
        if soft_modes > 0:
            raise FlexlinkError('the soft basis and the dynamic second-order pass do not go '
                                'together: the pass steps the reduced coordinates')
        return dataclasses.replace(model, info={**model.info, 'soft': {'used': False,
                                                                       'reason': reason}})
    try:
        soft = _cached_soft_tables(model, soft_modes, place, key)
    except FlexlinkError as exc:
        if soft_modes > 0:
            raise
        LOGGER.warning('stepping all %d coordinates: %s', model.size, exc)
        return dataclasses.replace(model, info={**model.info, 'soft': {'used': False,
                                                                       'reason': str(exc)}})
    gap = soft.pop('soft_gap')
    size = soft['soft_phi'].shape[2] // model.size
    info = {**model.info, 'soft': {'used': True, 'size': size,
                                   'gap_ratio': float(gap[size - 1]) if size < gap.size + 1
                                   else None}}
    return dataclasses.replace(model, soft=soft, info=info)


def _cached_soft_tables(model, soft_modes, place, key):
    """soft_tables of the model, from (or into) its cache file if there is one."""
    path, root = place
    if path is None:
        return soft_tables(model, soft_modes)
    arrays, _, _ = store.load_or_build(
        path, store.cache_key('soft-tables', SOFT_TABLES_VERSION, key, soft_modes),
        lambda: (soft_tables(model, soft_modes), {}), root)
    return dict(arrays)


def fe_mechanism(mechanism, options):
    """Return the mechanism with the element count of ``options`` (if set)."""
    if options.elements_per_link is None:
        return mechanism
    return dataclasses.replace(mechanism, elements_per_link=int(options.elements_per_link))


def modal_damping_matrix(mass, stiffness, zeta):
    """
    ``C_d = M Phi diag(2 zeta omega) Phi^T M`` over all frozen modes (as core/fe/modes.py).

    Parameters
    ----------
    mass, stiffness : ndarray, shape (n, n)
        Mass and symmetric frozen stiffness.
    zeta : float
        Damping ratio of every mode.

    Returns
    -------
    ndarray, shape (n, n)

    """
    eigenvalues, shapes = scipy.linalg.eigh(stiffness, mass)
    left = mass @ shapes
    return (left * (2.0 * zeta * np.sqrt(np.maximum(eigenvalues, 0.0)))) @ left.T


def frozen_samples_for(mechanism, options, points_per_element=SHAPE_POINTS_PER_ELEMENT):
    """
    Full-order affine pieces of the flexible model (core/fe/linkage.py) on the crank-angle grid.

    The frozen eigenproblem and the modal damping use ``K + K_G(w, a)`` as core/fe/modes.py does
    (no centrifugal term); the equations of motion add the rotating-frame terms K_c. With
    ``options.stiffness_damping`` (beta > 0) the objective Kelvin-Voigt damping of
    core/fe/stiffness_damping.py is added: ``C_beta = beta K`` to the damping and
    ``D_beta = w Kb1`` as the stiffness piece 'w' (linear in the crank speed). With beta = 0
    nothing changes (no piece 'w', the same damping).

    """
    mechanism = fe_mechanism(mechanism, options)
    linkage = assembly.FlexibleLinkage(mechanism, options)
    angles = 2.0 * np.pi * np.arange(options.grid_size) / options.grid_size
    system = linkage.assemble(angles)
    frozen = {'1': system.stiffness + system.geometric['1'], 'a': system.geometric['a'],
              'w2': system.geometric['w2']}
    stiffness = {'1': frozen['1'], 'a': system.coupling['a'] + system.geometric['a'],
                 'w2': system.coupling['w2'] + system.geometric['w2']}
    positions, operator = linkage.shape_operator(angles, points_per_element)
    zeta = mechanism.damping_ratio
    beta = options.stiffness_damping
    beta_damping = None
    if beta:
        # D_beta at unit crank speed is Kb1: the stiffness piece of monomial w.
        beta_damping, stiffness['w'] = stiffness_damping_terms(linkage, angles, 1.0, beta)

    def damping(k, w):
        stiff = frozen['1'][k] + w * w * frozen['w2'][k]
        modal = modal_damping_matrix(system.mass[k], stiff, zeta)
        return modal if beta_damping is None else modal + beta_damping[k]

    return FrozenSamples(mass=system.mass, gyroscopic=system.gyroscopic, stiffness=stiffness,
                         load=dict(system.load), outputs=linkage.output_operator(angles),
                         damping=damping, shape_operator=operator, shape_positions=positions,
                         frozen=frozen)


def reaction_pieces(mechanism, angles):
    """
    Rigid-body joint reactions F = F_1 + a F_a + w^2 F_w2 and dF/dtheta on the grid.

    From core/dynamics.py (Newton-Euler, reactions across each bearing with the mechanism's
    joint-mass split; spring and gravity in F_1).

    Returns
    -------
    forces : dict
        As :func:`reduce_samples` takes them.
    source : str
        Where the reactions come from.

    """
    pieces = dynamics.reaction_pieces(mechanism, angles)
    forces = {'force': pieces['force'], 'force_rate': pieces['force_rate']}
    return forces, 'rigid-body Newton-Euler reactions (core/dynamics.py)'
