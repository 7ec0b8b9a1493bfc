"""
What made a recording: the mechanism file, model options and version a bag carries.

The node, ``flexlink replay --out`` and ``flexlink mcap-record`` write one MCAP Metadata record
named ``flexlink_ros`` into every file of a recording (after rosbag2's own ``rosbag2`` record)
and the same entries, keys prefixed ``flexlink_ros.``, into ``metadata.yaml``'s
``custom_data`` (the string-to-string map rosbag2 keeps for its recorder's user). The entries:

- ``producer``, ``version``: the program that wrote the recording and the package version;
- ``mechanism_file``, ``mechanism_sha256``, ``mechanism_yaml``: the mechanism file as the
  model was built from it (its path as resolved, the SHA-256 of its bytes, its text);
- ``damping_ratio``: the modal damping ratio the model used (the node's parameter may replace
  the file's), ``model_options``: the resolved :class:`core.options.ModelOptions` as JSON;
- ``crank_joint``, ``warm_start``: what the estimator read and how it started;
- ``nonlinear``: ``on`` when the deflections are the reduced nonlinear model's, ``off`` when
  the linear model's (absent in recordings made before the nonlinear model existed).

``mcap-record`` writes only the first two: such a bag says what wrote it, not a model.

Reading is bounded (:func:`read_provenance`): only the first file's top-level records are
walked (no chunk is decompressed), a record larger than :data:`MAX_RECORD_BYTES` is refused
before a byte of it is copied, and the recorded mechanism text goes through the mechanism
file's own loader (its size bound, YAML restrictions and checks) with its SHA-256 verified.
"""

import dataclasses
import hashlib
import json
import struct

from .mcap_reader import map_file
from .mcap_records import FOOTER, MCAP_MAGIC, read_strings, records_in
from .recording import recording_files
from .. import __version__
from ..core.mechanism_file import (find_config, load_mechanism, MAX_FILE_BYTES,
                                   stiffness_damping_from_file)
from ..core.options import ModelOptions
from ..errors import DamagedRecord, FlexlinkError, McapFileError

PROVENANCE_RECORD = 'flexlink_ros'   # name of the MCAP Metadata record
CUSTOM_DATA_PREFIX = 'flexlink_ros.'   # of its keys in metadata.yaml's custom_data
PROVENANCE_FORMAT = '1'
# The mechanism text is at most MAX_FILE_BYTES; the other entries are a few hundred bytes.
MAX_RECORD_BYTES = 2 * MAX_FILE_BYTES + 16 * 1024
METADATA = 0x0C
MAX_RECORDS_WALKED = 100_000   # top-level records looked at (chunks are skipped by length)
_NAME = PROVENANCE_RECORD.encode()


class ProvenanceError(FlexlinkError):
    """A recording's provenance record is there but cannot be used (says why in one line)."""


@dataclasses.dataclass(frozen=True)
class Provenance:
    """What a recording says made it (:func:`read_provenance`)."""

    producer: str
    version: str
    mechanism_file: str = ''
    mechanism_sha256: str = ''
    mechanism_yaml: str = ''
    damping_ratio: float = None
    model_options: dict = None
    crank_joint: str = ''
    warm_start: bool = True
    nonlinear: str = ''

    @property
    def has_model(self):
        """Whether the recording names the mechanism and model its estimates came from."""
        return bool(self.mechanism_yaml) and self.model_options is not None

    def mechanism(self):
        """Return the recorded Mechanism (its damping ratio the one the model used)."""
        mechanism = load_mechanism(self._where(), raw=self.mechanism_yaml.encode('utf-8'))
        return dataclasses.replace(mechanism, damping_ratio=self.damping_ratio)

    def options(self):
        """Return the recorded :class:`ModelOptions`."""
        return ModelOptions(**self.model_options)

    def _where(self):
        return f'the recorded mechanism file ({self.mechanism_file})'

    def summary(self):
        """One line per fact, for ``mcap-info`` and replay's notes."""
        lines = [f'made by {self.producer} {self.version}']
        if self.has_model:
            lines.append(f'mechanism {self.mechanism_file} (sha256 {self.mechanism_sha256[:12]}'
                         f', damping ratio {self.damping_ratio:g})')
            lines.append('model ' + ', '.join(f'{k}={v}' for k, v in self.model_options.items()))
            if self.nonlinear:
                lines.append(f'nonlinear model {self.nonlinear}')
        return lines


def mechanism_bytes(path_or_name):
    """
    Return (resolved path, bytes) of a mechanism file, read with the loader's size bound.

    Parameters
    ----------
    path_or_name : str
        A path or a bare name ('cho1992'), as the node's ``mechanism`` parameter.

    """
    path = find_config(str(path_or_name))
    with open(path, 'rb') as stream:
        raw = stream.read(MAX_FILE_BYTES + 1)
    load_mechanism(path, raw=raw)   # the loader's bound and checks, on these very bytes
    return path.resolve(), raw


def provenance_entries(producer, mechanism=None, options=None, damping_ratio=None,
                       crank_joint='crank', warm_start=True, raw=None):
    """
    Return the provenance map (str -> str) a recording carries.

    Parameters
    ----------
    producer : str
        What writes the recording ('flexlink_node', 'flexlink replay', ...).
    mechanism : str, optional
        The mechanism file (path or bare name) the model was built from; None: no model.
    options : ModelOptions, optional
        The model's resolved options (with ``mechanism``).
    damping_ratio : float, optional
        The modal damping ratio the model used (default: the file's).
    crank_joint : str
        The crank joint's name in the input.
    warm_start : bool
        Whether the estimator starts from the periodic steady state.
    raw : bytes, optional
        The mechanism file's bytes when they come from a recording (``mechanism`` then is the
        path it was recorded under).

    """
    entries = {'format': PROVENANCE_FORMAT, 'producer': producer, 'version': __version__}
    if mechanism is None:
        return entries
    if raw is None:
        path, raw = mechanism_bytes(mechanism)
    else:
        path = mechanism
    if damping_ratio is None:
        damping_ratio = load_mechanism(path, raw=raw).damping_ratio
    entries.update(mechanism_file=str(path), mechanism_sha256=hashlib.sha256(raw).hexdigest(),
                   mechanism_yaml=raw.decode('utf-8'), damping_ratio=repr(float(damping_ratio)),
                   model_options=json.dumps(dataclasses.asdict(options)),
                   crank_joint=str(crank_joint), warm_start=str(bool(warm_start)).lower())
    return entries


def custom_data(entries):
    """Return the entries as ``metadata.yaml``'s ``custom_data`` keys (``flexlink_ros.<key>``)."""
    return {CUSTOM_DATA_PREFIX + key: value for key, value in (entries or {}).items()}


def read_provenance(path):
    """
    Read what a recording says made it, bounded; None if it says nothing.

    Parameters
    ----------
    path : str or os.PathLike
        ``.mcap`` file or bag directory.

    Returns
    -------
    Provenance or None
        None for a recording without the record (``ros2 bag record``, an older version).

    Raises
    ------
    ProvenanceError
        The record is larger than :data:`MAX_RECORD_BYTES`, malformed, or its mechanism text
        fails its SHA-256 or the mechanism file's checks.

    """
    entries = read_entries(path)
    return None if entries is None else provenance_from_entries(entries, path)


def read_entries(path):
    """
    Return the undecoded entries of a recording's first ``flexlink_ros`` record, or None.

    Bounded as :func:`read_provenance` (whose refusals it raises), not otherwise checked:
    what ``reindex`` carries into a rebuilt ``metadata.yaml``.
    """
    first = recording_files(path)[0]
    try:
        buffer = map_file(first)
    except McapFileError:
        return None
    try:
        return _find_record(buffer, first)
    finally:
        buffer.close()


def _find_record(buffer, file):
    """Return the entries of the file's ``flexlink_ros`` Metadata record, or None; bounded."""
    try:
        for walked, (code, body, end) in enumerate(records_in(buffer, len(MCAP_MAGIC),
                                                              len(buffer))):
            if code == FOOTER or walked >= MAX_RECORDS_WALKED:
                return None
            if code != METADATA or end - body < 4 + len(_NAME):
                continue
            (length,) = struct.unpack_from('<I', buffer, body)
            if length != len(_NAME) or buffer[body + 4:body + 4 + length] != _NAME:
                continue
            if end - body > MAX_RECORD_BYTES:
                raise ProvenanceError(f'{file}: the {PROVENANCE_RECORD} record has {end - body} '
                                      f'bytes, more than the {MAX_RECORD_BYTES} a provenance '
                                      'record can have: not read')
            return _metadata_map(buffer, body + 4 + length, end, file)
    except DamagedRecord:   # a cut or damaged file: what was walked held no record
        return None
    return None


def _metadata_map(buffer, offset, end, file):
    """Decode a Metadata record's map<string, string> from ``offset`` (checked lengths)."""
    try:
        if offset + 4 > end:
            raise DamagedRecord('map length cut')
        (size,) = struct.unpack_from('<I', buffer, offset)
        offset += 4
        stop = offset + size
        if stop > end:
            raise DamagedRecord(f'map of {size} bytes overruns its record')
        entries = {}
        while offset < stop:
            (key, value), offset = read_strings(buffer, offset, stop, 2)
            entries[key] = value
        return entries
    except DamagedRecord as exc:
        raise ProvenanceError(f'{file}: damaged {PROVENANCE_RECORD} record: {exc}') from None


def provenance_from_entries(entries, where='recording'):
    """
    Check and decode a provenance map (the MCAP record's, or ``custom_data`` unprefixed).

    Raises
    ------
    ProvenanceError
        A wrong SHA-256, a mechanism text the loader refuses, options that do not parse.

    """
    try:
        record = Provenance(producer=entries.get('producer', '?'),
                            version=entries.get('version', '?'))
        if 'mechanism_yaml' not in entries:
            return record
        text = entries['mechanism_yaml']
        digest = hashlib.sha256(text.encode('utf-8')).hexdigest()
        if digest != entries.get('mechanism_sha256'):
            raise ProvenanceError('the recorded mechanism text does not match its SHA-256')
        record = dataclasses.replace(
            record, mechanism_file=entries.get('mechanism_file', ''), mechanism_sha256=digest,
            mechanism_yaml=text, damping_ratio=float(entries['damping_ratio']),
            model_options=json.loads(entries['model_options']),
            crank_joint=entries.get('crank_joint', 'crank'),
            warm_start=entries.get('warm_start', 'true') == 'true',
            nonlinear=entries.get('nonlinear', ''))
        if record.nonlinear not in ('', 'on', 'off'):
            raise ValueError(f'nonlinear {record.nonlinear[:20]!r} is not on or off')
        record.options()
        mechanism = record.mechanism()
        stiffness_damping_from_file(record._where(), raw=text.encode('utf-8'))
        if not 0.0 <= mechanism.damping_ratio <= 1.0:
            raise ValueError(f'damping ratio {mechanism.damping_ratio} outside 0..1')
    except ProvenanceError as exc:
        raise ProvenanceError(f'{where}: {exc}') from None
    except (FlexlinkError, KeyError, TypeError, ValueError) as exc:
        raise ProvenanceError(f'{where}: the recorded model cannot be used: '
                              f'{type(exc).__name__}: {exc}'[:300]) from None
    return record
