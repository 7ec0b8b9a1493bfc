"""Transfer-matrix frequencies (core/tmm/solve.py) against Table 5, FE and the continuous beam."""

import math

from flexlink_ros.core.tmm import beams, eigen, exact, roots, solve
from flexlink_ros.errors import FlexlinkError
import numpy as np
import pytest

BEAM = beams.UniformBeam.kim_moon()
BCS = beams.BOUNDARY_CONDITIONS
TABLE5_TMM3_6 = {'fixed-fixed': 1198.963684, 'fixed-supported': 826.462466,
                 'cantilever': 188.452845, 'supported': 529.097995}
# Observed error exponent p (error ~ h^p) per lumping method: methods 1 and 3 are O(h^4)
# except with a free end (method 1 O(h^2), method 3 O(h^3) with its share at h/6);
# method 2 misplaces mass, O(h); consistent-mass cubic FE O(h^4).
RATES = {'tmm1': 4, 'tmm2': 1, 'tmm3': 4, 'fe': 4}
CANTILEVER_RATES = {'tmm1': 2, 'tmm2': 1, 'tmm3': 3, 'fe': 4}


def _frequencies(bc, segments, method):
    if method == 'fe':
        return eigen.fe_frequencies(BEAM, bc, segments, 3)
    return solve.tmm_frequencies(BEAM, bc, segments, int(method[-1]), 3, 'newton',
                                 step=50.0).frequencies_rad_s


@pytest.mark.parametrize('search', roots.SEARCHES)
@pytest.mark.parametrize('bc', BCS)
def test_method3_six_segments_reproduce_table5(bc, search):
    result = solve.tmm_frequencies(BEAM, bc, 6, method=3, modes=1, search=search, step=10.0)
    assert round(result.frequencies_rad_s[0], 6) == pytest.approx(TABLE5_TMM3_6[bc], abs=1e-9)


@pytest.mark.parametrize('bc', BCS)
def test_searches_agree_and_equal_the_stiffness_eigenproblem(bc):
    for method, segments in ((1, 9), (2, 10), (3, 12)):
        model = beams.lump_masses(BEAM, segments, method, bc)
        reference = eigen.lumped_frequencies(model, bc)[:4]
        results = [solve.tmm_frequencies(BEAM, bc, segments, method, 4, search, step=25.0)
                   for search in roots.SEARCHES]
        for result in results:
            np.testing.assert_allclose(result.frequencies_rad_s,
                                       results[0].frequencies_rad_s, rtol=1e-9)
            np.testing.assert_allclose(result.frequencies_rad_s, reference, rtol=1e-9)


@pytest.mark.parametrize('method', list(RATES))
@pytest.mark.parametrize('bc', BCS)
def test_convergence_to_euler_bernoulli(bc, method):
    continuous = exact.exact_frequencies(BEAM, bc, 3)
    coarse, fine = (np.abs(_frequencies(bc, n, method) / continuous - 1) for n in (16, 32))
    observed = np.log2(coarse / fine)
    expected = (CANTILEVER_RATES if bc == 'cantilever' else RATES)[method]
    np.testing.assert_allclose(observed, expected, atol=0.3)
    assert np.all(fine < (0.03 if method == 'tmm2' else 2e-3))


def test_skipped_root_is_reported():
    # roots 1199 and 3292 rad/s share the first step of 5000 rad/s and cancel
    with pytest.raises(FlexlinkError, match='smaller step'):
        solve.tmm_frequencies(BEAM, 'fixed-fixed', 6, 3, 1, step=5000.0)


@pytest.mark.parametrize('call, argument', [
    (lambda: solve.tmm_frequencies(BEAM, 'clamped', 6), '`bc`'),
    (lambda: solve.tmm_frequencies(BEAM, 'cantilever', 0), '`segments`'),
    (lambda: solve.tmm_frequencies(BEAM, 'cantilever', 2.5), '`segments`'),
    (lambda: solve.tmm_frequencies(BEAM, 'cantilever', 1, method=2), '`segments`'),
    (lambda: solve.tmm_frequencies(BEAM, 'cantilever', 6, method=4), '`method`'),
    (lambda: solve.tmm_frequencies(BEAM, 'cantilever', 6, modes=7), '`modes`'),
    (lambda: solve.tmm_frequencies(BEAM, 'cantilever', 6, modes=0), '`modes`'),
    (lambda: solve.tmm_frequencies(BEAM, 'cantilever', 6, search='secant'), '`search`'),
    (lambda: solve.tmm_frequencies(BEAM, 'cantilever', 6, step=0.0), '`step`'),
    (lambda: solve.tmm_frequencies(BEAM, 'cantilever', 6, step=math.nan), '`step`'),
    (lambda: eigen.fe_frequencies(BEAM, 'supported', 0), '`elements`'),
    (lambda: eigen.fe_frequencies(BEAM, 'fixed-fixed', 1, modes=3), '`modes`'),
    (lambda: beams.UniformBeam(-1.0, 1.0, mass_per_length=1.0, length=1.0), '`E`'),
    (lambda: roots.refine_root(beams.lump_masses(BEAM, 6, 3, 'supported'), 'supported',
                               (100.0, 200.0)), '`bracket`'),
])
def test_bad_input_names_the_argument(call, argument):
    with pytest.raises(ValueError, match=argument):
        call()
