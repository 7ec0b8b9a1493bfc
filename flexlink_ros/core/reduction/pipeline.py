"""
Reduced models of a mechanism: the full-order pieces from the FE model, built or cached.

:func:`model_for_mechanism` loads a verified cache file (:mod:`.store`) or builds the model
from the frozen system of core/fe/linkage.py on the crank-angle grid, the modal damping of its
frozen modes and the rigid-body joint reactions of core/dynamics.py.
"""

import dataclasses

import numpy as np
import scipy.linalg

from . import second_order_tables, store
from .basis import FrozenSamples
from .build import reduce_samples
from .model import ReducedModel
from .. import dynamics
from ..fe import linkage as assembly
from ..options import MODEL_VERSION, ModelOptions

# Points per beam element where link shapes are tabulated (3 elements: 10 points per link).
SHAPE_POINTS_PER_ELEMENT = 3


def model_key(mechanism, options):
    """Cache key of a mechanism's reduced model (hex)."""
    # {'criteria': True} keeps the keys of models cached when the reactions were optional.
    return store.cache_key('reduced-model', MODEL_VERSION, mechanism.key(),
                           options.cache_fields(), {'criteria': True})


def model_for_mechanism(mechanism, options=None, cache_dir=None, use_cache=True):
    """
    Return the reduced model of a mechanism: from a verified cache file, or built (and cached).

    Parameters
    ----------
    mechanism : Mechanism
        The linkage.
    options : ModelOptions or None
        Model options (None: the defaults).
    cache_dir : str, Path or None
        Cache directory (None: core.store.default_cache_dir()).
    use_cache : bool
        False builds without reading or writing a cache.

    Returns
    -------
    ReducedModel

    """
    options = options or ModelOptions()
    key = model_key(mechanism, options)
    path = None
    if use_cache:
        directory = store.default_cache_dir() if cache_dir in (None, '') else cache_dir
        path = f'{directory}/{mechanism.name}-{key[:16]}.npz'

    def build():
        return build_model(mechanism, options).to_arrays()

    arrays, meta, _ = store.load_or_build(path, key, build)
    return ReducedModel.from_arrays(arrays, meta)


def build_model(mechanism, options):
    """Precompute the reduced model of a mechanism (full-order pieces from core/assembly.py)."""
    samples = frozen_samples_for(mechanism, options)
    angles = 2.0 * np.pi * np.arange(options.grid_size) / options.grid_size
    forces, criteria_source = reaction_pieces(mechanism, angles)
    model = reduce_samples(samples, options.modes, options.static, options.speed_max,
                           mechanism.damping_ratio, forces=forces,
                           info={'options': options.cache_fields(),
                                 'mechanism': mechanism.name, 'criteria': criteria_source})
    if options.order == 1:
        return model
    linkage = assembly.FlexibleLinkage(fe_mechanism(mechanism, options), options)
    return dataclasses.replace(model, second_order=second_order_tables.build_tables(
        linkage, model.basis, options.grid_size))


def fe_mechanism(mechanism, options):
    """Return the mechanism with the element count of ``options`` (if set)."""
    if options.elements_per_link is None:
        return mechanism
    return dataclasses.replace(mechanism, elements_per_link=int(options.elements_per_link))


def modal_damping_matrix(mass, stiffness, zeta):
    """
    ``C_d = M Phi diag(2 zeta omega) Phi^T M`` over all frozen modes (as core/modes.py).

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
    Full-order affine pieces of the flexible model (core/assembly.py) on the crank-angle grid.

    The frozen eigenproblem and the modal damping use ``K + K_G(w, a)`` as core/modes.py does
    (no centrifugal term); the equations of motion add the rotating-frame terms K_c.

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

    def damping(k, w):
        stiff = frozen['1'][k] + w * w * frozen['w2'][k]
        return modal_damping_matrix(system.mass[k], stiff, zeta)

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
