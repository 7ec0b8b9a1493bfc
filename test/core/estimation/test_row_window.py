"""row_window: a stream's rows by their numbers, only a window of them in memory."""

from flexlink_ros.core.estimation.row_window import RowWindow
import numpy as np
import pytest


def window():
    return RowWindow({'stamp': ((), np.int64), 'value': ((2,), float), 'flag': ((), np.int8)})


def test_rows_keep_their_numbers_as_the_window_moves():
    rows = window()
    rows.append({'stamp': np.arange(10), 'value': np.ones((10, 2))})
    assert rows['flag'][0:10].tolist() == [0] * 10          # not given: zeros
    rows['value'][np.array([3, 4])] = [[3.0, 3.5], [4.0, 4.5]]
    rows['flag'][4] |= 2
    rows.drop_before(4)
    rows.append({'stamp': np.arange(10, 16), 'value': np.zeros((6, 2))})
    assert (rows.base, rows.end) == (4, 16)
    assert rows['stamp'][4:16].tolist() == list(range(4, 16))
    assert rows['value'][4].tolist() == [4.0, 4.5] and rows['flag'][4] == 2
    block = rows.rows(4, 6, ('stamp', 'value'))
    block['stamp'][:] = -1                                   # a copy
    assert rows['stamp'][4] == 4
    with pytest.raises(IndexError):
        rows['stamp'][3]                                     # dropped
    with pytest.raises(IndexError):
        rows['stamp'][np.array([5, 16])]                     # not read yet
    with pytest.raises(IndexError):
        rows['value'][2:6]


def test_a_dropped_row_held_aside_is_still_copied():
    rows = window()
    rows.append({'stamp': np.arange(8), 'value': np.arange(16.0).reshape(8, 2)})
    rows.drop_before(6, hold=2)
    rows.copy_row(2, 7, ('value', 'stamp'))
    assert rows['value'][7].tolist() == [4.0, 5.0] and rows['stamp'][7] == 2
    rows.copy_row(6, 7, ('value',))
    assert rows['value'][7].tolist() == [12.0, 13.0]
    with pytest.raises(IndexError, match='no longer held'):
        rows.copy_row(1, 7, ('value',))
    rows.append({'stamp': np.arange(8, 100), 'value': np.zeros((92, 2))})
    assert len(rows.arrays['stamp']) == 94                   # the rows held, no more
