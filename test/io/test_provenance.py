"""provenance: what made a recording, written into every file and metadata.yaml, read bounded."""

import hashlib
import json
import pathlib
import struct
import tracemalloc

from flexlink_ros import __version__
from flexlink_ros.io import mcap_records
from flexlink_ros.io.provenance import (MAX_RECORD_BYTES, provenance_entries, PROVENANCE_RECORD,
                                        ProvenanceError, read_provenance)
from flexlink_ros.io.recorder import McapRecorder
from flexlink_ros.ros.parameters import default_model_options
from mcap.reader import make_reader
import pytest
from recorder_helpers import sample_messages, STEP_NS, T0_NS
from rosbags.rosbag2 import Reader
import yaml

SOFT = pathlib.Path(__file__).resolve().parents[1] / 'data' / 'soft_linkage.yaml'


def record(path, entries, count=40, **options):
    with McapRecorder(path, provenance=entries, **options) as recorder:
        for k in range(count):
            for topic, message in sample_messages(k).items():
                recorder.write(topic, message, T0_NS + k * STEP_NS)


def soft_entries():
    options = default_model_options(bearings='rigid')
    return provenance_entries('flexlink_node', str(SOFT), options, 0.05, 'wheel', False)


def test_every_file_and_metadata_yaml_say_what_made_the_bag(tmp_path):
    bag = tmp_path / 'bag'
    record(bag, soft_entries(), split_duration_s=0.01)
    files = sorted(bag.glob('*.mcap'))
    assert len(files) > 2
    text = SOFT.read_bytes()
    for file in files:    # the mcap library's reader: one flexlink_ros record per file
        with open(file, 'rb') as stream:
            records = [m for m in make_reader(stream).iter_metadata()
                       if m.name == PROVENANCE_RECORD]
        assert len(records) == 1
        assert records[0].metadata['mechanism_sha256'] == hashlib.sha256(text).hexdigest()
        assert records[0].metadata['mechanism_yaml'].encode() == text
    with Reader(bag) as reader:   # rosbags still opens the bag (version 9 metadata)
        assert reader.message_count == 40 * len(sample_messages(0))
    custom = yaml.safe_load((bag / 'metadata.yaml').read_text())[
        'rosbag2_bagfile_information']['custom_data']
    assert all(isinstance(v, str) for v in custom.values())   # string -> string, as rosbag2
    assert custom['flexlink_ros.version'] == __version__
    assert custom['flexlink_ros.producer'] == 'flexlink_node'
    assert json.loads(custom['flexlink_ros.model_options'])['bearings'] == 'rigid'
    recorded = read_provenance(bag)
    assert recorded.has_model and recorded.version == __version__
    assert recorded.options() == default_model_options(bearings='rigid')
    assert recorded.mechanism().name == 'soft_test_linkage'
    assert recorded.mechanism().damping_ratio == 0.05     # the model's, not the file's 0.03
    assert (recorded.crank_joint, recorded.warm_start) == ('wheel', False)
    assert recorded.mechanism_file == str(SOFT.resolve())


def test_a_bag_without_the_record_says_nothing_and_a_tool_bag_names_no_model(tmp_path):
    record(tmp_path / 'plain.mcap', None)
    assert read_provenance(tmp_path / 'plain.mcap') is None
    record(tmp_path / 'tool.mcap', provenance_entries('flexlink mcap-record'))
    recorded = read_provenance(tmp_path / 'tool.mcap')
    assert recorded.producer == 'flexlink mcap-record' and not recorded.has_model


def _rewrite_entry(path, key, value):
    """Rewrite one entry of a file's provenance record (same length not needed: a new file)."""
    with open(path, 'rb') as stream:
        reader = make_reader(stream)
        entries = next(m.metadata for m in reader.iter_metadata() if m.name == PROVENANCE_RECORD)
    entries = dict(entries, **{key: value})
    out = path.with_name('edited.mcap')
    record(out, entries)
    return out


@pytest.mark.parametrize('key, value, reason', [
    ('mechanism_yaml', SOFT.read_text().replace('0.20,', '0.21,'), 'does not match its SHA-256'),
    ('model_options', '{"modes": -3}', 'cannot be used'),
    ('damping_ratio', 'lots', 'cannot be used'),
    ('nonlinear', 'maybe', 'cannot be used'),
])
def test_an_altered_record_is_refused_with_one_line(tmp_path, key, value, reason):
    record(tmp_path / 'good.mcap', soft_entries())
    with pytest.raises(ProvenanceError, match=reason) as caught:
        read_provenance(_rewrite_entry(tmp_path / 'good.mcap', key, value))
    assert '\n' not in str(caught.value)


def test_a_recorded_mechanism_the_loader_refuses_is_refused(tmp_path):
    """A text with its true SHA-256 that is no crank-rocker: the mechanism file's own check."""
    text = SOFT.read_text().replace('length_m: 0.05,', 'length_m: 0.5,')
    entries = dict(soft_entries(), mechanism_yaml=text,
                   mechanism_sha256=hashlib.sha256(text.encode()).hexdigest())
    record(tmp_path / 'bad.mcap', entries)
    with pytest.raises(ProvenanceError, match='links.crank|crank') as caught:
        read_provenance(tmp_path / 'bad.mcap')
    assert '\n' not in str(caught.value)


def test_a_1_gb_record_is_refused_without_reading_it(tmp_path):
    """A crafted file declaring a 1 GiB flexlink_ros record (sparse): refused, not copied."""
    name = PROVENANCE_RECORD.encode()
    size = 2 ** 30
    path = tmp_path / 'crafted.mcap'
    header_body = struct.pack('<I', 4) + b'ros2' + struct.pack('<I', 0)
    with open(path, 'wb') as stream:
        stream.write(mcap_records.MCAP_MAGIC)
        stream.write(struct.pack('<BQ', mcap_records.HEADER, len(header_body)) + header_body)
        stream.write(struct.pack('<BQ', 0x0C, size) + struct.pack('<I', len(name)) + name
                     + struct.pack('<I', size - 8 - len(name)))
        stream.truncate(stream.tell() + size - 8 - len(name))   # sparse: costs no disk
    assert path.stat().st_size > size > MAX_RECORD_BYTES
    tracemalloc.start()
    try:
        with pytest.raises(ProvenanceError, match=r'more than the \d+ a provenance record'):
            read_provenance(path)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 10 * 2 ** 20


def test_a_file_that_is_not_mcap_or_is_cut_says_nothing(tmp_path):
    (tmp_path / 'junk.mcap').write_bytes(b'not an mcap file at all')
    assert read_provenance(tmp_path / 'junk.mcap') is None
    record(tmp_path / 'whole.mcap', soft_entries())
    data = (tmp_path / 'whole.mcap').read_bytes()
    cut = tmp_path / 'cut.mcap'
    cut.write_bytes(data[:60])   # inside the rosbag2 record: the walk ends, nothing found
    assert read_provenance(cut) is None
