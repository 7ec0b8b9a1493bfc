"""
The MCAP of a replay: the input and the node's outputs recomputed offline.

Per sample: the input, the two deflections, the criteria and the quality (the error and
nonlinearity indicators, the node's ``~/quality``), and every ``markers_every_n``-th sample the
markers, each logged at the input's log time (the order the node records them in). The
messages are encoded in bulk (the row encoders of :mod:`io.output_cdr`, a 2-D uint8 array per
topic) and written in batches of samples (:meth:`McapRecorder.write_batch`) as
:class:`.packed_messages.PackedMessages`: no Python object per message, the records of a batch
laid out in one buffer that the chunks are cut from.
"""

import itertools

import numpy as np

from .mcap_writer import McapFileWriter
from .output_cdr import criteria_rows, MarkerEncoder, quality_rows, vector3_stamped_rows
from .packed_messages import FixedColumn, PackedMessages, VariableColumn
from .recorder import McapRecorder
from .recorder_files import add_batch, batch_arguments, OpenFile, Topic
from ..core.reduction.second_order_tables import SecondOrderForms
from ..names import JOINT_STATE, MARKER_ARRAY, OUTPUT_POINTS, VECTOR3_STAMPED

# Rows encoded and written together by write_replay. The markers' contraction runs over a
# batch's rows at once and its last bits depend on them (about one marker in a thousand differs
# with batches of 2 048): the same batches give the same bytes.
WRITE_BATCH = 1024
# The output is written in one go, not live: chunks larger than the node's (whose chunk is what
# a crash may lose), no flushes by log time and no flush thread (whose flushes by wall time
# would make the chunk boundaries depend on the machine's speed).
OUTPUT_CHUNK_BYTES = 1 << 20
OUTPUT_FLUSH_PERIOD_S = 3600.0
# zstd level -3, the MCAP writers' "fast" level: a third of the compression time of the default
# level 3, the file about 3 % larger (the outputs are doubles: little to find at any level).
OUTPUT_ZSTD_LEVEL = -3


class MarkerSource:
    """
    MarkerArray bytes of the deformed linkage at replayed samples.

    Parameters
    ----------
    model : ReducedModel
        The model whose shape table gives the link points.
    frame_id : str
        Frame of the markers.
    exaggeration : float
        Scale of the drawn deflections.
    points_per_link : int
        Points drawn along each link.
    joint_levels : sequence
        Diagnostic level of each of the four joints (their colours).

    """

    def __init__(self, model, frame_id, exaggeration, points_per_link, joint_levels):
        self.model, self.exaggeration = model, exaggeration
        self.encoder = MarkerEncoder(frame_id, points_per_link)
        self.levels = list(joint_levels)
        # Resampling the link points (linear interpolation along each link) is linear: apply
        # it to the shape table once.
        table = model.shape_table
        source = np.linspace(0.0, 1.0, table.shape[3])
        target = np.linspace(0.0, 1.0, points_per_link)
        resample = np.stack([np.interp(target, source, unit) for unit in np.eye(source.size)],
                            axis=1)
        self.table = np.einsum('ts,nclsdr->ncltdr', resample, table)
        # A model of order 2 draws the joints' second-order motion too.
        self.second = (None if model.second_order is None
                       else SecondOrderForms(model.second_order))

    def rows(self, stamps_ns, angles, modal):
        """
        Marker arrays at many samples.

        Parameters
        ----------
        stamps_ns : ndarray of int, shape (m,)
            Stamps [ns].
        angles : ndarray, shape (m,)
            Crank angles [rad].
        modal : ndarray, shape (m, r)
            Reduced coordinates.

        Returns
        -------
        ndarray of uint8, shape (m, length)
            One CDR message per row.

        """
        cells, t = self.model.cell(angles)
        powers = t[:, None] ** np.arange(self.table.shape[1])
        values = np.einsum('mp,mpltdr->mltdr', powers, self.table[cells])
        positions = values[..., -1]
        deflections = np.einsum('mltdr,mr->mltd', values[..., :-1], modal)
        if self.second is not None:
            deflections += self.second.link_motion(cells, t, modal, deflections.shape[2])
        joints = positions[:, (0, 0, 1, 2), (0, -1, -1, 0)]
        return self.encoder.encode_rows(stamps_ns, positions, deflections, self.exaggeration,
                                        joints, self.levels)


def replay_topics(input_topic, topics, markers):
    """Return the output file's topics and their types, in the order they are declared."""
    declared = [(input_topic, JOINT_STATE)]
    declared += [(topics[key], VECTOR3_STAMPED) for key in OUTPUT_POINTS]
    declared += [(topics['criteria'], JOINT_STATE), (topics['quality'], JOINT_STATE)]
    if markers:
        declared.append((topics['markers'], MARKER_ARRAY))
    return declared


def _output_columns(samples, estimate, chosen, valid, frame):
    """Encode the samples ``chosen``: a column of inputs, one per output (``valid`` only)."""
    stamps = samples['stamps_ns'][chosen][valid]

    def values(key):
        return estimate[key][chosen][valid]

    return [VariableColumn.from_sequence(samples['data'][chosen]),
            FixedColumn(vector3_stamped_rows(stamps, frame, values('lever_tip'))),
            FixedColumn(vector3_stamped_rows(stamps, frame, values('coupler_mid'))),
            FixedColumn(criteria_rows(stamps, frame, values('criterion'), values('gamma_dot'),
                                      values('reaction_n'))),
            FixedColumn(quality_rows(stamps, frame, values('error_indicator'),
                                     values('nonlinearity')))]


def _write_batch(recorder, samples, estimate, chosen, first, names, marker_topic, frame,
                 markers_every_n, marker_source):
    """Encode and write the samples of the slice ``chosen`` of a block of rows from ``first``."""
    # Outlier and out-of-bound samples (NaN) keep their input, with no outputs.
    valid = (np.all(np.isfinite(estimate['lever_tip'][chosen]), axis=1)
             & np.all(np.isfinite(estimate['coupler_mid'][chosen]), axis=1))
    columns = _output_columns(samples, estimate, chosen, valid, frame)
    topics = list(names)
    present = np.zeros((valid.size, len(names) + bool(markers_every_n)), dtype=bool)
    present[:, 0] = True
    present[:, 1:len(names)] = valid[:, None]
    if markers_every_n:
        rows = np.arange(first + chosen.start, first + chosen.stop)
        marked = (rows % markers_every_n == 0) & valid
        columns.append(FixedColumn(marker_source.rows(
            samples['stamps_ns'][chosen][marked], estimate['crank_angle'][chosen][marked],
            estimate['modal'][chosen][marked])))
        topics.append(marker_topic)
        present[:, -1] = marked
    # Per sample its input, outputs and marker, each logged at the input's log time; the
    # input keeps its publish time, the outputs are sent at its log time.
    per_sample = present.sum(axis=1)
    log_times = np.repeat(samples['log_ns'][chosen], per_sample)
    publish_times = log_times.copy()
    publish_times[np.cumsum(per_sample) - per_sample] = samples['publish_ns'][chosen]
    recorder.write_batch(topics, PackedMessages(columns, present), log_times, publish_times)


class PartWriter:
    """
    Replay rows written as chunks alone into a stream, to append to a recording later.

    The part of a replay another process writes (:mod:`cli.replay_split`): the channels are
    numbered as :func:`write_replay` declares them and each topic's sequence numbers go on
    from ``sequences`` (topic -> messages before the part); :meth:`McapRecorder.append_part`
    appends the stream to the output file.
    """

    def __init__(self, stream, declared, sequences, spill_directory):
        self.writer = McapFileWriter(stream, chunk_size=OUTPUT_CHUNK_BYTES, compression='zstd',
                                     spill_directory=spill_directory,
                                     compression_level=OUTPUT_ZSTD_LEVEL)
        self.stream = stream
        self.topics = {name: Topic(name, type_name, [], sequence=int(sequences.get(name, 0)))
                       for name, type_name in declared}
        self.file = OpenFile(None, stream, self.writer,
                             {name: number for number, (name, _) in enumerate(declared, 1)})

    def write_batch(self, topics, messages, log_times_ns, publish_times_ns):
        """Write a batch (:meth:`McapRecorder.write_batch`'s arguments)."""
        names, index, log, publish = batch_arguments(topics, messages, log_times_ns,
                                                     publish_times_ns, self.topics)
        if len(messages):
            add_batch(self.file, self.topics, names, index, messages, log, publish,
                      int(OUTPUT_FLUSH_PERIOD_S * 1e9), None)

    def finish(self):
        """Write the open chunk and flush the stream."""
        self.writer.write_chunks_only()
        self.writer.close()
        self.stream.flush()


def write_rows(target, blocks, declared, frame_id, model, markers_every_n=10,
               exaggeration=10.0, points_per_link=9, progress=None, joint_levels=None):
    """
    Encode and write blocks of rows into ``target`` (a recorder or a :class:`PartWriter`).

    ``declared``: :func:`replay_topics`. The other arguments as :func:`write_replay`; rows
    are numbered by their blocks' ``first`` (markers on rows that are multiples of
    ``markers_every_n``). Returns the rows written up to.
    """
    names = tuple(name for name, _ in declared[:5])
    marker_topic = declared[5][0] if len(declared) > 5 else None
    marker_source = (MarkerSource(model, frame_id, exaggeration, points_per_link,
                                  joint_levels) if markers_every_n else None)
    frame = frame_id.encode()
    written = 0
    for first, samples, estimate in blocks:
        count = len(samples['data'])
        for start in range(0, count, WRITE_BATCH):
            chosen = slice(start, min(start + WRITE_BATCH, count))
            _write_batch(target, samples, estimate, chosen, first, names, marker_topic, frame,
                         markers_every_n, marker_source)
        written = first + count
        if progress is not None:
            progress(written)
    return written


def write_replay(out_path, blocks, input_topic, topics, frame_id, model, markers_every_n=10,
                 exaggeration=10.0, points_per_link=9, progress=None, joint_levels=None,
                 provenance=None, tail=None):
    """
    Write the input and the recomputed outputs into a rosbag2 MCAP, a block of rows at a time.

    Parameters
    ----------
    out_path : str or os.PathLike
        Output ``.mcap`` file or bag directory (must not exist).
    blocks : iterable of (first, samples, estimate)
        Consecutive rows from row ``first``: their input (``samples``,
        :func:`io.joint_states.crank_samples`) and their offline estimate (``estimate``,
        :func:`core.estimation.offline.estimate_stream`). Rows are written in batches of
        ``WRITE_BATCH`` from the block's start (blocks starting at multiples of it give the
        same batches however the rows are split).
    input_topic : str
        Topic of the input.
    topics : dict
        Output topics (:func:`names.output_topics`).
    frame_id : str
        Frame of the outputs.
    model : ReducedModel
        The model of the estimate (its shapes draw the markers).
    markers_every_n : int
        Markers on every n-th row (0: none).
    exaggeration : float
        Scale of the drawn deflections.
    points_per_link : int
        Marker points along each link.
    progress : callable, optional
        ``progress(n)`` after each block (n: rows written) and ``progress(n, force=True)`` at
        the end.
    joint_levels : sequence, optional
        Diagnostic level of each joint in the markers (required with markers).
    provenance : dict, optional
        What made the estimates (:func:`.provenance.provenance_entries`), recorded with them.
    tail : callable, optional
        ``tail(recorder)`` after the blocks, before the file is closed (appends the rows
        another process wrote: :meth:`McapRecorder.append_part`); returns the rows it added.

    Returns
    -------
    dict
        The recorder's final status.

    """
    # The file is set up once the first rows are estimated: the estimate's start (its warm
    # start, numpy calls that each give the GIL up) then does not share the GIL with it.
    blocks = iter(blocks)
    head = next(blocks, None)
    blocks = itertools.chain([] if head is None else [head], blocks)
    recorder = McapRecorder(out_path, chunk_size_bytes=OUTPUT_CHUNK_BYTES,
                            flush_period_s=OUTPUT_FLUSH_PERIOD_S, flush_thread=False,
                            provenance=provenance, compression_level=OUTPUT_ZSTD_LEVEL)
    recorder.open()
    try:
        declared = replay_topics(input_topic, topics, markers_every_n)
        for name, type_name in declared:
            recorder.add_topic(name, type_name)
        written = write_rows(recorder, blocks, declared, frame_id, model, markers_every_n,
                             exaggeration, points_per_link, progress, joint_levels)
        if tail is not None:
            written += tail(recorder)
        if progress is not None:
            progress(written, force=True)
    finally:
        status = recorder.close()
    return status
