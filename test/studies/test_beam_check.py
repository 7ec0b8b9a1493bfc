"""The transfer-matrix beam check (studies/beam_check.py) against textbook beam frequencies."""

import math

from flexlink_ros.core.tmm import beams
from flexlink_ros.studies import beam_check
import numpy as np
import pytest

BEAM = beams.UniformBeam(E=2.0e11, I=1.0e-10, mass_per_length=2.0, length=1.0)
# first frequency of a pinned-pinned Euler-Bernoulli beam: pi^2 sqrt(E I / (rho A L^4))
PINNED = math.pi ** 2 * math.sqrt(BEAM.E * BEAM.I / BEAM.mass_per_length)
# cantilever: (1.8751041)^2 sqrt(E I / (rho A L^4))
CANTILEVER = 1.8751040687 ** 2 * math.sqrt(BEAM.E * BEAM.I / BEAM.mass_per_length)


@pytest.mark.parametrize('method', beam_check.METHODS)
def test_every_method_converges_to_the_textbook_first_frequency(method):
    for bc, exact in (('supported', PINNED), ('cantilever', CANTILEVER)):
        coarse = abs(beam_check.frequencies(BEAM, bc, 4, method)[0] / exact - 1.0)
        fine = abs(beam_check.frequencies(BEAM, bc, 32, method)[0] / exact - 1.0)
        # 8 times the segments: at least first order (lumping 2 is; the others faster)
        assert fine < 0.02 and fine < coarse / 4.0, (bc, coarse, fine)


def test_has_mode_refuses_the_models_without_one():
    assert not beam_check.has_mode(BEAM, 'supported', 1, 'tmm2')
    assert not beam_check.has_mode(BEAM, 'fixed-fixed', 1, 'fe')
    assert beam_check.has_mode(BEAM, 'cantilever', 1, 'fe')
    assert beam_check.has_mode(BEAM, 'supported', 6, 'tmm1')


def test_observed_order_of_a_power_law_within_the_fit_range():
    segments = np.array([4, 8, 12, 16, 24, 32, 48, 64, 96])
    errors = -3.0 * segments ** -2.0
    errors[segments > 48] = 1e-16               # a round-off floor beyond the range
    errors[segments < 12] = 0.5                 # not yet asymptotic
    assert beam_check.observed_order(segments, errors) == pytest.approx(2.0, rel=1e-9)
    assert beam_check.observed_order(segments, 7.0 * segments ** -4.0,
                                     fit_range=(4, 96)) == pytest.approx(4.0, rel=1e-9)
