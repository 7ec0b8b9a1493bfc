"""markers: the marker and row encoders against rclpy's serialisation."""

from cdr_helpers import rclpy_exact
from flexlink_ros.io import cdr
from flexlink_ros.io import markers
from flexlink_ros.ros import messages as ros_messages
import numpy as np
import pytest


@pytest.mark.parametrize('frame, count', [('linkage_ground', 9), ('m', 2), ('odd_frame', 17)])
def test_marker_encoder_equals_the_exact_serialisation(frame, count):
    rng = np.random.default_rng(count)
    encoder = markers.MarkerEncoder(frame, count)
    assert len(encoder.stamp_offsets) == 10      # 6 link strips + 4 joint spheres
    levels = [ros_messages.OK, ros_messages.WARN, ros_messages.ERROR, ros_messages.STALE]
    for _ in range(3):
        points = [rng.normal(size=(count, 2)) for _ in range(3)]
        deflections = [1e-3 * rng.normal(size=(count, 2)) for _ in range(3)]
        joints = rng.normal(size=(4, 2))
        stamp_ns = int(rng.integers(0, 2**31 - 1)) * 10**9 + int(rng.integers(0, 10**9))
        rng.shuffle(levels)
        expected = rclpy_exact(markers.linkage_markers(
            ros_messages.ns_to_stamp(stamp_ns), frame, points, deflections, 37.0, joints,
            levels))
        assert encoder.encode(stamp_ns, points, deflections, 37.0, joints, levels) == expected


@pytest.mark.parametrize('frame', ['linkage_ground', 'm', 'odd_frame'])
def test_row_encoders_equal_the_one_message_encoders(frame):
    rng = np.random.default_rng(len(frame))
    count = 7
    stamps = rng.integers(0, 2**31 - 1, count) * 10**9 + rng.integers(0, 10**9, count)
    values = rng.normal(size=(count, 2))
    ratio, rate, force = (rng.normal(size=(count, 4)) for _ in range(3))
    encoded = frame.encode()
    vectors = markers.rows_to_bytes(markers.vector3_stamped_rows(stamps, encoded, values))
    criteria = markers.rows_to_bytes(markers.criteria_rows(stamps, encoded, ratio, rate, force))
    encoder = markers.MarkerEncoder(frame, 5)
    points = rng.normal(size=(count, 3, 5, 2))
    deflections = 1e-3 * rng.normal(size=(count, 3, 5, 2))
    joints = rng.normal(size=(count, 4, 2))
    levels = [ros_messages.OK, ros_messages.WARN, ros_messages.ERROR, ros_messages.OK]
    marker_rows = markers.rows_to_bytes(encoder.encode_rows(stamps, points, deflections, 11.0,
                                                            joints, levels))
    for n, stamp in enumerate(stamps.tolist()):
        sec, nanosec = divmod(stamp, 10**9)
        assert vectors[n] == cdr.vector3_stamped_cdr(sec, nanosec, encoded, *values[n])
        assert criteria[n] == cdr.criteria_cdr(sec, nanosec, encoded, ratio[n], rate[n],
                                               force[n])
        assert marker_rows[n] == encoder.encode(stamp, list(points[n]), list(deflections[n]),
                                                11.0, joints[n], levels)
