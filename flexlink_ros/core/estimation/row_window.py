"""
The rows of a long sample stream held in bounded memory: appended at the end, dropped at the start.

:class:`RowWindow` keeps named columns (the input and the estimate of each sample) for the rows
``base <= row < end`` of a stream and is indexed by the rows' numbers in the whole stream, so
the offline run (:mod:`.offline`) reads and writes rows as if it held the whole recording
while only a window of it is in memory. A row dropped from the window but still needed as the
source of later repeats is held aside (:meth:`RowWindow.drop_before`).
"""

import numpy as np


class RowWindow:
    """
    Named columns of the rows ``base <= row < end`` of a stream.

    Parameters
    ----------
    columns : dict
        Name -> (shape of one row's value, dtype). Appended rows are zero in the columns the
        caller does not give.

    """

    def __init__(self, columns):
        self.columns = dict(columns)
        self.base = self.end = 0
        self.arrays = {name: np.zeros((0,) + tuple(shape), dtype=dtype)
                       for name, (shape, dtype) in self.columns.items()}
        self.held_row, self.held = None, {}

    def __getitem__(self, name):
        """Return the column ``name``, indexed by stream row numbers."""
        return _Column(self, name)

    def append(self, values):
        """
        Add rows at the end.

        Parameters
        ----------
        values : dict
            Name -> array of the new rows (all of one length); other columns get zeros.

        """
        count = len(next(iter(values.values())))
        used = self.end - self.base
        capacity = len(next(iter(self.arrays.values())))
        if used + count > capacity:
            size = used + count     # a stream's appends are alike: this size then lasts
            for name, array in self.arrays.items():
                grown = np.zeros((size,) + array.shape[1:], dtype=array.dtype)
                grown[:used] = array[:used]
                self.arrays[name] = grown
        for name, array in self.arrays.items():
            fresh = array[used:used + count]
            if name in values:
                fresh[...] = values[name]
            else:
                fresh[...] = 0
        self.end += count

    def drop_before(self, row, hold=None):
        """
        Forget the rows before ``row``, keeping row ``hold`` aside if it is one of them.

        Parameters
        ----------
        row : int
            First row kept.
        hold : int or None
            A row whose values later rows still copy (the source of repeats); one at a time.

        """
        row = min(max(row, self.base), self.end)
        if row == self.base:
            return
        if hold is not None and self.base <= hold < row:
            self.held_row = hold
            self.held = {name: array[hold - self.base].copy()
                         for name, array in self.arrays.items()}
        kept = self.end - row
        for array in self.arrays.values():
            array[:kept] = array[row - self.base:self.end - self.base]
        self.base = row

    def copy_row(self, source, row, names):
        """Copy the values of row ``source`` (in the window or held aside) to ``row``."""
        for name in names:
            if source >= self.base:
                value = self.arrays[name][source - self.base]
            elif source == self.held_row:
                value = self.held[name]
            else:
                raise IndexError(f'row {source} is no longer held (window from {self.base})')
            self.arrays[name][row - self.base] = value

    def rows(self, first, stop, names):
        """Return copies of the columns ``names`` for rows ``first <= row < stop``."""
        return {name: self.arrays[name][first - self.base:stop - self.base].copy()
                for name in names}


class _Column:
    """One column of a :class:`RowWindow`, indexed by stream row numbers."""

    def __init__(self, window, name):
        self.window, self.name = window, name

    def _local(self, index):
        base, end = self.window.base, self.window.end
        if isinstance(index, slice):
            start = base if index.start is None else index.start
            stop = end if index.stop is None else index.stop
            if index.step not in (None, 1) or start < base or stop > end:
                raise IndexError(f'rows {start}:{stop} outside the window {base}:{end}')
            return slice(start - base, max(stop, start) - base)
        if isinstance(index, (int, np.integer)):
            if not base <= index < end:
                raise IndexError(f'row {index} outside the window {base}:{end}')
            return int(index) - base
        local = np.asarray(index)
        if local.dtype == bool:
            raise TypeError('index a window column by row numbers, not a mask')
        if local.size and (local.min() < base or local.max() >= end):
            raise IndexError(f'rows outside the window {base}:{end}')
        return local - base

    def __getitem__(self, index):
        return self.window.arrays[self.name][self._local(index)]

    def __setitem__(self, index, value):
        self.window.arrays[self.name][self._local(index)] = value
