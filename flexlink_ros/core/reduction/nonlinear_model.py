"""
The reduced nonlinear model of a mechanism: its damping rule and its cached tables.

Damping (the rule the streaming nonlinear model states). The nonlinear model damps the
nonlinear strain rate by Kelvin-Voigt ``beta`` (and the bearing springs by ``beta k``), as
the nonlinear full order and the peer do: ``beta`` is the options' ``stiffness_damping``
when it is not 0; otherwise, with a modal ``damping_ratio`` zeta in the mechanism file,
``beta = 2 zeta / omega_1`` (omega_1: the lowest frozen frequency at crank angle 0, at rest),
the stiffness-proportional damping that gives the first mode the file's zeta (higher modes
more, ``zeta_i = zeta omega_i / omega_1``); with neither, 0.

The tables (:mod:`.nonlinear_tables`) are cached like the other tables of the model (npz,
checksummed, never pickled; :func:`.store.load_or_build`), keyed by the mechanism, the
options, ``beta`` and the basis (its size, or the rule that sizes it).

The basis size (:func:`.nonlinear_tables.basis_size`): by default every direction of the
snapshot POD down to 1e-3 of the largest singular value (20 vectors for cho1992 with bearing
springs and 8 elements per link, 14 with pins); ``basis_size`` fixes it instead.
"""

import numpy as np

from . import store
from .basis import frozen_modes
from .cache_location import cache_file
from .mechanism_model import fe_mechanism
from .nonlinear_tables import (BASIS_MODES, BASIS_TOLERANCE, build_nonlinear_tables,
                               NonlinearTables)
from ..fe.linkage import FlexibleLinkage

NONLINEAR_VERSION = 3


def nonlinear_beta(linkage, stiffness_damping, damping_ratio):
    """
    Return (beta [s], how it was chosen) by the rule of the module notes.

    ``linkage``: the :class:`FlexibleLinkage` (its first frozen mode at rest is used only
    when beta is derived from zeta).
    """
    if stiffness_damping > 0.0:
        return float(stiffness_damping), f'beta {stiffness_damping:g} s (stiffness damping)'
    if damping_ratio > 0.0:
        system = linkage.assemble(np.array([0.0]))
        omega, _ = frozen_modes(system.stiffness[0], system.mass[0], 1)
        beta = 2.0 * damping_ratio / float(omega[0])
        return beta, (f'beta {beta:.3g} s = 2 zeta / omega_1 (zeta {damping_ratio:g} at '
                      f'{omega[0] / (2.0 * np.pi):.1f} Hz)')
    return 0.0, 'undamped (no stiffness damping, zeta 0)'


def nonlinear_model_for(mechanism, options, cache_dir=None, use_cache=True, basis_size=None):
    """
    Return (NonlinearTables, damping text) of a mechanism with model options.

    Cached in ``cache_dir`` (None: the default cache directory) unless ``use_cache`` is False.
    ``basis_size``: the basis's vectors (None: as the snapshots' singular values say).
    """
    linkage = FlexibleLinkage(fe_mechanism(mechanism, options), options)
    beta, how = nonlinear_beta(linkage, options.stiffness_damping, mechanism.damping_ratio)
    key = store.cache_key('nonlinear-tables', NONLINEAR_VERSION, mechanism.key(),
                          options.cache_fields(), {'beta': beta},
                          {'basis_size': 'rule' if basis_size is None else int(basis_size),
                           'basis_modes': BASIS_MODES, 'basis_tolerance': BASIS_TOLERANCE})
    directory = None
    if use_cache:
        directory = store.usable_cache_dir(store.default_cache_dir() if cache_dir in (None, '')
                                           else cache_dir)
    path = None if directory is None else cache_file(directory, mechanism.name, key,
                                                     '-nonlinear.npz')
    arrays, meta, _ = store.load_or_build(
        path, key, lambda: build_nonlinear_tables(linkage, beta, size=basis_size).to_arrays(),
        directory)
    return NonlinearTables.from_arrays(arrays, meta), how


__all__ = ['NONLINEAR_VERSION', 'nonlinear_beta', 'nonlinear_model_for']
