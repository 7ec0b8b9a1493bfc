"""
The summary's Chunk Index records of an MCAP file being written, kept encoded and spilled.

The mcap library's ``Writer`` keeps one ``ChunkIndex`` object per chunk (about 740 B); a long
recording has many thousands of chunks. :class:`ChunkIndexStore` keeps them as their encoded
records (about 130 B each), at most :data:`INDEX_SPILL_BYTES` in memory and the rest in an
unnamed temporary file, so memory stays flat however many chunks a file holds.
"""

import os
import tempfile

from mcap.data_stream import RecordBuilder

# The summary's chunk indexes (one record per chunk, about 130 B with 5 topics) are held in
# memory up to this size, then moved to an unnamed temporary file beside the recording.
INDEX_SPILL_BYTES = 256 * 1024


class ChunkIndexStore:
    """
    Chunk Index records for the summary, spilled to an unnamed temporary file.

    Each ``ChunkIndex`` is encoded when the chunk is written; at most
    :data:`INDEX_SPILL_BYTES` of records stay in memory and the rest go to a temporary file in
    ``directory`` (deleted by the OS when closed, even on a crash).
    """

    def __init__(self, directory):
        self._directory = directory
        self._buffer = bytearray()
        self._spill = None
        self._count = 0

    def append(self, index):
        """Encode one ``mcap.records.ChunkIndex``."""
        builder = RecordBuilder()
        index.write(builder)
        self._buffer += builder.end()
        self._count += 1
        if len(self._buffer) >= INDEX_SPILL_BYTES:
            if self._spill is None:
                self._spill = tempfile.TemporaryFile(dir=self._directory, prefix='.mcap-index-')
            self._spill.write(self._buffer)
            self._buffer = bytearray()   # a new buffer: the old one's memory is released

    def __len__(self):
        return self._count

    @property
    def memory_bytes(self):
        """Bytes of records held in memory (the rest are in the temporary file)."""
        return len(self._buffer)

    def write(self, builder):
        """Append every record, in order, to ``builder`` (the summary being written)."""
        if self._spill is not None:
            self._spill.flush()
            self._spill.seek(0)
            for block in iter(lambda: self._spill.read(1 << 20), b''):
                builder.write(block)
            self._spill.seek(0, os.SEEK_END)
        builder.write(self._buffer)

    def close(self):
        """Drop the temporary file (the summary is written, or the file is abandoned)."""
        if self._spill is not None:
            self._spill.close()
            self._spill = None
        self._buffer = bytearray()
