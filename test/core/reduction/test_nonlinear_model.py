"""The reduced nonlinear model of a mechanism: damping rule, cached tables (nonlinear_model.py)."""

import dataclasses

from flexlink_ros.core.fe.linkage import FlexibleLinkage
from flexlink_ros.core.mechanism_file import load_mechanism
from flexlink_ros.core.options import ModelOptions
from flexlink_ros.core.reduction import nonlinear_model
from flexlink_ros.core.reduction.nonlinear_tables import NonlinearTables
import numpy as np
import scipy.linalg

OPTIONS = ModelOptions(rigid_crank=True, elements_per_link=2, stiffness_damping=1e-4)


def test_beta_is_the_stiffness_damping_or_gives_the_first_mode_the_files_zeta():
    mech = dataclasses.replace(load_mechanism('cho1992'), elements_per_link=2)
    linkage = FlexibleLinkage(mech, OPTIONS)
    assert nonlinear_model.nonlinear_beta(linkage, 1e-4, 0.02)[0] == 1e-4
    beta, how = nonlinear_model.nonlinear_beta(linkage, 0.0, 0.02)
    system = linkage.assemble(np.array([0.0]))
    values, shapes = scipy.linalg.eigh(system.stiffness[0], system.mass[0])
    first = shapes[:, 0]
    # the modal damping ratio of beta K on the first mode is the file's zeta
    zeta = first @ (beta * system.stiffness[0]) @ first / (2.0 * np.sqrt(values[0]))
    assert abs(zeta - 0.02) < 1e-9 and 'zeta' in how
    assert nonlinear_model.nonlinear_beta(linkage, 0.0, 0.0)[0] == 0.0


def test_tables_are_cached_and_read_back(tmp_path):
    mech = load_mechanism('cho1992')
    built, how = nonlinear_model.nonlinear_model_for(mech, OPTIONS, cache_dir=tmp_path)
    files = sorted(p.name for p in tmp_path.rglob('*-nonlinear.npz'))
    assert len(files) == 1 and 'stiffness damping' in how
    again, _ = nonlinear_model.nonlinear_model_for(mech, OPTIONS, cache_dir=tmp_path)
    assert isinstance(again, NonlinearTables) and again.beta == 1e-4
    np.testing.assert_array_equal(again.values, built.values)
    np.testing.assert_array_equal(again.basis, built.basis)
    assert again.at(0.3)['mass'].shape == (1, built.size, built.size)


def test_basis_size_is_part_of_the_cache_key(tmp_path):
    mech = load_mechanism('cho1992')
    ruled, _ = nonlinear_model.nonlinear_model_for(mech, OPTIONS, cache_dir=tmp_path)
    fixed, _ = nonlinear_model.nonlinear_model_for(mech, OPTIONS, cache_dir=tmp_path,
                                                   basis_size=ruled.size - 2)
    assert fixed.size == ruled.size - 2
    assert len(list(tmp_path.rglob('*-nonlinear.npz'))) == 2
    again, _ = nonlinear_model.nonlinear_model_for(mech, OPTIONS, cache_dir=tmp_path)
    assert again.size == ruled.size
