"""
What rosbag2 stores about a ROS 2 message type, rebuilt from the installed interface packages.

- :func:`message_definition`: the concatenated ``ros2msg`` schema text rosbag2 writes into MCAP
  (the root ``.msg`` text, then for every dependency, depth first, sorted, once each: a line of
  80 ``=``, ``MSG: pkg/Type`` and that type's text), following rosbag2_cpp's
  ``LocalMessageDefinitionSource`` character for character.
- :func:`type_hash`: the ``RIHS01_...`` type-description hash from ``share/<pkg>/msg/<Type>.json``.
- :func:`offered_qos_yaml`: the ``offered_qos_profiles`` channel metadata (rosbag2 metadata
  version 9 spelling: policy names, not numbers).
- :func:`serialize_exact`: CDR bytes identical to what a ``raw=True`` subscription receives.
  ``rclpy.serialization.serialize_message`` returns the rmw's estimated buffer size, which can
  carry trailing uninitialised bytes (an empty ``float64[]`` makes rosbags reject the record);
  here the message's ``SLOT_TYPES`` are walked with XCDR1 alignment (:mod:`.cdr`) and
  alignment padding is zeroed as the DDS payload has it.
"""

import functools
import importlib
import json
import pathlib
import re
import sys

from ament_index_python.packages import get_package_share_directory

from .cdr import serialize_message

ROS2MSG_DELIMITER = '=' * 80 + '\n'
RMW_DURATION_INFINITE = (9223372036, 854775807)  # sec, nsec as rmw reports "infinite"

# rosbag2's MSG_FIELD_TYPE_REGEX and primitive list (local_message_definition_source.cpp).
_MSG_FIELD_TYPE = re.compile(r'(?:^|\n)\s*([a-zA-Z0-9_/]+)(?:\[[^\]]*\])?\s+')
_PRIMITIVE_TYPES = frozenset((
    'bool', 'byte', 'char', 'float32', 'float64', 'int8', 'uint8', 'int16', 'uint16', 'int32',
    'uint32', 'int64', 'uint64', 'string'))


def message_type_name(message):
    """
    Return the ``pkg/msg/Type`` name of a message instance or class.

    Parameters
    ----------
    message : ROS 2 message instance or class
        Of a generated ``<pkg>.msg`` module.

    """
    cls = message if isinstance(message, type) else type(message)
    package = cls.__module__.split('.')[0]
    return f'{package}/msg/{cls.__name__}'


def message_class(type_name):
    """
    Import the Python class of ``pkg/msg/Type`` (``pkg/Type`` is accepted too).

    Parameters
    ----------
    type_name : str
        The type's full name.

    Raises
    ------
    ValueError
        If the name is malformed or the package/type is not installed.

    """
    package, interface, name = _split_type_name(type_name)
    try:
        module = importlib.import_module(f'{package}.{interface}')
        return getattr(module, name)
    except (ImportError, AttributeError):
        raise ValueError(f'`type_name`: message type {type_name!r} is not installed') from None


def _split_type_name(type_name):
    parts = type_name.split('/')
    if len(parts) == 2:
        return parts[0], 'msg', parts[1]
    if len(parts) == 3:
        return parts[0], parts[1], parts[2]
    raise ValueError(f'`type_name`: expected pkg/msg/Type, got {type_name!r}')


@functools.lru_cache(maxsize=None)
def share_directory(package):
    """
    Find the ``share/<package>`` directory of an installed ROS package.

    ament_index first (``AMENT_PREFIX_PATH``); otherwise the prefix the package's Python module
    was installed under (``<prefix>/lib/pythonX.Y/site-packages/<package>`` ->
    ``<prefix>/share/<package>``), which is where the PyPI wheels put their ``.msg`` files.

    Parameters
    ----------
    package : str
        The ROS package's name.

    Raises
    ------
    ValueError
        If no share directory is found.

    """
    try:
        return pathlib.Path(get_package_share_directory(package))
    except (LookupError, ValueError, OSError):  # OSError: AMENT_PREFIX_PATH unset
        pass
    candidates = [pathlib.Path(sys.prefix) / 'share' / package]
    try:
        module = importlib.import_module(package)
        module_dir = pathlib.Path(module.__file__).resolve().parent
        candidates.insert(0, module_dir.parents[3] / 'share' / package)
    except (ImportError, AttributeError, TypeError, IndexError):
        pass
    for candidate in candidates:
        if candidate.is_dir():
            return candidate
    raise ValueError(f'`package`: share directory of {package!r} not found')


@functools.lru_cache(maxsize=None)
def _interface_text(package, interface, name, extension):
    path = share_directory(package) / interface / f'{name}.{extension}'
    try:
        return path.read_text(encoding='utf-8')
    except OSError:
        raise ValueError(f'`type_name`: {path} not found') from None


def _msg_dependencies(text, package):
    """Sorted dependency names exactly as rosbag2 parses them from .msg text."""
    dependencies = set()
    for match in _MSG_FIELD_TYPE.finditer(text):
        name = match.group(1)
        if name in _PRIMITIVE_TYPES:
            continue
        dependencies.add(name if '/' in name else f'{package}/{name}')
    return sorted(dependencies)


@functools.lru_cache(maxsize=None)
def message_definition(type_name):
    """
    Return the full ``ros2msg`` definition rosbag2 stores as the MCAP schema of ``type_name``.

    Parameters
    ----------
    type_name : str
        ``pkg/msg/Type``.

    Returns
    -------
    str

    """
    seen = set()

    def append_recursive(name, depth):
        if depth <= 0:
            raise ValueError(f'`type_name`: definition of {type_name!r} nests too deep')
        package, interface, short = _split_type_name(name)
        text = _interface_text(package, interface, short, 'msg')
        result = text
        for dependency in _msg_dependencies(text, package):
            if dependency not in seen:
                seen.add(dependency)
                result += '\n' + ROS2MSG_DELIMITER + f'MSG: {dependency}\n'
                result += append_recursive(dependency, depth - 1)
        return result

    return append_recursive(type_name, 50)


@functools.lru_cache(maxsize=None)
def type_hash(type_name):
    """
    Return the ``RIHS01_<sha256>`` type-description hash of ``pkg/msg/Type``, '' if absent.

    Parameters
    ----------
    type_name : str
        The type's full name.

    """
    package, interface, name = _split_type_name(type_name)
    try:
        description = json.loads(_interface_text(package, interface, name, 'json'))
    except ValueError:
        return ''
    full_name = f'{package}/{interface}/{name}'
    for entry in description.get('type_hashes', ()):
        if entry.get('type_name') == full_name:
            return entry['hash_string']
    return ''


def _policy_name(value):
    name = getattr(value, 'name', None)
    if name is None:
        return str(value).lower()
    return name.lower()


def _duration_dict(duration):
    nanoseconds = int(getattr(duration, 'nanoseconds', duration))
    if nanoseconds <= 0 or nanoseconds >= 2 ** 63 - 1:
        sec, nsec = RMW_DURATION_INFINITE
    else:
        sec, nsec = divmod(nanoseconds, 1_000_000_000)
    return {'sec': sec, 'nsec': nsec}


def qos_profile_dict(profile):
    """
    One QoS profile as rosbag2 (metadata version 9) serialises it.

    Parameters
    ----------
    profile : rclpy.qos.QoSProfile
        E.g. a publisher's ``qos_profile`` or an entry of ``get_publishers_info_by_topic``.
        Unspecified durations (0) are written as rmw's infinite duration, as the rmw reports
        them for an offered profile.

    Returns
    -------
    dict

    """
    return {
        'history': _policy_name(profile.history),
        'depth': int(profile.depth),
        'reliability': _policy_name(profile.reliability),
        'durability': _policy_name(profile.durability),
        'deadline': _duration_dict(profile.deadline),
        'lifespan': _duration_dict(profile.lifespan),
        'liveliness': _policy_name(profile.liveliness),
        'liveliness_lease_duration': _duration_dict(profile.liveliness_lease_duration),
        'avoid_ros_namespace_conventions': bool(profile.avoid_ros_namespace_conventions),
    }


def offered_qos_yaml(profiles):
    """
    Write the ``offered_qos_profiles`` text of MCAP channel metadata as rosbag2 does (yaml-cpp).

    Parameters
    ----------
    profiles : sequence of rclpy.qos.QoSProfile or dict
        Dicts as returned by :func:`qos_profile_dict` pass through.

    Returns
    -------
    str

    """
    lines = []
    for profile in profiles:
        entry = profile if isinstance(profile, dict) else qos_profile_dict(profile)
        first = True
        for key, value in entry.items():
            prefix = '- ' if first else '  '
            first = False
            if isinstance(value, dict):
                lines.append(f'{prefix}{key}:')
                lines.extend(f'    {k}: {v}' for k, v in value.items())
            elif isinstance(value, bool):
                lines.append(f'{prefix}{key}: {"true" if value else "false"}')
            else:
                lines.append(f'{prefix}{key}: {value}')
    return '\n'.join(lines) if lines else '[]'


def serialize_exact(message):
    """
    Return the CDR bytes of a message, exactly as long as the DDS payload, zeroed padding.

    The bytes of a ``raw=True`` subscription, padding zeroed; rclpy's ``serialize_message``
    gives the same bytes up to its estimated buffer size (trailing bytes that make rosbags
    reject an empty ``float64[]``) and uninitialised padding (tested). Written by the one CDR
    walker (:func:`flexlink_ros.io.cdr.serialize_message`), without importing rclpy.

    Parameters
    ----------
    message : ROS 2 message instance
        Of a type without ``wstring`` fields.

    Returns
    -------
    bytes

    """
    return serialize_message(message)
