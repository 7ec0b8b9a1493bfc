"""Root refinement of |D(omega)| (core/tmm/roots.py): the paper's iterates and counts."""

from flexlink_ros.core.tmm import beams, roots, solve
import numpy as np
import pytest

BEAM = beams.UniformBeam.kim_moon()
BCS = beams.BOUNDARY_CONDITIONS


def test_first_false_position_iterate_is_the_printed_fixed_fixed_value():
    model = beams.lump_masses(BEAM, 6, 3, 'fixed-fixed')
    root = roots.refine_root(model, 'fixed-fixed', (1190.0, 1200.0), 'false-position')
    # Table 5 prints 1198.96312 after one iteration: the paper's |D| <= 1e-6 accepted it
    assert root.history[0] == pytest.approx(1198.96312, abs=1e-3)
    assert root.iterations_paper_criterion == 1
    assert root.frequency_rad_s == pytest.approx(1198.963684, abs=5e-7)


@pytest.mark.parametrize('bc', BCS)
def test_bisection_needs_more_iterations(bc):
    counts = {}
    for search in roots.SEARCHES:
        result = solve.tmm_frequencies(BEAM, bc, 6, 3, 2, search, step=10.0)
        counts[search] = np.array(result.iterations)
        paper = [root.iterations_paper_criterion for root in result.roots]
        counts[search + '/paper'] = np.array(paper)
    assert np.all(counts['bisection'] > counts['false-position'])
    assert np.all(counts['bisection'] > counts['newton'])
    assert np.all(counts['bisection/paper'] > counts['false-position/paper'])
    assert np.all(counts['bisection/paper'] > counts['newton/paper'])


def test_paper_criterion_counts_reproduce_table2_fixed_row():
    # Table 2, fixed-fixed, d_omega = 10: HIS 5, FPM 1, NRM 1 iterations to |D| <= 1e-6
    counts = [solve.tmm_frequencies(BEAM, 'fixed-fixed', 6, 3, 1, search).roots[0]
              .iterations_paper_criterion for search in roots.SEARCHES]
    assert counts == [5, 1, 1]
