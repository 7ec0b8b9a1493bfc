"""msg_schema: .msg definitions, type hashes and exact CDR serialisation against rclpy."""

import re

from cdr_helpers import cdr_layout, rclpy_exact
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from flexlink_ros.io.msg_schema import message_definition, serialize_exact, type_hash
from flexlink_ros.ros import messages as ros_messages
import output_messages
import pytest
from rclpy.serialization import deserialize_message, serialize_message
from rosbags.typesys import get_types_from_msg
from sensor_msgs.msg import JointState
from visualization_msgs.msg import Marker


def test_serialize_exact_trims_what_rclpy_overallocates():
    empty = JointState()
    # encapsulation 4 + stamp 8 + frame_id 4+1 (+3 padding) + four empty sequences 4 each
    assert len(serialize_exact(empty)) == 36
    assert len(serialize_message(empty)) > 36  # the rmw's estimate, trailing bytes included
    one_byte_tail = Marker()
    data = serialize_exact(one_byte_tail)
    assert len(data) <= len(serialize_message(one_byte_tail))
    assert data[-1:] == b'\x00'  # mesh_use_embedded_materials = False, no tail padding


def diagnostics():
    status = DiagnosticStatus(level=DiagnosticStatus.WARN, name='jöint', message='',
                              values=[KeyValue(key='k', value='v' * 5)])
    return DiagnosticArray(status=[status, DiagnosticStatus()])


@pytest.mark.parametrize('message', [
    JointState(), JointState(name=['a', 'bb'], position=[1.0, 2.0], velocity=[], effort=[3.0]),
    Marker(), Marker(points=[], text='é', frame_locked=True),
    output_messages.deflection_message(ros_messages.ns_to_stamp(7), 'ground', 1.0, 2.0),
    diagnostics(),
], ids=['empty', 'joints', 'marker', 'marker-text', 'vector', 'diagnostics'])
def test_serialize_exact_equals_rclpy_trimmed_with_zeroed_padding(message):
    data = serialize_exact(message)
    assert data == rclpy_exact(message)
    assert cdr_layout(message)[0] == len(data)
    assert deserialize_message(data, type(message)) == message


def test_joint_state_definition_parses_to_its_fields_and_hash_has_the_rihs01_form():
    """The .msg text of JointState, read by rosbags' parser; its hash in rosbag2's form."""
    text = message_definition('sensor_msgs/msg/JointState')
    types = get_types_from_msg(text, 'sensor_msgs/msg/JointState')
    # The text carries its dependencies (MSG: sections) as rosbag2 writes them.
    assert {'std_msgs/msg/Header', 'builtin_interfaces/msg/Time'} <= set(types)
    fields = types['sensor_msgs/msg/JointState'][1]
    assert [name for name, _ in fields] == ['header', 'name', 'position', 'velocity', 'effort']
    assert [name for name, _ in types['std_msgs/msg/Header'][1]] == ['stamp', 'frame_id']
    digest = type_hash('sensor_msgs/msg/JointState')
    assert re.fullmatch('RIHS01_[0-9a-f]{64}', digest)
    assert digest != type_hash('geometry_msgs/msg/Vector3Stamped')
