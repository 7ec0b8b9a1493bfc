"""The compiled step: built, its filter-state layout as in the C file, its LU solve."""

import inspect
import pathlib
import re

from estimation_toys import compiled_or_skip
from flexlink_ros.core.estimation import native
from flexlink_ros.core.estimation.streaming import StreamingEstimator
import numpy as np
import pytest


C_SOURCE = pathlib.Path(native.__file__).with_name('_radau_step.c')


def c_enum(source, first):
    """Values of the C ``enum { ... }`` whose first name is ``first`` (name = expression)."""
    body = re.search(r'enum\s*{\s*(' + first + r'\b[^}]*)}', source).group(1)
    values, value = {}, -1
    for entry in body.replace('\n', ' ').split(','):
        name, _, expression = entry.partition('=')
        value = eval(expression, {}, dict(values)) if expression.strip() else value + 1
        values[name.strip()] = value
    return values


def c_define(source, name):
    """Value of a ``#define name expression`` of the C file (earlier defines resolved)."""
    defines = dict(re.findall(r'#define (\w+) ([^/\n]+)', source))
    numbers = {key: int(value) for key, value in defines.items() if value.strip().isdigit()}
    return eval(defines[name], {}, numbers)


def test_compiled_step_is_built():
    """The package's compiled step is built (make install and colcon build build it)."""
    assert native.impl is not None, 'flexlink_ros.core.estimation._radau_step is not built'
    assert native.compiled_step_available()
    assert inspect.signature(StreamingEstimator).parameters['compiled'].default is True


@pytest.mark.parametrize('n', [1, 2, 3, 4, 5, 8, 12, 13, 52, 61])
def test_compiled_lu_solve_with_pivoting(n):
    # Small diagonals force row swaps in every panel; sizes around the panel width of 4.
    compiled_or_skip()
    rng = np.random.default_rng(n)
    a = rng.standard_normal((n, n))
    a[np.diag_indices(n)] *= 1e-3
    b = rng.standard_normal(n)
    expected = np.linalg.solve(a, b)
    x, factors = b.copy(), a.copy()
    native.impl.lu_solve(factors, x)
    np.testing.assert_allclose(x, expected, rtol=1e-9, atol=1e-9 * np.max(np.abs(expected)))
    with pytest.raises(ValueError, match='singular'):
        native.impl.lu_solve(np.zeros((n, n)), b.copy())
    # A zero column inside a panel and the last one: their pivots are found in the
    # elimination's pass (not by a search of their own).
    for column in {n // 2, n - 1} - {0}:
        deficient = a.copy()
        deficient[:, column] = 0.0
        with pytest.raises(ValueError, match='singular'):
            native.impl.lu_solve(deficient, b.copy())


def test_filter_state_layout_is_the_c_files():
    """native.FILTER_* are the enum F_* of _radau_step.c, in order, with its state size."""
    source = C_SOURCE.read_text()
    layout = c_enum(source, 'F_STARTED')
    python = {'FILTER_STATE': native.FILTER_STATE}
    python.update({name: getattr(native, 'FILTER' + name[1:]) for name in layout
                   if name.startswith('F_')})
    assert layout == python
    assert layout['F_ANGLE_FIT'] - layout['F_SPEED_FIT'] == native.FIT_SIZE
    assert c_enum(source, 'MODE_NONE')['MODE_SPEED'] == native.MODE_SPEED
    # A fit: s0..s4, t0..t2, then the count (fit[8] in the C file).
    assert 'fit[8] += 1.0' in source and native.FIT_COUNT == 8


def test_record_and_row_sizes_are_the_c_files():
    source = C_SOURCE.read_text()
    assert c_define(source, 'RECORD_SIZE') == native.RECORD_SIZE
    assert c_define(source, 'ROW_FIELDS') == native.ROW_SIZE
