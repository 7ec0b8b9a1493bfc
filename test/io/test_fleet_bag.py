"""One bag of a fleet recomputed without Ray: its rows, its skipped messages, its failures."""

import math

from fleet_bags import bad_messages, crank_stream, write_bag
from flexlink_ros.core.estimation.offline import estimate_offline
from flexlink_ros.core.mechanism_file import load_mechanism
from flexlink_ros.core.reduction import mechanism_model
from flexlink_ros.io.fleet_bag import FleetSettings, recompute_bag
from flexlink_ros.io.joint_states import read_crank_samples
from flexlink_ros.ros import parameters as node_params
import numpy as np
import pytest
from rosbags.highlevel import AnyReader


@pytest.fixture(scope='module')
def options():
    return node_params.default_model_options(geometric_stiffness=False)


def test_rows_hold_each_revolution_and_its_skipped_messages(tmp_path, options):
    stamps, angles, speeds = crank_stream(1.5, 391.0, gap_at=1.0)
    bad_rows = [5, 400, 401, 1200]
    bag = tmp_path / 'bag'
    write_bag(bag, stamps, angles, speeds, bad_messages(stamps, bad_rows))
    result = recompute_bag(str(bag), ('cho1992', options), FleetSettings())
    summary, rows = result['summary'], result['rows']
    assert summary['error'] is None and summary['samples'] == stamps.size
    assert summary['skipped'] == 4 and summary['segments'] == 2
    assert sum(row['skipped'] for row in rows) == 4
    reasons = {}
    for row in rows:
        for why, n in row['skipped_reasons'].items():
            reasons[why] = reasons.get(why, 0) + n
    assert reasons == summary['skipped_reasons'] and len(reasons) == 3
    # Each bad message is in the row of the samples logged before it.
    for row_index in bad_rows:
        stamp = int(stamps[row_index])
        owner = [r for r in rows if r['start_stamp_ns'] <= stamp <= r['end_stamp_ns']]
        assert len(owner) == 1 and owner[0]['skipped'] >= 1
    # Rows are revolutions, restarted at the gap; they cover every sample once.
    assert [r['index'] for r in rows] == list(range(len(rows)))
    assert sum(r['samples'] for r in rows) == stamps.size
    after_gap = [r for r in rows if r['start_stamp_ns'] == int(stamps[1000])]
    assert len(after_gap) == 1
    # 391 rpm: 6.5 turns a second, so 1 s + 0.5 s make 7 + 4 rows give or take a partial one.
    assert 9 <= len(rows) <= 13


def test_the_numbers_are_the_offline_estimate_s(tmp_path, options):
    stamps, angles, speeds = crank_stream(1.0, 300.0)
    bag = tmp_path / 'one.mcap'
    write_bag(bag, stamps, angles, speeds)
    out = tmp_path / 'out.mcap'
    result = recompute_bag(str(bag), ('cho1992', options),
                           FleetSettings(per='minute', nonlinear='off'), output=str(out))
    assert result['summary']['model_choice'] == {
        'nonlinear': False, 'why': 'asked for (--nonlinear off)', 'asked': 'off'}
    model = mechanism_model.model_for_mechanism(load_mechanism('cho1992'), options)
    samples = read_crank_samples(bag, '/joint_states', 'crank')
    estimate = estimate_offline(model, samples['stamps_ns'], samples['angles'],
                                samples['speeds'])
    (row,) = result['rows']
    for axis, name in enumerate(('lever_tip_dx', 'lever_tip_dy')):
        values = estimate['lever_tip'][:, axis]
        assert row[f'{name}_p2p_um'] == pytest.approx(1e6 * (values.max() - values.min()),
                                                      rel=1e-12)
    worst = int(np.argmax(estimate['criterion'][:, 1]))
    assert row['criterion_max_A'] == estimate['criterion'][worst, 1]
    assert row['criterion_angle_A_rad'] == pytest.approx(
        math.fmod(estimate['crank_angle'][worst], 2 * math.pi))
    assert result['summary']['output'] == str(out)
    # The written MCAP, read by an independent reader: one deflection per sample.
    with AnyReader([out]) as reader:
        counts = {c.topic: c.msgcount for c in reader.connections}
    assert counts['/flexlink_node/lever_tip/deflection'] == stamps.size


def test_a_bag_that_fails_is_a_row_with_its_reason(tmp_path, options):
    stamps, angles, speeds = crank_stream(0.2, 391.0)
    good = tmp_path / 'good'
    write_bag(good, stamps, angles, speeds)
    corrupt = tmp_path / 'corrupt.mcap'
    corrupt.write_bytes(bytes(range(256)) * 4)
    empty = tmp_path / 'empty.mcap'
    write_bag(empty, stamps[:0], angles[:0], speeds[:0])
    cases = {str(good): None, str(corrupt): ('cho1992', options),
             str(empty): ('cho1992', options), str(tmp_path / 'missing'): ('cho1992', options)}
    reasons = {}
    for bag, fallback in cases.items():
        result = recompute_bag(bag, fallback, FleetSettings())
        (row,) = result['rows']
        assert row['index'] == -1 and row['error'] == result['summary']['error']
        reasons[bag] = row['error']
    assert 'has no recorded mechanism: give `--mechanism`' in reasons[str(good)]
    assert 'corrupt.mcap is not an MCAP file' in reasons[str(corrupt)]
    assert 'no sensor_msgs/msg/JointState topic' in reasons[str(empty)]
    assert 'no such file or directory' in reasons[str(tmp_path / 'missing')]


def test_a_bag_that_names_its_model_is_recomputed_with_it(tmp_path):
    """The recording's own mechanism and options come first; --mechanism only for the rest."""
    from flexlink_ros.io.fleet_bag import bag_model
    from flexlink_ros.io.provenance import provenance_entries
    from flexlink_ros.io.recorder import McapRecorder
    from sensor_msgs.msg import JointState
    made = node_params.default_model_options(bearings='rigid', grid_size=48)
    path = tmp_path / 'named.mcap'
    with McapRecorder(path, provenance=provenance_entries('flexlink_node', 'kang1990',
                                                          made)) as recorder:
        recorder.write('/joint_states', JointState(name=['crank'], position=[0.0]), 10**9)
    fallback = ('cho1992', node_params.default_model_options())
    mechanism, options, source, nonlinear = bag_model(str(path), fallback)
    assert (mechanism.name, options, nonlinear) == ('kang1990', made, 'off')
    assert source.startswith('recorded')
    plain = tmp_path / 'plain.mcap'
    with McapRecorder(plain) as recorder:
        recorder.write('/joint_states', JointState(name=['crank'], position=[0.0]), 10**9)
    mechanism, options, source, nonlinear = bag_model(str(plain), fallback)
    assert (mechanism.name, source, nonlinear) == ('cho1992', '--mechanism cho1992', None)
    with pytest.raises(ValueError, match='give `--mechanism`'):
        bag_model(str(plain), None)
