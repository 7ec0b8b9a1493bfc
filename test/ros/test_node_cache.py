"""flexlink_node with a model cache planted by another local user: refused, the same outputs."""

import json
import math
import os
import time

from flexlink_ros.core.estimation.streaming import StreamingEstimator
from flexlink_ros.core.reduction import store
from flexlink_ros.names import READY_MESSAGE
from flexlink_ros.ros import parameters as node_params
from flexlink_ros.ros.messages import stamp_to_ns
from flexlink_ros.ros.node_model import load_node_model
import numpy as np
import pytest
from test_node import (joint_state, NodeProcess, OUTPUTS, processes, READY_TIMEOUT_S,  # noqa
                       ros, spin_until)

OTHER_UID = 65534


def plant(directory, scale=1.3):
    """Build the node's default model into ``directory``, scale its tables, hand it over."""
    values = dict(node_params.defaults(), **{'model.cache_dir': str(directory)})
    model, _, _ = load_node_model(values, lambda note: None)
    for path in sorted(directory.glob('*.npz')):
        with np.load(path, allow_pickle=False) as archive:
            key = json.loads(archive['__header__'].tobytes())['key']
        arrays, meta = store.load_cache(path, key)
        arrays = {name: a * scale if a.dtype.kind == 'f' and name.endswith('table') else a
                  for name, a in arrays.items()}
        store.save_cache(path, key, arrays, meta)       # the checksum recomputed
        os.chown(path, OTHER_UID, OTHER_UID)
    os.chown(directory, OTHER_UID, OTHER_UID)
    os.chmod(directory, 0o777)
    return model


@pytest.mark.skipif(os.geteuid() != 0, reason='chown to another uid needs root')
def test_a_planted_cache_is_refused_and_the_published_deflections_are_the_models(
        tmp_path, processes, ros):  # noqa: F811
    from geometry_msgs.msg import Vector3Stamped
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import JointState
    planted = tmp_path / 'shared_cache'
    planted.mkdir()
    model = plant(planted)
    files = {p.name: p.stat().st_mtime_ns for p in planted.iterdir()}
    assert len(files) == 3      # the model, its validity-indicator and soft-basis tables
    # The linear model's deflections: the planted file is one (the nonlinear tables are
    # built beside it by the same trusted store).
    node = NodeProcess(tmp_path, f'model.cache_dir:={planted}', 'model.nonlinear:=off')
    processes.append(node)
    node.wait_for(READY_MESSAGE, READY_TIMEOUT_S)

    test_node, executor = ros
    qos = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
    publisher = test_node.create_publisher(JointState, 'joint_states', qos)
    lever = []
    test_node.create_subscription(Vector3Stamped, OUTPUTS[0], lever.append, qos)
    spin_until(executor, lambda: publisher.get_subscription_count() > 0
               and test_node.count_publishers(OUTPUTS[0]) > 0, 20.0, 'discovery')
    speed = 391.0 * 2.0 * math.pi / 60.0
    stamps = [1_800_000_000 * 10**9 + k * 1_000_000 for k in range(200)]
    angles = [math.fmod(speed * k * 1e-3, 2 * math.pi) for k in range(200)]
    for n, (stamp, angle) in enumerate(zip(stamps, angles)):
        publisher.publish(joint_state(stamp, ['crank'], [angle], [speed]))
        if n == 0:
            spin_until(executor, lambda: lever, 20.0, 'the first output')
        time.sleep(0.001)
    spin_until(executor, lambda: len(lever) >= len(stamps), 30.0, 'all outputs')
    assert [stamp_to_ns(m.header.stamp) for m in lever] == stamps
    estimator = StreamingEstimator(model)
    expected = np.array([estimator.update(s, a, speed).lever_tip
                         for s, a in zip(stamps, angles)])
    got = np.array([(m.vector.x, m.vector.y) for m in lever])
    assert np.max(np.abs(got - expected)) <= 1e-12 * np.max(np.abs(expected))
    log = node.log()   # the one line saying why; nothing written there
    refusals = [line for line in log.splitlines() if 'model cache not used' in line]
    assert len(refusals) == 1 and f'owned by uid {OTHER_UID}' in refusals[0]
    assert {p.name: p.stat().st_mtime_ns for p in planted.iterdir()} == files
