"""
Second-order outputs on a reduced basis, three ways (docs/studies/second_order_forms.py).

The quadratic form on a reduced basis against the full-order computation on V q (the compiled
kernel and the streamed reduced model: test/benchmarks/test_second_order_bench.py,
test/docs_studies/test_second_order_study.py).
"""

from flexlink_ros.core import options as core_options
from flexlink_ros.core.fe import linkage as assembly
from flexlink_ros.core.fe import second_order_full as so_full
from flexlink_ros.core.mechanism_file import load_mechanism
from flexlink_ros.core.reduction import basis as reduction_basis
from flexlink_ros.core.reduction import mechanism_model
import numpy as np
import pytest
import second_order_forms as so_reduced

ELEMENTS = 4


@pytest.fixture(scope='module')
def mech():
    return load_mechanism('cho1992')


# -- reduced basis ----------------------------------------------------------------------------

@pytest.mark.parametrize('options', [
    core_options.ModelOptions.linear(grid_size=8, bearings='rigid', elements_per_link=ELEMENTS),
    core_options.ModelOptions.linear(grid_size=8, bearings='flexible', rigid_crank=False,
                         elements_per_link=3, modes=24, static=2)], ids=['rigid', 'flexible'])
def test_quadratic_form_equals_the_full_order_on_v_q(mech, options):
    samples = mechanism_model.frozen_samples_for(mech, options)
    basis, _ = reduction_basis.build_basis(samples, options.modes, options.static,
                                           np.linspace(0.0, 60.0, 2))
    linkage = assembly.FlexibleLinkage(mechanism_model.fe_mechanism(mech, options),
                                       options)
    theta = np.linspace(0.0, 2.0 * np.pi, 9, endpoint=False) + 0.2
    q = np.random.default_rng(3).standard_normal((theta.size, basis.shape[1])) * 1e-4
    full = so_full.second_order_outputs(linkage, q @ basis.T, theta)['outputs']
    tables = so_reduced.quadratic_tables(linkage, basis, theta)
    scale = np.abs(full).max()
    assert scale > 0.0
    np.testing.assert_allclose(so_reduced.reduced_second_order(tables, q), full, rtol=0,
                               atol=1e-13 * scale)
    assert np.allclose(tables['Q'], np.swapaxes(tables['Q'], -1, -2))
    factored = so_reduced.factored_forms(linkage, basis)
    np.testing.assert_allclose(so_reduced.factored_second_order(factored, mech, theta, q), full,
                               rtol=0, atol=1e-13 * scale)
    cost = so_reduced.step_cost(factored, basis.shape[1])
    assert cost['factored'] < cost['tables']
