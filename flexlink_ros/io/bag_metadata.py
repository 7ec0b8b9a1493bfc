"""
The ``metadata.yaml`` of a rosbag2 bag directory (version 9), as ``ros2 bag record`` writes it.

``ros2 bag play DIR``, ``ros2 bag info DIR`` and ``rosbags`` read a bag directory through it:
the files in order, their time spans and message counts, and every topic with its type, QoS
offered by its publishers and type-description hash.
"""

import os
import pathlib

import yaml

from .msg_schema import type_hash
from .recorder_files import create_exclusive

ROSBAG2_METADATA_VERSION = 9  # rosbag2 metadata.yaml version written (QoS policies as names)
ROS_DISTRO = 'kilted'
METADATA_RECORD = 'rosbag2'   # name of the MCAP Metadata record rosbag2 writes
UNSET_NS = 2 ** 63 - 1   # rosbag2's starting time before the first message (nanoseconds::max)
DEFAULT_QOS = {
    'history': 'keep_last', 'depth': 10, 'reliability': 'reliable', 'durability': 'volatile',
    'deadline': {'sec': 9223372036, 'nsec': 854775807},
    'lifespan': {'sec': 9223372036, 'nsec': 854775807},
    'liveliness': 'automatic',
    'liveliness_lease_duration': {'sec': 9223372036, 'nsec': 854775807},
    'avoid_ros_namespace_conventions': False,
}


# libyaml's emitter where PyYAML was built with it (its wheels are): 7x faster than the pure
# Python one (8 -> 1.1 ms for a replay's metadata, written when the file opens and closes).
_SAFE_DUMPER = getattr(yaml, 'CSafeDumper', yaml.SafeDumper)


class _PlainDumper(_SAFE_DUMPER):
    """YAML without anchors/aliases (shared QoS dicts are written out each time)."""

    def ignore_aliases(self, data):
        """Write every object out, never as an alias of an earlier one."""
        return True


def _since_epoch(nanoseconds):
    return {'nanoseconds_since_epoch': int(nanoseconds)}


def bag_metadata(files, topics, no_message_ns=0, counts=None, custom_data=None):
    """
    Return the rosbag2 (version 9) bag information of MCAP files and their topics.

    Keys in the order rosbag2's ``YAML::convert<BagMetadata>::encode`` writes them.

    Parameters
    ----------
    files : list of dict
        Per file: ``path``, ``message_count``, ``first_log_ns``, ``last_log_ns``.
    topics : dict
        Topic name -> object with ``name``, ``type_name``, ``qos_profiles``, ``message_count``
        (and optionally ``type_hash``, else the installed type's).
    no_message_ns : int
        Starting time written while there is no message (rosbag2 writes ``UNSET_NS`` in the
        record at open; ``metadata.yaml`` of an empty bag here says 0).
    counts : dict, optional
        Topic name -> message count to write instead of each topic's ``message_count``
        (a topic not in it: 0), for a record that describes one file.
    custom_data : dict, optional
        str -> str entries of ``custom_data`` (what made the bag, :mod:`.provenance`).

    Returns
    -------
    dict

    """
    starts = [f['first_log_ns'] for f in files if f['first_log_ns'] is not None]
    ends = [f['last_log_ns'] for f in files if f['last_log_ns'] is not None]
    start = min(starts) if starts else no_message_ns
    duration = max(ends) - start if ends else 0
    return {
        'version': ROSBAG2_METADATA_VERSION,
        'storage_identifier': 'mcap',
        'duration': {'nanoseconds': duration},
        'starting_time': _since_epoch(start),
        'message_count': sum(f['message_count'] for f in files),
        'topics_with_message_count': [
            {'topic_metadata': {'name': t.name, 'type': t.type_name,
                                'serialization_format': 'cdr',
                                'offered_qos_profiles': list(t.qos_profiles),
                                'type_description_hash': (getattr(t, 'type_hash', None)
                                                          or type_hash(t.type_name))},
             'message_count': (t.message_count if counts is None
                               else counts.get(t.name, 0))}
            for t in topics.values()],
        'compression_format': '',
        'compression_mode': '',
        'relative_file_paths': [pathlib.Path(f['path']).name for f in files],
        'files': [
            {'path': pathlib.Path(f['path']).name,
             'starting_time': _since_epoch(_or(f['first_log_ns'], no_message_ns)),
             'duration': {'nanoseconds': _or(f['last_log_ns'], 0) - _or(f['first_log_ns'], 0)},
             'message_count': f['message_count']}
            for f in files],
        'custom_data': dict(custom_data or {}),
        'ros_distro': ROS_DISTRO,
    }


def _or(value, default):
    return default if value is None else value


def serialized_metadata(files, topics, no_message_ns=0, counts=None, custom_data=None):
    """
    Return the ``rosbag2`` MCAP Metadata record's map, as rosbag2's MCAP storage writes it.

    rosbag2 (``MCAPStorage::update_metadata``) writes a Metadata record named ``rosbag2`` with
    one key, ``serialized_metadata``: the YAML of the bag information (no
    ``rosbag2_bagfile_information`` wrapper), once when a file is opened and again before it is
    closed. Arguments as :func:`bag_metadata`. The recorder and reindex give it one file
    (and that file's counts), so a split costs the same whatever the files before it: rosbag2
    replaces the file list by the file itself when it reads one file anyway.

    Returns
    -------
    dict
        ``{'serialized_metadata': yaml_text}``.

    """
    text = yaml.dump(bag_metadata(files, topics, no_message_ns, counts, custom_data),
                     Dumper=_PlainDumper,
                     sort_keys=False)
    return {'serialized_metadata': text}


def write_bag_metadata(bag_dir, files, topics, custom_data=None):
    """
    Write a rosbag2 (version 9) ``metadata.yaml`` for MCAP files in a bag directory.

    Parameters
    ----------
    bag_dir : pathlib.Path
        The bag directory.
    files : list of dict
        Per file: ``path``, ``message_count``, ``first_log_ns``, ``last_log_ns``.
    topics : dict
        Topic name -> object with ``name``, ``type_name``, ``qos_profiles``, ``message_count``.
    custom_data : dict, optional
        str -> str entries of ``custom_data``.

    """
    metadata = bag_metadata(files, topics, custom_data=custom_data)
    bag_dir = pathlib.Path(bag_dir)
    temporary = bag_dir / 'metadata.yaml.tmp'
    text = yaml.dump({'rosbag2_bagfile_information': metadata}, Dumper=_PlainDumper,
                     sort_keys=False)
    if os.path.lexists(temporary):   # left by an earlier close that failed half-way
        os.unlink(temporary)
    with create_exclusive(temporary) as stream:
        stream.write(text.encode('utf-8'))
    temporary.replace(bag_dir / 'metadata.yaml')   # replaces a link itself, never its target
