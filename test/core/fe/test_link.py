"""One link of the FE model (core/fe/link.py): beam frequencies, geometric stiffness A.4."""

from flexlink_ros.core.fe import beam
from flexlink_ros.core.fe.link import (element_geometric_stiffness, gauss_points, link_matrices,
                                       transverse_slopes)
import numpy as np
import pytest
import scipy.linalg

E, RHO, AREA, SECOND, LENGTH = 2.19e11, 7718.0, 0.14406e-4, 1.153e-12, 0.262
CANTILEVER_BL = (1.875104068711961, 4.694091132974175, 7.854757438237613)


def _bending_frequencies(elements, keep, geometric=None, shift=0.0):
    mats = link_matrices(E, AREA, SECOND, RHO, LENGTH, elements)
    dofs = np.array([d for d in range(3 * (elements + 1)) if d % 3 and keep(d)])
    stiffness = mats.stiffness if geometric is None else mats.stiffness + geometric
    stiffness = stiffness - shift * mats.mass
    values = scipy.linalg.eigh(stiffness[np.ix_(dofs, dofs)], mats.mass[np.ix_(dofs, dofs)],
                               eigvals_only=True, subset_by_index=[0, 2])
    return np.sqrt(values)


def _scale():
    return np.sqrt(E * SECOND / (RHO * AREA * LENGTH ** 4))


@pytest.mark.parametrize('bc', ['cantilever', 'pinned-pinned'])
def test_beam_frequencies_converge_at_fourth_order(bc):
    """Euler-Bernoulli closed forms: (beta L)^2 sqrt(EI / (rho A L^4)); cubic Hermite: h^4."""
    if bc == 'cantilever':
        exact = np.array(CANTILEVER_BL) ** 2 * _scale()
        keep = lambda n: lambda d: d >= 3  # noqa: E731 - clamp node 0 (v, phi)
    else:
        exact = (np.pi * np.arange(1, 4)) ** 2 * _scale()
        keep = lambda n: lambda d: d not in (1, 3 * n + 1)  # noqa: E731 - v = 0 at both ends
    errors = []
    for n in (4, 8, 16):
        freqs = _bending_frequencies(n, keep(n))
        errors.append(np.abs(freqs / exact - 1))
    errors = np.array(errors)
    assert errors[-1].max() < 1e-4
    rates = np.log2(errors[:-1] / errors[1:])
    assert np.all(rates[-1] > 3.8) and np.all(rates[-1] < 4.2), rates   # asymptotic: 8 -> 16


# Wright, Smith, Thresher & Wang (1982), "Vibration modes of centrifugally stiffened beams",
# J. Appl. Mech. 49, 197-202 (zero hub radius), the values Yoo & Shin (1998), "Vibration
# analysis of rotating cantilever beams", J. Sound Vib. 212(5), 807-828, compare with:
# dimensionless flapwise frequencies w sqrt(rho A L^4 / EI) at speed ratios
# gamma = Omega sqrt(rho A L^4 / EI). In-plane (chordwise) with the stretching coupling ignored,
# w_c^2 = w_f^2 - Omega^2 (the -Omega^2 M term of Eq. 22): the Southwell form with S - 1.
# (Re-computed here by Chebyshev collocation to 1e-8: 3.68164744, 22.18101126 at gamma 1;
# 11.20232867, 33.64036449 at gamma 10.)
ROTATING_FLAPWISE = {1.0: (3.6816, 22.1810), 2.0: (4.1373, 22.6149), 3.0: (4.7973, 23.3203),
                     5.0: (6.4495, 25.4461), 10.0: (11.2023, 33.6404)}


@pytest.mark.parametrize('gamma', sorted(ROTATING_FLAPWISE))
def test_rotating_cantilever_matches_published_centrifugal_stiffening(gamma):
    elements = 24
    omega = gamma * _scale()
    mats = link_matrices(E, AREA, SECOND, RHO, LENGTH, elements)
    x = (mats.nodes[:-1, None] + gauss_points(mats.element_length)[0][None, :])
    tension = RHO * AREA * omega ** 2 * (LENGTH ** 2 - x ** 2) / 2.0   # rotation about the root
    kg = np.zeros_like(mats.stiffness)
    for e, element in enumerate(element_geometric_stiffness(tension, mats.element_length)):
        kg[3 * e:3 * e + 6, 3 * e:3 * e + 6] += element
    keep = lambda d: d >= 3  # noqa: E731
    flap = _bending_frequencies(elements, keep, kg) / _scale()
    chord = _bending_frequencies(elements, keep, kg, shift=omega ** 2) / _scale()
    published = np.array(ROTATING_FLAPWISE[gamma])
    np.testing.assert_allclose(flap[:2], published, rtol=2e-5, atol=6e-5)
    np.testing.assert_allclose(chord[:2], np.sqrt(published ** 2 - gamma ** 2), rtol=2e-5,
                               atol=6e-5)
    if gamma == 1.0:   # Southwell coefficient of mode 1 at low speed
        southwell = (flap[0] ** 2 - (CANTILEVER_BL[0] ** 2) ** 2) / gamma ** 2
        assert southwell == pytest.approx(1.1925, abs=1e-3)


def test_geometric_stiffness_with_constant_force_is_a4():
    forces = np.full(4, 37.5)
    np.testing.assert_allclose(element_geometric_stiffness(forces, 0.09),
                               beam.beam_geometric_stiffness(37.5, 0.09), rtol=1e-13, atol=1e-12)
    # a force linear in x integrates exactly (compare with 8-point quadrature)
    x8, w8 = np.polynomial.legendre.leggauss(8)
    length = 0.09
    x8, w8 = 0.5 * length * (x8 + 1), 0.5 * length * w8
    force = lambda x: 10.0 - 300.0 * x + 900.0 * x ** 2  # noqa: E731
    dense = np.einsum('g,g,gi,gj->ij', force(x8), w8, transverse_slopes(x8, length),
                      transverse_slopes(x8, length))
    xg, _ = gauss_points(length)
    np.testing.assert_allclose(element_geometric_stiffness(force(xg), length), dense,
                               rtol=1e-12, atol=1e-12 * np.abs(dense).max())
