"""
Many messages as numpy arrays, and their MCAP Message records assembled as one buffer.

A replay writes, per sample, its input and the outputs computed from it: hundreds of thousands
of small messages. Held as one ``bytes`` object each, and joined to their record headers one
by one, they cost several Python objects per message. :class:`PackedMessages` keeps a batch
sample-major instead: per sample a message from each column present there, in column order,
each column one array of rows (:class:`FixedColumn`, the fixed-layout outputs) or one flat
array with lengths (:class:`VariableColumn`, the input as recorded).
:meth:`PackedMessages.records` lays the Message records out in one uint8 buffer: the samples of
one kind (same columns present, same variable lengths) are written together as the rows of one
2-D array, column by column (headers, then payloads), and consecutive samples of one kind are
copied into the buffer as one block. Only the runs of samples of one kind cost Python.
"""

import numpy as np


class FixedColumn:
    """
    Messages of one fixed length: one row each.

    Parameters
    ----------
    rows : ndarray of uint8, shape (m, length)
        The messages' bytes.

    """

    def __init__(self, rows):
        self.rows = np.ascontiguousarray(rows, dtype=np.uint8)
        if self.rows.ndim != 2:
            raise ValueError(f'`rows` must be 2-D (messages, bytes), got {self.rows.shape}')

    def __len__(self):
        return self.rows.shape[0]

    def lengths(self):
        """Return each message's length [bytes]."""
        return np.full(len(self), self.rows.shape[1], dtype=np.int64)

    def take(self, chosen, length):
        """Return the messages ``chosen`` (indices), all ``length`` bytes, as rows."""
        return self.rows.take(chosen, axis=0)

    def message(self, k):
        """Return message ``k`` as bytes."""
        return self.rows[k].tobytes()


class VariableColumn:
    """
    Messages of any length, concatenated in one flat array.

    Parameters
    ----------
    data : ndarray of uint8, shape (total,)
        The messages' bytes, one after another.
    lengths : ndarray of int, shape (m,)
        Each message's length [bytes] (summing to ``total``).

    """

    def __init__(self, data, lengths):
        self.data = np.ascontiguousarray(data, dtype=np.uint8).reshape(-1)
        self._lengths = np.asarray(lengths, dtype=np.int64).reshape(-1)
        if self._lengths.size and (self._lengths.min() < 0
                                   or int(self._lengths.sum()) != self.data.size):
            raise ValueError(f'`lengths` sum to {int(self._lengths.sum())} bytes, '
                             f'`data` holds {self.data.size}')
        self.starts = np.cumsum(self._lengths) - self._lengths
        # All of one length: the rows are a 2-D view of the data, taken without an index.
        self.uniform = bool(self._lengths.size) and bool(np.all(self._lengths
                                                                == self._lengths[0]))

    @classmethod
    def from_sequence(cls, messages):
        """Concatenate a sequence of bytes-like messages (one pass each, no object per one)."""
        lengths = np.fromiter(map(len, messages), dtype=np.int64, count=len(messages))
        return cls(np.frombuffer(b''.join(messages), dtype=np.uint8), lengths)

    def __len__(self):
        return self._lengths.size

    def lengths(self):
        """Return each message's length [bytes]."""
        return self._lengths

    def take(self, chosen, length):
        """Return the messages ``chosen`` (indices), all ``length`` bytes, as rows."""
        if self.uniform:
            return self.data.reshape(len(self), -1).take(chosen, axis=0)
        return self.data[self.starts[chosen][:, None] + np.arange(length)]

    def message(self, k):
        """Return message ``k`` as bytes."""
        start = int(self.starts[k])
        return self.data[start:start + int(self._lengths[k])].tobytes()


class PackedMessages:
    """
    A batch of messages in sample-major order: per sample, each column present, in order.

    Parameters
    ----------
    columns : sequence of FixedColumn or VariableColumn
        Column ``c`` holds one message per sample where ``present[:, c]``, in sample order.
    present : ndarray of bool, shape (samples, columns)
        Which columns have a message at each sample.

    """

    def __init__(self, columns, present):
        self.columns = list(columns)
        self.present = np.asarray(present, dtype=bool)
        if self.present.ndim != 2 or self.present.shape[1] != len(self.columns):
            raise ValueError(f'`present` must have shape (samples, {len(self.columns)}), '
                             f'got {self.present.shape}')
        counts = self.present.sum(axis=0).tolist()
        # Each message's length at its sample and column (-1: none there).
        self.length_table = np.full(self.present.shape, -1, dtype=np.int64)
        for c, column in enumerate(self.columns):
            if len(column) != counts[c]:
                raise ValueError(f'column {c} holds {len(column)} messages for {counts[c]} '
                                 'samples present')
            self.length_table[self.present[:, c], c] = column.lengths()
        # Each message's row in its column: samples present before it in that column.
        self.rank = np.cumsum(self.present, axis=0) - 1
        # Each message's sample and column (row-major: sample-major, columns in order).
        self.sample_of, self.column_of = np.nonzero(self.present)

    def __len__(self):
        return self.sample_of.size

    def lengths(self):
        """Return each message's length [bytes], in order."""
        return self.length_table[self.present]

    def __getitem__(self, k):
        """Return message ``k`` as bytes (a writer that takes messages one by one)."""
        sample, column = int(self.sample_of[k]), int(self.column_of[k])
        return self.columns[column].message(int(self.rank[sample, column]))

    def message_list(self):
        """Return the messages as a list of bytes, in order (one object each)."""
        places = zip(self.column_of.tolist(),
                     self.rank[self.sample_of, self.column_of].tolist())
        return [self.columns[c].message(row) for c, row in places]

    def records(self, headers):
        """
        Lay out the messages' records, ``headers[k]`` then message k's bytes, in one buffer.

        Parameters
        ----------
        headers : ndarray of uint8, shape (n, head)
            Each message's record header (for MCAP: opcode, length, channel, sequence, log
            and publish time).

        Returns
        -------
        ndarray of uint8, shape (n * head + total length,)

        """
        kind_of, kinds = self._kinds()
        per_sample = self.present.sum(axis=1)
        first_message = np.cumsum(per_sample) - per_sample
        blocks = [self._kind_block(np.flatnonzero(kind_of == k), kind, headers, first_message)
                  for k, kind in enumerate(kinds)]
        if len(blocks) == 1:
            return blocks[0].reshape(-1)
        buffer = np.empty(sum(block.size for block in blocks), dtype=np.uint8)
        target = memoryview(buffer)
        sources = [memoryview(block.reshape(-1)) for block in blocks]
        sample_bytes = [block.shape[1] for block in blocks]
        # Runs of consecutive samples of one kind: one copy each, from the kind's next rows.
        starts = np.flatnonzero(np.diff(kind_of, prepend=-1))
        stops = np.append(starts[1:], kind_of.size)
        taken, offset = [0] * len(blocks), 0
        for start, stop, kind in zip(starts.tolist(), stops.tolist(),
                                     kind_of[starts].tolist()):
            size = (stop - start) * sample_bytes[kind]
            target[offset:offset + size] = sources[kind][taken[kind]:taken[kind] + size]
            taken[kind] += size
            offset += size
        return buffer

    def _kinds(self):
        """
        Group the samples by kind: the same columns present, of the same lengths.

        Returns
        -------
        kind_of : ndarray of intp, shape (samples,)
        kinds : ndarray of int64, shape (kinds, columns)
            Each kind's lengths (-1: column absent).

        """
        key = np.zeros(self.present.shape[0], dtype=np.int64)
        radix = 1
        for c, column in enumerate(self.columns):
            if isinstance(column, VariableColumn) and not column.uniform:
                values, code = np.unique(self.length_table[:, c], return_inverse=True)
                base = values.size
            else:
                code, base = self.present[:, c], 2
            if radix * base >= 1 << 62:     # keep the key in int64: renumber the kinds so far
                values, key = np.unique(key, return_inverse=True)
                radix = values.size
            key += code.reshape(-1) * radix
            radix *= base
        _, first, kind_of = np.unique(key, return_index=True, return_inverse=True)
        return kind_of.reshape(-1), self.length_table[first]

    def _kind_block(self, chosen, kind, headers, first_message):
        """Lay out the records of the samples ``chosen`` (all of one kind) as rows."""
        width = headers.shape[1]
        present = np.flatnonzero(kind >= 0)
        block = np.empty((chosen.size, int(kind[present].sum()) + width * present.size),
                         dtype=np.uint8)
        offset = 0
        for slot, c in enumerate(present.tolist()):
            block[:, offset:offset + width] = headers.take(first_message[chosen] + slot, axis=0)
            offset += width
            length = int(kind[c])
            block[:, offset:offset + length] = self.columns[c].take(self.rank[chosen, c],
                                                                    length)
            offset += length
        return block
