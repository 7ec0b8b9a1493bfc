"""replay_writer: the input and its recomputed outputs interleaved per sample in a bag."""

import dataclasses
import pathlib
import tempfile

from flexlink_ros.core.mechanism_file import load_mechanism
from flexlink_ros.core.options import ModelOptions
from flexlink_ros.core.reduction.mechanism_model import model_for_mechanism
from flexlink_ros.core.reduction.second_order_tables import SecondOrderForms
from flexlink_ros.io.msg_schema import serialize_exact
from flexlink_ros.io.output_cdr import criteria_cdr, quality_cdr, vector3_stamped_cdr
from flexlink_ros.io.recorder import McapRecorder
from flexlink_ros.io.replay_writer import MarkerSource, OUTPUT_CHUNK_BYTES, \
    OUTPUT_FLUSH_PERIOD_S, OUTPUT_ZSTD_LEVEL, PartWriter, replay_topics, write_replay, \
    write_rows
from flexlink_ros.names import JOINT_NAMES, output_topics, QUALITY_NAMES
from flexlink_ros.ros import messages as ros_messages
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
import numpy as np
from rclpy.serialization import deserialize_message
from recorder_helpers import STEP_NS, T0_NS
from rosbags.highlevel import AnyReader
from sensor_msgs.msg import JointState
from visualization_msgs.msg import MarkerArray

COUNT = 6
OUTLIER = 2     # its estimate is NaN: the input is kept, no outputs


def random_rows(rng, stamps, data):
    """Return the samples of input ``data`` at ``stamps`` and a random estimate of outputs."""
    count = len(data)
    samples = {'data': data, 'stamps_ns': stamps, 'log_ns': stamps + 50_000,
               'publish_ns': stamps + 20_000}
    estimate = {key: rng.normal(size=(count, 2)) for key in ('lever_tip', 'coupler_mid')}
    estimate.update({key: rng.normal(size=(count, 4))
                     for key in ('criterion', 'gamma_dot', 'reaction_n')})
    estimate['error_indicator'] = rng.uniform(0.0, 0.1, count)
    estimate['nonlinearity'] = rng.uniform(0.0, 0.5, count)
    return samples, estimate


def replay_inputs():
    rng = np.random.default_rng(5)
    stamps = T0_NS + STEP_NS * np.arange(COUNT)
    data = []
    for k, stamp in enumerate(stamps.tolist()):
        message = JointState(name=['crank'], position=[0.1 * k], velocity=[40.0])
        message.header.stamp = ros_messages.ns_to_stamp(stamp)
        data.append(serialize_exact(message))
    samples, estimate = random_rows(rng, stamps, data)
    estimate['nonlinearity'][1] = np.nan      # not available: written as NaN, as the node
    estimate['lever_tip'][OUTLIER] = np.nan
    return samples, estimate


def test_replay_bag_holds_each_input_then_its_outputs(tmp_path):
    samples, estimate = replay_inputs()
    topics = output_topics('/flexlink_node')
    progress = []
    status = write_replay(tmp_path / 'replay', [(0, samples, estimate)], '/joint_states', topics,
                          'linkage_ground', None, markers_every_n=0,
                          progress=lambda n, force=False: progress.append((n, force)))
    assert status['state'] == 'closed' and status['message_count'] == 1 + 5 * (COUNT - 1)
    assert progress == [(COUNT, False), (COUNT, True)]
    with open(status['files'][0], 'rb') as stream:
        decoded = [(channel.topic, message, msg) for _, channel, message, msg in make_reader(
            stream, decoder_factories=[DecoderFactory()]).iter_decoded_messages(
                log_time_order=False)]
    order = [topic for topic, _, _ in decoded]
    per_sample = ['/joint_states', topics['lever_tip'], topics['coupler_mid'], topics['criteria'],
                  topics['quality']]
    assert order == per_sample * OUTLIER + ['/joint_states'] + \
        per_sample * (COUNT - OUTLIER - 1)
    rows = iter(k for k in range(COUNT) for _ in range(1 if k == OUTLIER else 5))
    for (topic, message, msg), k in zip(decoded, rows):
        assert message.log_time == samples['log_ns'][k]
        stamp = msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec
        assert stamp == samples['stamps_ns'][k]
        if topic == '/joint_states':
            assert message.publish_time == samples['publish_ns'][k]
            assert list(msg.position) == [0.1 * k]
            continue
        assert message.publish_time == message.log_time and msg.header.frame_id == 'linkage_ground'
        if topic == topics['quality']:
            assert list(msg.name) == list(QUALITY_NAMES) and not msg.velocity and not msg.effort
            np.testing.assert_array_equal(
                msg.position, [estimate['error_indicator'][k], estimate['nonlinearity'][k]])
        elif topic == topics['criteria']:
            assert list(msg.name) == list(JOINT_NAMES)
            assert list(msg.position) == estimate['criterion'][k].tolist()
            assert list(msg.velocity) == estimate['gamma_dot'][k].tolist()
            assert list(msg.effort) == estimate['reaction_n'][k].tolist()
        else:
            point = 'lever_tip' if topic == topics['lever_tip'] else 'coupler_mid'
            assert [msg.vector.x, msg.vector.y, msg.vector.z] == \
                estimate[point][k].tolist() + [0.0]
    with AnyReader([tmp_path / 'replay']) as reader:
        assert {c.topic: c.msgcount for c in reader.connections} == {
            '/joint_states': COUNT, topics['lever_tip']: COUNT - 1,
            topics['coupler_mid']: COUNT - 1, topics['criteria']: COUNT - 1,
            topics['quality']: COUNT - 1}


def rows_of(samples, estimate, rows):
    """Cut the samples and the estimate to ``rows`` (a slice)."""
    return ({key: value[rows] for key, value in samples.items()},
            {key: value[rows] for key, value in estimate.items()})


def test_a_part_written_elsewhere_and_appended_gives_the_bag_of_one_writer(tmp_path):
    """Sequence numbers go on, the summary and metadata.yaml count the appended messages."""
    samples, estimate = replay_inputs()
    topics = output_topics('/flexlink_node')
    whole = write_replay(tmp_path / 'whole', [(0, samples, estimate)], '/joint_states', topics,
                         'linkage_ground', None, markers_every_n=0)
    declared = replay_topics('/joint_states', topics, 0)
    split = OUTLIER + 2     # the first part holds the outlier: one input without outputs
    written = {name: split - (name != '/joint_states') for name, _ in declared}
    with tempfile.TemporaryFile(dir=tmp_path) as stream:
        part = PartWriter(stream, declared, written, tmp_path)
        write_rows(part, [(split, *rows_of(samples, estimate, slice(split, None)))], declared,
                   'linkage_ground', None, markers_every_n=0)
        part.finish()
        stream.seek(0)

        def tail(recorder):
            return recorder.append_part(stream)
        first = rows_of(samples, estimate, slice(0, split))
        status = write_replay(tmp_path / 'parts', [(0, *first)], '/joint_states', topics,
                              'linkage_ground', None, markers_every_n=0, tail=tail)
    assert status['message_count'] == whole['message_count'] == 1 + 5 * (COUNT - 1)
    assert status['topics'] == whole['topics']
    read = []
    for path in (whole['files'][0], status['files'][0]):
        with open(path, 'rb') as stream:
            reader = make_reader(stream)
            summary = reader.get_summary()
            read.append([(c.topic, m.log_time, m.publish_time, m.sequence, bytes(m.data))
                         for _, c, m in reader.iter_messages(log_time_order=True)])
            assert summary.statistics.message_count == len(read[-1])
    assert read[0] == read[1] and summary.statistics.chunk_count == 2
    with AnyReader([tmp_path / 'parts']) as reader:
        assert {c.topic: c.msgcount for c in reader.connections} == whole['topics']
        assert sum(1 for _ in reader.messages()) == whole['message_count']


def test_replay_markers_of_an_order_2_model_draw_the_joints_second_order_motion():
    # The lever's deformed end (joint B) moves by the second-order lever tip, drawn
    # exaggerated; the model's linear deflections are the same in both drawings.
    model = model_for_mechanism(load_mechanism('cho1992'),
                                ModelOptions.linear(bearings='rigid', grid_size=32, order=2))
    linear = dataclasses.replace(model, second_order=None)
    rng = np.random.default_rng(3)
    angles = rng.uniform(0.0, 2.0 * np.pi, 4)
    modal = rng.standard_normal((4, model.size)) * 1e-3
    stamps = T0_NS + STEP_NS * np.arange(4)
    exaggeration = 50.0
    drawn = {}
    for name, source_model in (('second', model), ('linear', linear)):
        source = MarkerSource(source_model, 'linkage_ground', exaggeration, 5,
                              [ros_messages.OK] * 4)
        rows = source.rows(stamps, angles, modal)
        drawn[name] = [deserialize_message(row.tobytes(), MarkerArray) for row in rows]
    forms = SecondOrderForms(model.second_order)
    cells, t = model.cell(angles)
    _, d_b = forms.joint_motion(forms.spline_scalars(cells, t), modal)
    assert np.abs(d_b).max() > 0.0
    for k in range(4):
        ends = {}
        for name, array in drawn.items():
            lever = [m for m in array[k].markers if m.ns.endswith('/deformed') and m.id == 2][0]
            ends[name] = np.array([lever.points[-1].x, lever.points[-1].y])
            start = np.array([lever.points[0].x, lever.points[0].y])
            ends[name + '_start'] = start
        np.testing.assert_allclose(ends['second'] - ends['linear'], exaggeration * d_b[k],
                                   rtol=1e-9, atol=1e-12)
        np.testing.assert_array_equal(ends['second_start'], ends['linear_start'])   # O4


def uneven_replay(model, count):
    """Make inputs of several lengths and estimates with outliers and a batch of them."""
    rng = np.random.default_rng(17)
    stamps = T0_NS + STEP_NS * np.arange(count)
    data = []
    for k, stamp in enumerate(stamps.tolist()):
        message = JointState(name=['crank'], position=[0.1 * k],
                             velocity=[] if k % 7 == 3 else [40.0])
        message.header.stamp = ros_messages.ns_to_stamp(stamp)
        message.header.frame_id = 'crank' + 'x' * (k % 5)
        data.append(serialize_exact(message))
    samples, estimate = random_rows(rng, stamps, data)
    estimate['crank_angle'] = rng.uniform(-np.pi, np.pi, count)
    estimate['modal'] = rng.normal(size=(count, model.size)) * 1e-3
    estimate['lever_tip'][1024:2048] = np.nan       # a whole batch of inputs alone
    estimate['coupler_mid'][[5, 2100, 2101]] = np.nan
    return samples, estimate


def write_one_by_one(path, samples, estimate, declared, markers):
    """
    Write the replay's messages one recorder.write call each, from one-message encoders.

    ``markers``: row -> marker array bytes of the rows that have one.
    """
    frame = b'linkage_ground'
    recorder = McapRecorder(path, chunk_size_bytes=OUTPUT_CHUNK_BYTES,
                            flush_period_s=OUTPUT_FLUSH_PERIOD_S, flush_thread=False,
                            compression_level=OUTPUT_ZSTD_LEVEL)
    recorder.open()
    for name, type_name in declared:
        recorder.add_topic(name, type_name)
    names = [name for name, _ in declared]
    for k in range(len(samples['data'])):
        log = int(samples['log_ns'][k])
        recorder.write(names[0], samples['data'][k], log, int(samples['publish_ns'][k]))
        if not (np.isfinite(estimate['lever_tip'][k]).all()
                and np.isfinite(estimate['coupler_mid'][k]).all()):
            continue
        sec, nanosec = divmod(int(samples['stamps_ns'][k]), 10**9)
        outputs = [vector3_stamped_cdr(sec, nanosec, frame, *estimate['lever_tip'][k]),
                   vector3_stamped_cdr(sec, nanosec, frame, *estimate['coupler_mid'][k]),
                   criteria_cdr(sec, nanosec, frame, estimate['criterion'][k],
                                estimate['gamma_dot'][k], estimate['reaction_n'][k]),
                   quality_cdr(sec, nanosec, frame, estimate['error_indicator'][k],
                               estimate['nonlinearity'][k])]
        if k in markers:
            outputs.append(markers[k])
        for name, message in zip(names[1:], outputs):
            recorder.write(name, message, log)
    return recorder.close()


def test_a_replay_bag_is_the_bag_of_its_messages_written_one_by_one(tmp_path):
    """Packed batches: inputs of several lengths, no outputs in a batch, chunks cut inside."""
    model = model_for_mechanism(load_mechanism('cho1992'),
                                ModelOptions.linear(bearings='rigid', grid_size=32))
    count, every = 2600, 2
    samples, estimate = uneven_replay(model, count)
    topics = output_topics('/flexlink_node')
    levels = [ros_messages.OK] * 4
    # Two blocks: the second's batches start at its own first row (1500), not at 1024s.
    blocks = [(0, *rows_of(samples, estimate, slice(0, 1500))),
              (1500, *rows_of(samples, estimate, slice(1500, None)))]
    (tmp_path / 'packed').mkdir()
    packed = write_replay(tmp_path / 'packed' / 'replay.mcap', blocks, '/joint_states', topics,
                          'linkage_ground', model, markers_every_n=every, joint_levels=levels)
    (tmp_path / 'single').mkdir()
    # The markers of the rows of each batch the writer computes together: the contraction's
    # last bits depend on the rows it runs over.
    source = MarkerSource(model, 'linkage_ground', 10.0, 9, levels)
    markers = {}
    for start, stop in ((0, 1024), (1024, 1500), (1500, 2524), (2524, count)):
        rows = np.arange(start, stop)
        rows = rows[(rows % every == 0) & np.isfinite(estimate['lever_tip'][rows]).all(axis=1)
                    & np.isfinite(estimate['coupler_mid'][rows]).all(axis=1)]
        encoded = source.rows(samples['stamps_ns'][rows], estimate['crank_angle'][rows],
                              estimate['modal'][rows])
        markers.update(zip(rows.tolist(), (row.tobytes() for row in encoded)))
    single = write_one_by_one(tmp_path / 'single' / 'replay.mcap', samples, estimate,
                              replay_topics('/joint_states', topics, every), markers)
    first, second = (pathlib.Path(status['files'][0]).read_bytes()
                     for status in (packed, single))
    assert first == second
    valid = count - 1024 - 3
    marked = sum(1 for k in range(0, count, every) if not 1024 <= k < 2048 and k != 2100)
    with AnyReader([tmp_path / 'packed' / 'replay.mcap']) as reader:
        assert {c.topic: c.msgcount for c in reader.connections} == {
            '/joint_states': count, topics['lever_tip']: valid, topics['coupler_mid']: valid,
            topics['criteria']: valid, topics['quality']: valid, topics['markers']: marked}
    with open(packed['files'][0], 'rb') as stream:
        reader = make_reader(stream)
        assert reader.get_summary().statistics.chunk_count >= 3
        lengths = {len(m.data) for _, c, m in reader.iter_messages() if c.topic
                   == '/joint_states'}
    assert len(lengths) > 3
