"""Transfer matrices and |D(omega)| (core/tmm/matrices.py) against Table 4 and statics."""

from flexlink_ros.core.tmm import beams, matrices
import numpy as np
import pytest

BEAM = beams.UniformBeam.kim_moon()
BCS = beams.BOUNDARY_CONDITIONS
# Table 4: scan ends around mode 1 (d_omega = 10) and |D| there, kgf-mm units.
TABLE4 = {'fixed-fixed': ((1190, 6.61e-5), (1200, -7.65e-6)),
          'fixed-supported': ((820, 2.32e-1), (830, -1.27e-1)),
          'cantilever': ((180, 8.53e-2), (190, -1.60e-2)),
          'supported': ((520, 1.26e3), (530, -1.26e2))}


@pytest.mark.parametrize('bc', BCS)
def test_determinant_matches_table4(bc):
    model = beams.lump_masses(BEAM, 6, 3, bc)
    factor = matrices.determinant_to_kgf_mm(bc)
    for omega, printed in TABLE4[bc]:
        value = matrices.frequency_determinant(model, bc, omega) * factor
        assert value == pytest.approx(printed, rel=6e-3)


def test_transfer_by_entries_equals_matrix_product_and_batch():
    model = beams.lump_masses(BEAM, 5, 3, 'cantilever')
    omega = 700.0
    state = np.eye(4)[:, [2, 3]]
    x = 0.0
    for end, mass in zip(model.segment_ends, model.point_masses):
        field = matrices.field_matrix(end - x, model.flexural_rigidity)
        state = matrices.point_matrix(mass, omega) @ field @ state
        x = end
    expected = np.linalg.det(state[[2, 3]])
    assert matrices.frequency_determinant(model, 'cantilever', omega) == pytest.approx(
        expected, rel=1e-12)
    batch = matrices.frequency_determinants(model, 'cantilever', np.array([0.0, omega, 2 * omega]))
    assert batch[1] == pytest.approx(expected, rel=1e-12)
    assert batch[0] == pytest.approx(1.0)  # static cantilever: M_n, V_n equal M_0, V_0


def test_field_matrix_is_the_static_beam_solution():
    # columns of the field matrix = deflection, slope, moment, shear of u'''' = 0
    ei, span = 2.5, 0.3
    field = matrices.field_matrix(span, ei)
    x = np.linspace(0, span, 4)
    for moment0, shear0 in ((1.0, 0.0), (0.0, 1.0)):
        u = moment0 * x ** 2 / (2 * ei) + shear0 * x ** 3 / (6 * ei)
        end = field @ np.array([0.0, 0.0, moment0, shear0])
        assert end[0] == pytest.approx(u[-1])
        assert end[2] == pytest.approx(moment0 + shear0 * span)


@pytest.mark.parametrize('bc', BCS)
def test_newton_derivative_matches_finite_difference(bc):
    model = beams.lump_masses(BEAM, 7, 1, bc)
    for omega in (150.0, 900.0, 2500.0):
        value, slope = matrices.frequency_determinant(model, bc, omega, derivative=True)
        h = 1e-4 * omega
        fd = (matrices.frequency_determinant(model, bc, omega + h)
              - matrices.frequency_determinant(model, bc, omega - h)) / (2 * h)
        assert value == matrices.frequency_determinant(model, bc, omega)
        assert slope == pytest.approx(fd, rel=1e-6)
