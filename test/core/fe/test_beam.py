"""Cho 1992 element matrices against quadrature of their shape functions (Appendix A)."""

from flexlink_ros.core.fe import beam
import numpy as np
import pytest

RHO, AREA, E, I, L = 7718.0, 1.44e-5, 2.19e11, 1.153e-12, 0.0873
GAUSS_X, GAUSS_W = np.polynomial.legendre.leggauss(8)  # exact to degree 15
X = 0.5 * L * (GAUSS_X + 1.0)
W = 0.5 * L * GAUSS_W


def _integrate(values):
    return np.einsum('n,n...->...', W, values)


def _derivative(fun, x, h=1e-7):
    return (fun(x + h) - fun(x - h)) / (2 * h)


def test_shape_functions_interpolate_nodal_dofs():
    h = beam.shape_functions(np.array([0.0, L]), L)
    # at x=0: u_x = u1, u_y = v1; at x=L: u_x = u4, u_y = v5
    np.testing.assert_allclose(h[0], [[1, 0, 0, 0, 0, 0], [0, 1, 0, 0, 0, 0]], atol=1e-15)
    np.testing.assert_allclose(h[1], [[0, 0, 0, 1, 0, 0], [0, 0, 0, 0, 1, 0]], atol=1e-15)
    slope = _derivative(lambda x: beam.shape_functions(x, L)[:, 1, :], np.array([0.0, L]))
    np.testing.assert_allclose(slope[0], [0, 0, 1, 0, 0, 0], atol=1e-7)
    np.testing.assert_allclose(slope[1], [0, 0, 0, 0, 0, 1], atol=1e-7)


def test_mass_matrices_equal_their_integrals():
    h = beam.shape_functions(X, L)
    hr = beam.rigid_shape_functions(X, L)
    m = RHO * AREA * _integrate(np.einsum('nki,nkj->nij', h, h))
    ms = RHO * AREA * _integrate(np.einsum('nki,kl,nlj->nij', h, beam.SKEW, h))
    mr = RHO * AREA * _integrate(np.einsum('nki,nkj->nij', h, hr))
    np.testing.assert_allclose(beam.beam_mass(RHO, AREA, L), m, rtol=1e-12, atol=1e-18)
    np.testing.assert_allclose(beam.beam_mass_skew(RHO, AREA, L), ms, rtol=1e-12, atol=1e-18)
    np.testing.assert_allclose(beam.beam_mass_rigid(RHO, AREA, L), mr, rtol=1e-12, atol=1e-18)


def test_stiffness_matrices_equal_their_integrals():
    # axial strain u_x' and curvature u_y'' by exact polynomial derivatives (cubic fit)
    def second(x):
        return (beam.shape_functions(x + 1e-4, L)[:, 1] - 2 * beam.shape_functions(x, L)[:, 1]
                + beam.shape_functions(x - 1e-4, L)[:, 1]) / 1e-8
    dux = _derivative(lambda x: beam.shape_functions(x, L)[:, 0], X)
    duy = _derivative(lambda x: beam.shape_functions(x, L)[:, 1], X)
    k = (E * AREA * _integrate(np.einsum('ni,nj->nij', dux, dux))
         + E * I * _integrate(np.einsum('ni,nj->nij', second(X), second(X))))
    np.testing.assert_allclose(beam.beam_stiffness(E, AREA, I, L), k, rtol=1e-5,
                               atol=1e-6 * np.abs(k).max())
    force = 37.0
    kg = force * _integrate(np.einsum('ni,nj->nij', duy, duy))
    np.testing.assert_allclose(beam.beam_geometric_stiffness(force, L), kg, rtol=1e-7,
                               atol=1e-9 * np.abs(kg).max())


def test_rigid_body_motions_are_stress_free():
    k = beam.beam_stiffness(E, AREA, I, L)
    rigid = np.array([[1, 0, 0, 1, 0, 0],          # translation along x
                      [0, 1, 0, 0, 1, 0],          # translation along y
                      [0, 0, 1, 0, L, 1]], float)  # small rotation about node 1
    np.testing.assert_allclose(k @ rigid.T, 0.0, atol=1e-9 * np.abs(k).max())
    assert np.linalg.matrix_rank(k) == 3
    assert np.all(np.linalg.eigvalsh(beam.beam_mass(RHO, AREA, L)) > 0)


@pytest.mark.parametrize('m1, m2', [(0.014, 0.0125), (0.0, 0.007)])
def test_lumped_masses_are_point_mass_integrals(m1, m2):
    h0 = beam.shape_functions(np.array([0.0]), L)[0]
    hl = beam.shape_functions(np.array([L]), L)[0]
    point = m1 * h0.T @ h0 + m2 * hl.T @ hl
    point_skew = m1 * h0.T @ beam.SKEW @ h0 + m2 * hl.T @ beam.SKEW @ hl
    np.testing.assert_allclose(beam.lumped_mass(m1, m2), point, atol=1e-15)
    np.testing.assert_allclose(beam.lumped_mass_skew(m1, m2), point_skew, atol=1e-15)


def test_bearing_stiffness_is_positive_semidefinite():
    kj = beam.bearing_stiffness(22700.0)
    eig = np.linalg.eigvalsh(kj)
    assert eig.min() > -1e-9 and np.count_nonzero(eig > 1e-6) == 2
    # equal translation of both nodes costs nothing
    np.testing.assert_allclose(kj @ np.array([1, 2, 0, 1, 2, 0.5]), 0.0)
