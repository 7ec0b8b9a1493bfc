"""The compiled kernel of the dynamic pass's work per sample (dynamic_second_order_bench)."""

import shutil

from dynamic_second_order_bench import time_pass
from dynamic_second_order_study import case_options
from flexlink_ros.core.mechanism_file import load_mechanism
from flexlink_ros.core.reduction.mechanism_model import model_for_mechanism
from flexlink_ros.core.reduction.second_order_dynamic_tables import load_for_model
import pytest


@pytest.mark.skipif(shutil.which('cc') is None and shutil.which('gcc') is None,
                    reason='needs a C compiler')
def test_kernel_load_is_the_numpy_load_and_it_is_timed():
    mech = load_mechanism('cho1992')
    options = case_options(391.0, 3, (4, 2))
    model = model_for_mechanism(mech, options, use_cache=False)
    load = load_for_model(mech, options, model)
    for solves in (True, False):
        ns, error = time_pass(load, samples=50, solves=solves)
        # the C stage load (total and eigenstrain part) equals DynamicLoad's to rounding
        assert error < 1e-12
        assert ns > 0.0
