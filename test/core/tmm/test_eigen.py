"""Stiffness-based beam frequencies (core/tmm/eigen.py): bounds and solver paths."""

from flexlink_ros.core.tmm import beams, eigen, exact, solve
import numpy as np
import pytest

BEAM = beams.UniformBeam.kim_moon()
BCS = beams.BOUNDARY_CONDITIONS


@pytest.mark.parametrize('bc', BCS)
def test_consistent_mass_fe_bounds_from_above(bc):
    continuous = exact.exact_frequencies(BEAM, bc, 3)
    for elements in (3, 5, 11):
        assert np.all(eigen.fe_frequencies(BEAM, bc, elements, 3) > continuous)


@pytest.mark.parametrize('bc', BCS)
def test_sparse_and_dense_eigen_paths_agree(bc, monkeypatch):
    # 1e-8: stiffness-based solves of 80 DOFs sit near their round-off floor, eps (L/h)^4
    model = beams.lump_masses(BEAM, 40, 3, bc)
    sparse_fe = eigen.fe_frequencies(BEAM, bc, 40, 4)
    sparse_lumped = eigen.lumped_frequencies(model, bc, 4)
    monkeypatch.setattr(eigen, 'DENSE_EIGEN_LIMIT', 10_000)
    np.testing.assert_allclose(sparse_fe, eigen.fe_frequencies(BEAM, bc, 40, 4), rtol=1e-8)
    np.testing.assert_allclose(sparse_lumped, eigen.lumped_frequencies(model, bc, 4), rtol=1e-8)
    np.testing.assert_allclose(sparse_lumped, solve.tmm_frequencies(BEAM, bc, 40, 3, 4, 'newton',
                                                                    50.0).frequencies_rad_s,
                               rtol=1e-8)


def test_supported_lumping_1_and_3_coincide():
    # observed: with both ends simply supported, masses m/n at segment centres (method 1)
    # and at division points plus inert end halves (method 3) share every lower frequency
    for n in (3, 6, 11):
        centres = eigen.lumped_frequencies(beams.lump_masses(BEAM, n, 1, 'supported'), 'supported')
        nodes = eigen.lumped_frequencies(beams.lump_masses(BEAM, n, 3, 'supported'), 'supported')
        np.testing.assert_allclose(centres[:n - 1], nodes, rtol=1e-10)
