"""
The dynamic pass's loads of one step (core/estimation/second_order_dynamic_kernel.py).

The compiled form (_second_order_dynamic.c) against its numpy twin, and the numpy twin against
its definition: the reduced static responses K_r^-1 f_r at the two points as the reference of
the elastic axial force, and K_r^-1 f2_eigenstrain at the sample.
"""

import math

from flexlink_ros.core.estimation import second_order_dynamic_kernel as kernel
from flexlink_ros.core.mechanism_file import load_mechanism
from flexlink_ros.core.options import ModelOptions
from flexlink_ros.core.reduction import mechanism_model
import numpy as np
import pytest

SPEED = 391 * math.pi / 30


@pytest.fixture(scope='module')
def arrays():
    options = ModelOptions.linear(bearings='rigid', elements_per_link=3, modes=5, static=3,
                                  order=2, grid_size=32, speed_max=1.05 * SPEED,
                                  second_order='dynamic')
    model = mechanism_model.model_for_mechanism(load_mechanism('cho1992'), options,
                                                use_cache=False)
    return model.dynamic_second_order


def _inputs(size, seed):
    rng = np.random.default_rng(seed)
    stored = np.zeros((2, 4, size * size))
    for slot in range(2):
        a = rng.standard_normal((size, size))
        stored[slot, 2] = (a @ a.T + size * np.eye(size)).ravel()
        stored[slot, 3, :size] = rng.standard_normal(size) * 1e-3
    return stored, rng.standard_normal((2, size)) * 1e-3


def test_numpy_form_is_its_definition(arrays):
    twin = kernel.DynamicPassKernel(arrays, compiled=False)
    r = twin.size
    stored, states = _inputs(r, 1)
    out = twin(stored, (1, 0), states, (0.3, 4.0)).copy()
    statics = [np.linalg.solve(stored[s, 2].reshape(r, r), stored[s, 3, :r]) for s in (1, 0)]
    stage = twin.load.load(states[0], 0.3, 0.0, 0.0, statics[0])
    sample = twin.load.load(states[1], 4.0, 0.0, 0.0, statics[1])
    np.testing.assert_allclose(out[0], stage[0], rtol=1e-12)
    np.testing.assert_allclose(out[1], sample[0], rtol=1e-12)
    np.testing.assert_allclose(stored[0, 2].reshape(r, r) @ out[2], sample[1], rtol=1e-9)
    # the static reference matters: against a zero reference the load differs
    assert not np.allclose(twin.load.load(states[1], 4.0, 0.0, 0.0, 0.0 * statics[1])[0],
                           out[1], rtol=1e-3)


@pytest.mark.skipif(not kernel.dynamic_pass_compiled_available(),
                    reason='the compiled pass (_second_order_dynamic.c) is not built')
@pytest.mark.parametrize('seed, slots, angles', [(2, (1, 0), (0.1, 0.2)),
                                                 (3, (0, 1), (6.28, -1.0)),
                                                 (4, (1, 0), (3.0, 12.0))])
def test_compiled_form_equals_numpy(arrays, seed, slots, angles):
    compiled = kernel.DynamicPassKernel(arrays)
    twin = kernel.DynamicPassKernel(arrays, compiled=False)
    assert compiled.compiled and not twin.compiled
    stored, states = _inputs(compiled.size, seed)
    expected = twin(stored, slots, states, angles).copy()
    got = compiled(stored, slots, states, angles)
    scale = np.abs(expected).max(axis=1, keepdims=True)
    assert np.all(np.abs(got - expected) <= 1e-12 * scale), np.abs(got - expected) / scale


@pytest.mark.skipif(not kernel.dynamic_pass_compiled_available(),
                    reason='the compiled pass (_second_order_dynamic.c) is not built')
def test_compiled_form_refuses_bad_buffers(arrays):
    compiled = kernel.DynamicPassKernel(arrays)
    stored, states = _inputs(compiled.size, 5)
    with pytest.raises(ValueError, match='states'):
        compiled(stored, (1, 0), states[:1], (0.0, 0.0))
    with pytest.raises(ValueError, match='slots'):
        compiled(stored, (2, 0), states, (0.0, 0.0))
    with pytest.raises(ValueError, match='singular'):
        compiled(np.zeros_like(stored), (1, 0), states, (0.0, 0.0))
