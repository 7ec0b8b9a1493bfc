"""
What a bag directory's MCAP files hold, read from the files alone (for ``flexlink reindex``).

A recorder killed before its ``close`` leaves a bag directory without ``metadata.yaml`` and
its last file without a summary. :func:`.bag_files.bag_files` finds the directory's MCAP files
as rosbag2 names them (``<dir>/<dir>_0.mcap``, ``<dir>_1.mcap``, ...); :func:`scan_bag_file` reads
one through the salvaging reader (:mod:`.mcap_reader`, bounded): its intact messages per
channel, their log times, and each channel's topic, type, ``offered_qos_profiles`` and
``topic_type_hash``. :func:`bag_topics` merges them into the topic records
:func:`.bag_metadata.write_bag_metadata` takes. :func:`rewrite_complete` writes the intact
messages of a file cut short into a complete file with the ``rosbag2`` metadata records
(without them rosbag2 reads the channels' QoS in the pre-version-9 format, and fails).
"""

import dataclasses
import os
import pathlib

import yaml

from .bag_metadata import METADATA_RECORD
from .mcap_reader import iter_messages, map_file, Salvage
from .mcap_records import MESSAGE_HEAD, MESSAGE_HEAD_SIZE
from .mcap_writer import McapFileWriter
from .provenance import PROVENANCE_RECORD
from .recorder_files import create_exclusive, LIBRARY


@dataclasses.dataclass
class BagTopic:
    """A topic as ``metadata.yaml`` lists it, rebuilt from the files' channels."""

    name: str
    type_name: str
    qos_profiles: list
    type_hash: str
    message_count: int = 0


def scan_bag_file(path):
    """
    Read one MCAP file (whole, truncated or damaged) and describe its intact messages.

    Parameters
    ----------
    path : pathlib.Path
        The file.

    Returns
    -------
    dict
        ``path``, ``complete`` (has its summary and footer), ``header`` (readable),
        ``end_reason``,
        ``message_count``, ``first_log_ns``, ``last_log_ns`` (None without messages),
        ``channels`` (list of dicts: ``topic``, ``type``, ``encoding``, ``metadata``,
        ``count``), ``damaged_count``.

    """
    salvage = Salvage()
    counts, first, last = {}, None, None
    buffer = map_file(path)
    try:
        for records, body, _ in iter_messages(buffer, salvage):
            channel_id, _, log_time, _ = MESSAGE_HEAD.unpack_from(records, body)
            if channel_id not in salvage.channels:
                continue
            counts[channel_id] = counts.get(channel_id, 0) + 1
            first = log_time if first is None else min(first, log_time)
            last = log_time if last is None else max(last, log_time)
    finally:
        buffer.close()
    channels = []
    for channel in salvage.channels.values():
        schema = salvage.schemas.get(channel.schema_id)
        channels.append({'topic': channel.topic, 'type': schema.name if schema else '',
                         'encoding': channel.message_encoding,
                         'metadata': dict(channel.metadata),
                         'count': counts.get(channel.id, 0)})
    return {'path': pathlib.Path(path), 'complete': salvage.end_reason == 'complete',
            'header': salvage.profile is not None,
            'end_reason': salvage.end_reason, 'message_count': sum(counts.values()),
            'first_log_ns': first, 'last_log_ns': last, 'channels': channels,
            'damaged_count': salvage.damaged_count}


def bag_topics(scans):
    """
    Merge the channels of a bag's files into its topics (first file's QoS and type win).

    Parameters
    ----------
    scans : list of dict
        :func:`scan_bag_file` results.

    Returns
    -------
    dict
        Topic name -> :class:`BagTopic`, in order of first appearance.

    Raises
    ------
    ValueError
        A channel that is not CDR-encoded or has no schema (not a rosbag2 recording).

    """
    topics = {}
    for scan in scans:
        for channel in scan['channels']:
            if channel['encoding'] != 'cdr' or not channel['type']:
                raise ValueError(f"{scan['path']}: topic {channel['topic']!r} is not a ROS 2 "
                                 f"CDR channel with a schema (encoding {channel['encoding']!r})")
            topic = topics.get(channel['topic'])
            if topic is None:
                metadata = channel['metadata']
                profiles = yaml.safe_load(metadata.get('offered_qos_profiles') or '[]') or []
                topic = topics[channel['topic']] = BagTopic(
                    channel['topic'], channel['type'], list(profiles),
                    metadata.get('topic_type_hash', ''))
            topic.message_count += channel['count']
    return topics


def rewrite_complete(source, destination, opening, closing, mode=0o644, provenance=None):
    """
    Write every intact message of an MCAP file into a new, complete file.

    Schemas, channels (with their metadata), sequence numbers and times are kept; the
    ``rosbag2`` metadata records are written as the recorder writes them (one after the
    header, one before the summary).

    Parameters
    ----------
    source : pathlib.Path
        The file cut short (or damaged).
    destination : pathlib.Path
        The new file; created exclusively (refused if anything is there).
    opening, closing : dict
        The maps of the two ``rosbag2`` records (:func:`.bag_metadata.serialized_metadata`).
    mode : int
        Permission bits of the new file (from its creation on, so never more open).
    provenance : dict, optional
        The ``flexlink_ros`` record's map, written after the opening record (:mod:`.provenance`).

    """
    salvage = Salvage()
    buffer = map_file(source)
    try:
        with create_exclusive(destination, mode) as stream:
            os.fchmod(stream.fileno(), mode)     # exactly, whatever the umask
            writer = McapFileWriter(stream, chunk_size=128 * 1024, compression='zstd',
                                    spill_directory=pathlib.Path(destination).parent)
            copy = _Copy(writer, salvage, opening, provenance)
            for records, body, stop in iter_messages(buffer, salvage):
                channel_id, sequence, log_time, publish_time = MESSAGE_HEAD.unpack_from(
                    records, body)
                if channel_id in salvage.channels:
                    writer.add_message(copy.channel(channel_id), log_time,
                                       bytes(records[body + MESSAGE_HEAD_SIZE:stop]),
                                       publish_time, sequence)
            for channel_id in salvage.channels:   # channels without a message kept too
                copy.channel(channel_id)
            copy.start()
            writer.add_metadata(METADATA_RECORD, closing)
            writer.finish()
    finally:
        buffer.close()


class _Copy:
    """Schemas and channels of a salvaged file, added to the new file as first needed."""

    def __init__(self, writer, salvage, opening, provenance=None):
        self.writer, self.salvage, self.opening = writer, salvage, opening
        self.provenance = provenance
        self.started = False
        self.schema_ids, self.channel_ids = {}, {}

    def start(self):
        """Write the header and the opening record, once (the source's header read by now)."""
        if not self.started:
            self.writer.start(profile=self.salvage.profile or 'ros2', library=LIBRARY)
            self.writer.add_metadata(METADATA_RECORD, self.opening)
            if self.provenance:
                self.writer.add_metadata(PROVENANCE_RECORD, self.provenance)
            self.started = True

    def channel(self, channel_id):
        """Map an old channel id to the new file's (started, schema added as needed)."""
        writer, salvage = self.writer, self.salvage
        self.start()
        if channel_id not in self.channel_ids:
            channel = salvage.channels[channel_id]
            schema = salvage.schemas.get(channel.schema_id)
            if schema is not None and schema.id not in self.schema_ids:
                self.schema_ids[schema.id] = writer.register_schema(
                    schema.name, schema.encoding, schema.data)
            self.channel_ids[channel_id] = writer.register_channel(
                channel.topic, channel.message_encoding,
                self.schema_ids.get(channel.schema_id, 0), dict(channel.metadata))
        return self.channel_ids[channel_id]
