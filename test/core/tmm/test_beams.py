"""Beams and mass lumping of Kim & Moon (core/tmm/beams.py)."""

from flexlink_ros.core.tmm import beams, eigen, roots
import pytest

BEAM = beams.UniformBeam.kim_moon()
BCS = beams.BOUNDARY_CONDITIONS


def test_kim_moon_beam_in_si():
    assert BEAM.E == pytest.approx(18582 * 9.80665e6)
    assert BEAM.I == pytest.approx(0.030 * 0.0015 ** 3 / 12)
    # 7.43e-6 kgf/mm^3 over g = 9807 mm/s^2, per metre of a 30 x 1.5 mm strip
    assert BEAM.mass_per_length == pytest.approx(7.43e-6 / 9807 * 45.0 * 1e3 * 9.80665e3,
                                                 rel=1e-12)


@pytest.mark.parametrize('bc', BCS)
def test_lumping_conserves_mass_and_counts_modes(bc):
    n = 6
    for method, expected_modes in ((1, n), (2, n - 1), (3, n - (0 if bc == 'cantilever' else 1))):
        model = beams.lump_masses(BEAM, n, method, bc)
        assert model.masses.sum() == pytest.approx(BEAM.mass)
        assert roots.available_modes(model, bc) == expected_modes
        assert eigen.lumped_frequencies(model, bc).size == expected_modes
    tip = beams.lump_masses(BEAM, n, 3, bc).positions[-1]
    assert tip == pytest.approx(BEAM.length * (1 - 1 / (6 * n)) if bc == 'cantilever'
                                else BEAM.length)
