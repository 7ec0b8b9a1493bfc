"""
An MCAP file writer composed over the mcap library's public record classes.

Given the same calls it writes the bytes ``mcap.writer.Writer(enable_data_crcs=True)`` writes
(same records and order, chunking rule, summary groups and offsets; test_mcap_writer checks it
byte for byte), with what the recorder needs and the public ``Writer`` lacks:

- the summary's chunk indexes are kept encoded, at most ``chunk_index.INDEX_SPILL_BYTES`` in
  memory and the rest in an unnamed temporary file (:class:`.chunk_index.ChunkIndexStore`), so
  memory stays flat however many chunks a file holds (the ``Writer`` keeps a ~740 B
  ``ChunkIndex`` object per chunk);
- :meth:`McapFileWriter.add_messages` writes many messages at once, building Message and
  Message Index records with numpy rather than one Python call per message: a batch's records
  are laid out in one buffer (from a :class:`.packed_messages.PackedMessages`, the replay's,
  without a Python object per message) and each chunk takes slices of it.

Every other record is encoded by ``mcap.records`` through ``mcap.data_stream.RecordBuilder``;
Message and Message Index records follow the MCAP specification's layout.
"""

import struct
import zlib

from mcap.data_stream import RecordBuilder
from mcap.opcode import Opcode
from mcap.records import (Channel, Chunk, ChunkIndex, DataEnd, Footer, Header, Metadata,
                          MetadataIndex, Schema, Statistics, SummaryOffset)
import numpy as np
import zstandard

from .chunk_index import ChunkIndexStore
from .packed_messages import PackedMessages

MAGIC = b'\x89MCAP0\r\n'   # MCAP specification: starts and ends every file
COMPRESSIONS = ('zstd', 'none')
DEFAULT_ZSTD_LEVEL = 3
# Message record: opcode, record length, channel id, sequence, log time, publish time, data.
_MESSAGE_HEAD = struct.Struct('<BQHIQQ')
_MESSAGE_FIELDS = [('opcode', 'u1'), ('length', '<u8'), ('channel', '<u2'),
                   ('sequence', '<u4'), ('log', '<u8'), ('publish', '<u8')]
_MESSAGE_FIXED = _MESSAGE_HEAD.size - 9   # record length counts the fields after the prefix
# Chunk record after its prefix: start and end time, uncompressed size and CRC, and the
# compression's length (the name and the records' length and records follow).
_CHUNK_HEAD = struct.Struct('<QQQII')
# The longest record a part may hold (a chunk of OUTPUT_CHUNK_BYTES and one message more).
MAX_PART_RECORD = 1 << 28


class McapFileWriter:
    """
    Write one chunked, indexed MCAP file to a binary stream.

    Parameters
    ----------
    stream : binary file object
        Opened for writing; not closed here.
    chunk_size : int
        A chunk is written after the first record that takes it past this many bytes
        (uncompressed), as ``mcap.writer.Writer`` does.
    compression : {'zstd', 'none'}
    compression_level : int
        zstd level (3: zstandard's default; 1 compresses about twice as fast, the size within
        a percent on the node's outputs).
    spill_directory : str or os.PathLike
        Where the chunk index records beyond ``chunk_index.INDEX_SPILL_BYTES`` are kept until
        :meth:`finish`.

    """

    def __init__(self, stream, *, chunk_size, compression, spill_directory,
                 compression_level=DEFAULT_ZSTD_LEVEL):
        if compression not in COMPRESSIONS:
            raise ValueError(f'`compression` must be one of {COMPRESSIONS}, got {compression!r}')
        self._stream = stream
        self._chunk_size = int(chunk_size)
        self._compression = '' if compression == 'none' else compression
        # One compression context for every chunk: zstandard.compress() makes a new one per
        # call, which costs several times the compression of a 128 KiB chunk.
        self._compressor = (zstandard.ZstdCompressor(level=compression_level)
                            if self._compression else None)
        self._offset = 0          # bytes written to the stream
        self._data_crc = 0        # CRC-32 of the data section so far
        self._schemas = {}        # id -> Schema (the summary repeats them)
        self._channels = {}       # id -> Channel
        self._statistics = Statistics(
            attachment_count=0, channel_count=0, channel_message_counts={}, chunk_count=0,
            message_count=0, metadata_count=0, message_start_time=0, message_end_time=0,
            schema_count=0)
        self._chunk_indexes = ChunkIndexStore(spill_directory)
        self._metadata_indexes = []
        self._reset_chunk()

    # -- the open chunk ---------------------------------------------------------------------

    def _reset_chunk(self):
        self._parts = []          # records of the open chunk, uncompressed
        self._size = 0
        self._segments = []       # (channels, log times, offsets) arrays of its messages
        self._singles = ([], [], [])   # the same, for messages added one by one
        self._messages = 0
        self._start = self._end = 0

    def _append(self, record):
        self._parts.append(record)
        self._size += len(record)

    def _seal_singles(self):
        if self._singles[0]:
            channels, logs, offsets = self._singles
            self._segments.append((np.array(channels, dtype=np.uint16),
                                   np.array(logs, dtype=np.uint64),
                                   np.array(offsets, dtype=np.uint64)))
            self._singles = ([], [], [])

    # -- public API -------------------------------------------------------------------------

    @property
    def chunk_count(self):
        """Chunks written so far."""
        return self._statistics.chunk_count

    @property
    def chunk_indexes(self):
        """Return the :class:`ChunkIndexStore` of the chunks written so far."""
        return self._chunk_indexes

    def start(self, profile, library):
        """Write the magic and the Header record."""
        builder = RecordBuilder()
        Header(profile=profile, library=library).write(builder)
        self._write(MAGIC + builder.end())

    def register_schema(self, name, encoding, data):
        """Add a Schema (to the open chunk, and to the summary); return its id."""
        schema = Schema(id=len(self._schemas) + 1, name=name, encoding=encoding, data=data)
        self._schemas[schema.id] = schema
        self._statistics.schema_count += 1
        self._add_record(schema)
        return schema.id

    def register_channel(self, topic, message_encoding, schema_id, metadata):
        """Add a Channel (to the open chunk, and to the summary); return its id."""
        channel = Channel(id=len(self._channels) + 1, topic=topic, schema_id=schema_id,
                          message_encoding=message_encoding, metadata=metadata)
        self._channels[channel.id] = channel
        self._statistics.channel_count += 1
        self._add_record(channel)
        return channel.id

    def add_metadata(self, name, data):
        """Write a Metadata record now, outside any chunk (as ``Writer.add_metadata``)."""
        builder = RecordBuilder()
        Metadata(name=name, metadata=dict(data)).write(builder)
        record = builder.end()
        self._metadata_indexes.append(MetadataIndex(offset=self._offset, length=len(record),
                                                    name=name))
        self._statistics.metadata_count += 1
        self._write(record)

    def _add_record(self, record):
        builder = RecordBuilder()
        record.write(builder)
        self._append(builder.end())
        if self._size > self._chunk_size:
            self._finish_chunk()

    def add_message(self, channel_id, log_time, data, publish_time, sequence=0):
        """Add one message to the open chunk (written once it exceeds the chunk size)."""
        statistics = self._statistics
        statistics.message_start_time = (log_time if statistics.message_count == 0
                                         else min(log_time, statistics.message_start_time))
        statistics.message_end_time = max(log_time, statistics.message_end_time)
        counts = statistics.channel_message_counts
        counts[channel_id] = counts.get(channel_id, 0) + 1
        statistics.message_count += 1
        self._start = log_time if self._messages == 0 else min(self._start, log_time)
        self._end = max(self._end, log_time)
        channels, logs, offsets = self._singles
        channels.append(channel_id)
        logs.append(log_time)
        offsets.append(self._size)
        self._messages += 1
        self._append(_MESSAGE_HEAD.pack(Opcode.MESSAGE, _MESSAGE_FIXED + len(data), channel_id,
                                        sequence, log_time, publish_time))
        self._append(data)
        if self._size > self._chunk_size:
            self._finish_chunk()

    def flush(self):
        """Write the open chunk, if it holds a message, and flush the stream (no fsync)."""
        self._finish_chunk()
        self._stream.flush()

    def close(self):
        """Release the chunk index store without finishing (the file is abandoned)."""
        self._chunk_indexes.close()

    def _write(self, data):
        self._stream.write(data)
        self._offset += len(data)
        self._data_crc = zlib.crc32(data, self._data_crc)

    def _finish_chunk(self):
        """Write the open chunk and its message indexes (a chunk without messages waits)."""
        if self._messages == 0:
            return
        self._seal_singles()
        channels, logs, offsets = (np.concatenate(column) for column in zip(*self._segments))
        data = b''.join(self._parts)
        compressed = self._compressor.compress(data) if self._compression else data
        chunk = Chunk(compression=self._compression, data=compressed,
                      message_start_time=self._start, message_end_time=self._end,
                      uncompressed_crc=zlib.crc32(data), uncompressed_size=len(data))
        builder = RecordBuilder()
        chunk.write(builder)
        chunk_offset = self._offset
        self._write(builder.end())
        index_offsets, index_records = _message_indexes(channels, logs, offsets, self._offset)
        self._write(index_records)
        self._statistics.chunk_count += 1
        self._chunk_indexes.append(ChunkIndex(
            message_start_time=self._start, message_end_time=self._end,
            chunk_start_offset=chunk_offset, chunk_length=self._offset - chunk_offset
            - len(index_records), message_index_offsets=index_offsets,
            message_index_length=len(index_records), compression=self._compression,
            compressed_size=len(compressed), uncompressed_size=len(data)))
        self._reset_chunk()

    # -- many messages at once --------------------------------------------------------------

    def add_messages(self, channels, messages, log, publish, flush_period_ns, last_flush_ns,
                     sequences=None):
        """
        Add messages as :meth:`add_message` calls in order would, plus flushes by log time.

        A flush (chunk written, stream flushed) happens after the first message whose log time
        is ``flush_period_ns`` or more after the last flush's (``last_flush_ns``; None: the
        first message starts the period), as the recorder does after each message.

        Parameters
        ----------
        channels : numpy.ndarray of uint16, shape (n,)
            Channel id of each message.
        messages : sequence of bytes, or PackedMessages, length n
            CDR bytes of each message.
        log : numpy.ndarray of int64, shape (n,)
            Log (receive) times [ns].
        publish : numpy.ndarray of int64, shape (n,)
            Publish (send) times [ns].
        flush_period_ns : int
            Log time between flushes [ns].
        last_flush_ns : int or None
            Log time of the last flush [ns].
        sequences : numpy.ndarray of uint32, shape (n,), optional
            Sequence number of each message (default 0).

        Returns
        -------
        list of (index, log_ns)
            The messages after which a flush happened, and their log times.

        """
        count = len(messages)
        if isinstance(messages, PackedMessages):
            sizes = messages.lengths()
            records = messages.records(_message_headers(channels, sizes, log, publish,
                                                        sequences))
        else:
            sizes = np.fromiter(map(len, messages), dtype=np.int64, count=count)
            records = _message_records(channels, messages, sizes, log, publish, sequences)
        ends = np.cumsum(sizes + _MESSAGE_HEAD.size)   # end of each record in the batch
        starts = ends - (sizes + _MESSAGE_HEAD.size)
        self._count_batch(channels, log)
        flushes = []
        first = 0
        while first < count:
            # The chunk closes after the first message that takes it past chunk_size ...
            limit = self._chunk_size - self._size + int(starts[first])
            stop = first + int(np.searchsorted(ends[first:], limit, side='right'))
            stop = stop if stop < count else None
            # ... or after which the flush period of log time has elapsed.
            window_first = first
            if last_flush_ns is None:
                last_flush_ns = int(log[first])
                window_first = first + 1
            window_last = count - 1 if stop is None else stop
            timed = None
            if window_first <= window_last:
                due = log[window_first:window_last + 1] - last_flush_ns >= flush_period_ns
                if due.any():
                    timed = window_first + int(np.argmax(due))
                    stop = timed
            last = count if stop is None else stop + 1
            self._hold(records, channels, log, starts, ends, first, last)
            if stop is None:
                return flushes
            self._finish_chunk()
            if timed is not None:
                self._stream.flush()
                last_flush_ns = int(log[stop])
                flushes.append((stop, last_flush_ns))
            first = stop + 1
        return flushes

    def _count_batch(self, channels, log):
        statistics = self._statistics
        low, high = int(log.min()), int(log.max())
        statistics.message_start_time = (low if statistics.message_count == 0
                                         else min(statistics.message_start_time, low))
        statistics.message_end_time = max(statistics.message_end_time, high)
        statistics.message_count += len(log)
        counts = statistics.channel_message_counts
        unique, seen, numbers = np.unique(channels, return_index=True, return_counts=True)
        for k in np.argsort(seen, kind='stable').tolist():   # in order of first message
            channel = int(unique[k])
            counts[channel] = counts.get(channel, 0) + int(numbers[k])

    def _hold(self, records, channels, log, starts, ends, first, stop):
        """Put messages first..stop-1 of a batch (their records: a slice of ``records``)."""
        self._seal_singles()
        times = log[first:stop]
        low, high = int(times.min()), int(times.max())
        self._start = low if self._messages == 0 else min(self._start, low)
        self._end = max(self._end, high)
        offsets = (starts[first:stop] - int(starts[first]) + self._size).astype(np.uint64)
        self._segments.append((channels[first:stop], times.astype(np.uint64), offsets))
        self._messages += stop - first
        self._append(memoryview(records)[int(starts[first]):int(ends[stop - 1])])

    # -- chunks written elsewhere -----------------------------------------------------------

    def write_chunks_only(self):
        """Write the open chunk (no flush): what a part's writer does at its end."""
        self._finish_chunk()

    def append_chunks(self, source):
        """
        Append the chunks and message indexes another writer of the same channels wrote.

        ``source``: a binary file holding only Chunk records, each followed by its Message
        Index records (a writer that never started a file: :meth:`write_chunks_only`), read
        from its start. The open chunk is written first. Their summary entries (chunk
        indexes at this file's offsets, statistics) are added here.

        Returns
        -------
        appended : dict
            Channel id -> messages appended on it.
        times : list
            The least and the greatest log time appended [ns] (None twice: none).

        """
        self._finish_chunk()
        appended, times = {}, [None, None]
        reader = _RecordReader(source)
        record = reader.next()
        while record is not None:
            opcode, data = record
            if opcode != Opcode.CHUNK:
                raise ValueError(f'a part holds a record of opcode {opcode} outside a chunk')
            chunk_offset = self._offset
            self._write(data)
            head = _CHUNK_HEAD.unpack_from(data, 9)
            compression = bytes(data[9 + _CHUNK_HEAD.size:9 + _CHUNK_HEAD.size + head[4]])
            records_size = len(data) - 9 - _CHUNK_HEAD.size - head[4] - 8
            index_start = self._offset
            self._note_times(head[0], head[1])
            times = [head[0] if times[0] is None else min(times[0], head[0]),
                     head[1] if times[1] is None else max(times[1], head[1])]
            offsets = {}
            record = reader.next()
            while record is not None and record[0] == Opcode.MESSAGE_INDEX:
                channel, size = struct.unpack_from('<HI', record[1], 9)
                offsets[channel] = self._offset
                appended[channel] = appended.get(channel, 0) + size // 16
                self._count_channel(channel, size // 16)
                self._write(record[1])
                record = reader.next()
            self._statistics.chunk_count += 1
            self._chunk_indexes.append(ChunkIndex(
                message_start_time=head[0], message_end_time=head[1],
                chunk_start_offset=chunk_offset, chunk_length=index_start - chunk_offset,
                message_index_offsets=offsets, message_index_length=self._offset - index_start,
                compression=compression.decode(), compressed_size=records_size,
                uncompressed_size=head[2]))
        return appended, times

    def _count_channel(self, channel, count):
        counts = self._statistics.channel_message_counts
        counts[channel] = counts.get(channel, 0) + count
        self._statistics.message_count += count

    def _note_times(self, low, high):
        statistics = self._statistics
        statistics.message_start_time = (low if statistics.message_count == 0
                                         else min(statistics.message_start_time, low))
        statistics.message_end_time = max(statistics.message_end_time, high)

    # -- the end ----------------------------------------------------------------------------

    def finish(self):
        """Write the open chunk, Data End, the summary and the footer (stream left open)."""
        self._finish_chunk()
        builder = RecordBuilder()
        DataEnd(data_section_crc=self._data_crc).write(builder)
        self._write(builder.end())
        summary_start = self._offset
        summary = RecordBuilder()
        offsets = []

        def group(opcode, records):
            group_start = summary.count
            for record in records:
                record.write(summary)
            offsets.append(SummaryOffset(group_opcode=opcode,
                                         group_start=summary_start + group_start,
                                         group_length=summary.count - group_start))

        group(Opcode.SCHEMA, self._schemas.values())
        group(Opcode.CHANNEL, self._channels.values())
        group(Opcode.STATISTICS, [self._statistics])
        group(Opcode.CHUNK_INDEX, [self._chunk_indexes])
        group(Opcode.ATTACHMENT_INDEX, [])
        group(Opcode.METADATA_INDEX, self._metadata_indexes)
        summary_offset_start = summary_start + summary.count
        for offset in offsets:
            offset.write(summary)
        data = summary.end()
        footer = Footer(summary_start=summary_start, summary_offset_start=summary_offset_start,
                        summary_crc=0)
        builder = RecordBuilder()
        footer.write(builder)
        footer_record = builder.end()
        # The summary CRC covers the summary and the footer up to its own CRC field.
        footer.summary_crc = zlib.crc32(footer_record[:-4], zlib.crc32(data))
        footer.write(builder)
        self._stream.write(data + builder.end() + MAGIC)
        self._offset += len(data) + len(footer_record) + len(MAGIC)
        self._chunk_indexes.close()


class _RecordReader:
    """Records (opcode, bytes of the whole record) of a stream of MCAP records, in order."""

    def __init__(self, stream):
        self._stream = stream

    def next(self):  # noqa: A003
        """Read the next record: (opcode, its bytes), or None at the end."""
        prefix = self._stream.read(9)
        if not prefix:
            return None
        opcode, length = struct.unpack('<BQ', prefix)
        if len(prefix) < 9 or length > MAX_PART_RECORD:
            raise ValueError(f'a part holds a cut or oversized record ({length} bytes)')
        body = self._stream.read(length)
        if len(body) != length:
            raise ValueError('a part ends inside a record')
        return opcode, prefix + body


def _message_headers(channels, sizes, log, publish, sequences):
    """Message record headers of a batch (fields before the data), a row of uint8 each."""
    headers = np.zeros(len(sizes), dtype=np.dtype(_MESSAGE_FIELDS))
    headers['opcode'] = Opcode.MESSAGE
    headers['length'] = sizes + _MESSAGE_FIXED
    headers['channel'] = channels
    headers['log'] = log
    headers['publish'] = publish
    if sequences is not None:
        headers['sequence'] = sequences
    return headers.view(np.uint8).reshape(len(sizes), _MESSAGE_HEAD.size)


def _message_records(channels, messages, sizes, log, publish, sequences):
    """Message records of a batch of bytes objects, one after another in one bytes object."""
    count = len(messages)
    head_size = _MESSAGE_HEAD.size
    head = _message_headers(channels, sizes, log, publish, sequences).tobytes()
    parts = [None] * (2 * count)
    parts[0::2] = [head[k:k + head_size] for k in range(0, head_size * count, head_size)]
    parts[1::2] = messages
    return b''.join(parts)


def _message_indexes(channels, logs, offsets, start):
    """
    Message Index records of one chunk, a channel each in order of first message.

    Returns
    -------
    (dict, bytes)
        Channel id -> file offset of its record (records start at ``start``), and the
        records.

    """
    # The messages grouped by channel, in order within each (a stable sort): one pass.
    order = np.argsort(channels, kind='stable')
    entries = np.empty((order.size, 2), dtype='<u8')
    entries[:, 0] = logs[order]
    entries[:, 1] = offsets[order]
    firsts = np.flatnonzero(np.diff(channels[order], prepend=-1))
    lasts = np.append(firsts[1:], order.size)
    builder = RecordBuilder()
    index_offsets = {}
    for group in np.argsort(order[firsts]).tolist():     # by each channel's first message
        channel = int(channels[order[firsts[group]]])
        payload = entries[firsts[group]:lasts[group]].tobytes()
        index_offsets[channel] = start + builder.count
        builder.start_record(Opcode.MESSAGE_INDEX)
        builder.write2(channel)
        builder.write4(len(payload))
        builder.write(payload)
        builder.finish_record()
    return index_offsets, builder.end()
