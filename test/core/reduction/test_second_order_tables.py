"""The reduced model's second-order tables: against the full-order forms on V q."""

from flexlink_ros.core.fe import linkage as assembly
from flexlink_ros.core.fe import second_order_full as so_full
from flexlink_ros.core.mechanism_file import load_mechanism
from flexlink_ros.core.options import ModelOptions
from flexlink_ros.core.reduction import mechanism_model
from flexlink_ros.core.reduction import second_order_tables as so_tables
import numpy as np
import pytest


@pytest.fixture(scope='module')
def mech():
    return load_mechanism('cho1992')


@pytest.mark.parametrize('options', [
    ModelOptions.linear(bearings='rigid', grid_size=32, order=2),
    ModelOptions.linear(bearings='flexible', grid_size=32, order=2),
    ModelOptions.linear(bearings='flexible', rigid_crank=False, elements_per_link=3, grid_size=32,
                        order=2)], ids=['rigid', 'flexible', 'flexible-crank'])
def test_tables_give_the_full_order_second_order_of_v_q(mech, options):
    model = mechanism_model.model_for_mechanism(mech, options, use_cache=False)
    forms = so_tables.SecondOrderForms(model.second_order)
    linkage = assembly.FlexibleLinkage(mechanism_model.fe_mechanism(mech, options), options)
    rng = np.random.default_rng(2)
    # At the grid nodes the splines are their samples: equal to rounding; between them the
    # cubic spline of the link angles and of kappa on this 32-point grid is within 5e-4 of
    # the largest output (measured 2e-5 to 1.3e-4; about 16x less on the default 128).
    for shift, tolerance in ((0.0, 1e-12), (0.37, 5e-4)):
        theta = 2.0 * np.pi * (np.arange(options.grid_size) + shift) / options.grid_size
        q = rng.standard_normal((theta.size, model.size)) * 1e-4
        cells, t = model.cell(theta)
        scalars = forms.spline_scalars(cells, t)
        got = forms.outputs(scalars, forms.sums(scalars, q))
        full = so_full.second_order_outputs(linkage, q @ model.basis.T, theta)
        scale = np.abs(full['outputs']).max()
        assert scale > 0.0
        np.testing.assert_allclose(got, full['outputs'], rtol=0, atol=tolerance * scale)
        d_a, d_b = forms.joint_motion(scalars, q)
        np.testing.assert_allclose(d_b[:, 0] + 1j * d_b[:, 1], full['d_b'], rtol=0,
                                   atol=tolerance * scale)
        np.testing.assert_allclose(d_a[:, 0] + 1j * d_a[:, 1], full['d_a'], rtol=0,
                                   atol=tolerance * scale)
    # The crank's sum enters only with a flexible crank.
    assert np.any(d_a) == (not options.rigid_crank)


def test_link_points_follow_the_joints_second_order_motion():
    d_a, d_b = np.array([[1.0, 2.0]]), np.array([[-3.0, 5.0]])
    motion = so_tables.link_point_motion(d_a, d_b, 5)
    assert motion.shape == (1, 3, 5, 2)
    # crank O2 -> A, coupler A -> B, lever O4 -> B; linear in between
    np.testing.assert_array_equal(motion[0, :, 0], [[0.0, 0.0], d_a[0], [0.0, 0.0]])
    np.testing.assert_array_equal(motion[0, :, -1], [d_a[0], d_b[0], d_b[0]])
    np.testing.assert_allclose(motion[0, 1, 2], 0.5 * (d_a[0] + d_b[0]))


def test_index_arrays_are_int32_and_in_range(mech):
    options = ModelOptions.linear(bearings='rigid', grid_size=16, order=2)
    model = mechanism_model.model_for_mechanism(mech, options, use_cache=False)
    arrays = model.second_order
    gather, form = arrays['second_gather'], arrays['second_form']
    assert gather.dtype == np.int32 and form.dtype == np.int32
    assert gather[:, 1].max() < arrays['second_rows'].shape[0]
    assert set(np.unique(gather[:, 2])) <= {-1} | set(range(so_tables.TRIG_SCALARS))
    assert form[:, 0].max() < 4 and np.all(form[:, 1] <= form[:, 2])
    assert arrays['second_scalars'].shape == (16, 4, so_tables.SCALARS)
