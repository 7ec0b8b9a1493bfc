"""Sample messages of the recorder tests: the output types with known values at sample k."""

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import Point, PointStamped, Vector3Stamped
from sensor_msgs.msg import JointState
from std_msgs.msg import Header
from visualization_msgs.msg import Marker, MarkerArray

T0_NS = 1_700_000_000_000_000_000
STEP_NS = 1_000_000  # 1 kHz


def stamp(ns):
    return Header(stamp=Time(sec=ns // 10**9, nanosec=ns % 10**9), frame_id='ground')


def sample_messages(k):
    """Build the four output types (and an empty-array JointState) at sample k."""
    t = T0_NS + k * STEP_NS
    joint = JointState(header=stamp(t), name=['crank'], position=[0.001 * k],
                       velocity=[] if k % 3 == 0 else [2.0 + k])
    diag = DiagnosticArray(header=stamp(t), status=[DiagnosticStatus(
        level=DiagnosticStatus.WARN if k % 2 else DiagnosticStatus.OK, name='joint A',
        message=f'sample {k}', values=[KeyValue(key='criterion', value=f'{0.5 * k:.3f}')])])
    markers = MarkerArray(markers=[Marker(
        header=stamp(t), ns='links', id=k % 5, type=Marker.LINE_STRIP,
        points=[Point(x=float(j), y=0.1 * k) for j in range(4)])])
    deflection = Vector3Stamped(header=stamp(t))
    deflection.vector.x = 1e-4 * k
    point = PointStamped(header=stamp(t), point=Point(x=k * 1.0, y=-1.0, z=0.5))
    return {'/joint_states': joint, '/diagnostics': diag, '/linkage_markers': markers,
            '/deflection': deflection, '/coupler_point': point, '/empty': JointState()}


def check_values(topic, k, msg):
    """Field-by-field comparison of a decoded message (either reader) with sample k."""
    t = T0_NS + k * STEP_NS
    if topic == '/empty':
        assert list(msg.name) == [] and len(msg.position) == 0 and msg.header.frame_id == ''
        return
    header = msg.markers[0].header if topic == '/linkage_markers' else msg.header
    assert header.stamp.sec == t // 10**9 and header.stamp.nanosec == t % 10**9
    assert header.frame_id == 'ground'
    if topic == '/joint_states':
        assert list(msg.name) == ['crank']
        assert list(msg.position) == [0.001 * k]
        assert list(msg.velocity) == ([] if k % 3 == 0 else [2.0 + k])
        assert len(msg.effort) == 0
    elif topic == '/diagnostics':
        (status,) = msg.status
        assert status.level == (1 if k % 2 else 0) and status.name == 'joint A'
        assert status.message == f'sample {k}'
        assert (status.values[0].key, status.values[0].value) == ('criterion', f'{0.5 * k:.3f}')
    elif topic == '/linkage_markers':
        (marker,) = msg.markers
        assert (marker.ns, marker.id, marker.type) == ('links', k % 5, 4)
        assert [(p.x, p.y) for p in marker.points] == [(float(j), 0.1 * k) for j in range(4)]
    elif topic == '/deflection':
        assert (msg.vector.x, msg.vector.y, msg.vector.z) == (1e-4 * k, 0.0, 0.0)
    elif topic == '/coupler_point':
        assert (msg.point.x, msg.point.y, msg.point.z) == (k * 1.0, -1.0, 0.5)


def record_samples(recorder, count):
    for k in range(count):
        t = T0_NS + k * STEP_NS
        for topic, msg in sample_messages(k).items():
            recorder.write(topic, msg, t + 20_000, publish_time_ns=t)
