"""
Translation between ROS 2 messages and the core's arrays (standard message types only).

Input: the crank's angle and speed from a ``sensor_msgs/JointState``. Output topics (all
stamped with the input's stamp, frame = the ground frame, SI units):

- deflections: ``geometry_msgs/Vector3Stamped``, x and y = elastic deflection [m], z = 0;
- joint criteria: ``sensor_msgs/JointState`` with name = [O2, A, B, O4] and, per joint,
  position = |dgamma/dt| / R [rad/(s N)] (the Earles-Wu criterion), velocity = dgamma/dt
  [rad/s], effort = R [N] (reaction force magnitude);
- per-sample quality: ``sensor_msgs/JointState`` with name = [error_indicator, nonlinearity]
  and position = the two indicators (dimensionless; NaN = not available), velocity and effort
  empty (:func:`quality_message`);
- the deformed linkage: ``visualization_msgs/MarkerArray``;
- health and per-joint levels: ``diagnostic_msgs/DiagnosticArray``.

Also the ``rcl_interfaces/ParameterDescriptor`` of a parameter table's entry.
"""

import math

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import Vector3Stamped
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from sensor_msgs.msg import JointState
from std_msgs.msg import Header

from ..errors import InputRejected
from ..names import JOINT_NAMES, QUALITY_NAMES

OK, WARN, ERROR, STALE = (DiagnosticStatus.OK, DiagnosticStatus.WARN, DiagnosticStatus.ERROR,
                          DiagnosticStatus.STALE)
LEVEL_NAMES = {OK: 'OK', WARN: 'WARN', ERROR: 'ERROR', STALE: 'STALE'}


def stamp_to_ns(stamp):
    """Return the integer nanoseconds of a builtin_interfaces/Time."""
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def ns_to_stamp(stamp_ns):
    """Return the builtin_interfaces/Time of integer nanoseconds."""
    sec, nanosec = divmod(int(stamp_ns), 1_000_000_000)
    return Time(sec=sec, nanosec=nanosec)


def crank_from_joint_state(msg, joint_name):
    """
    Read the crank angle and speed from a JointState.

    Parameters
    ----------
    msg : sensor_msgs.msg.JointState
        The message.
    joint_name : str
        Name of the crank joint.

    Returns
    -------
    stamp_ns : int
    angle : float
        Crank angle [rad] (any real; the estimator wraps it).
    speed : float or None
        Crank speed [rad/s], None if the message has no usable velocity for the joint.

    Raises
    ------
    InputRejected
        Empty arrays, the joint missing, a position array too short, or a non-finite angle.

    """
    if not msg.name:
        raise InputRejected('empty JointState (no joint names)')
    try:
        index = list(msg.name).index(joint_name)
    except ValueError:
        raise InputRejected(f'joint {joint_name!r} not in JointState names '
                            f'{list(msg.name)[:8]}') from None
    if len(msg.position) <= index:
        raise InputRejected(f'JointState has {len(msg.position)} positions for '
                            f'{len(msg.name)} names: no position for {joint_name!r}')
    angle = float(msg.position[index])
    if not math.isfinite(angle):
        raise InputRejected(f'non-finite position {angle} for {joint_name!r}')
    speed = None
    if len(msg.velocity) > index:
        value = float(msg.velocity[index])
        if not math.isfinite(value):
            raise InputRejected(f'non-finite velocity {value} for {joint_name!r}')
        speed = value
    return stamp_to_ns(msg.header.stamp), angle, speed


def deflection_message(stamp, frame_id, dx, dy):
    """Return the Vector3Stamped of an elastic deflection [m] in the ground frame."""
    msg = Vector3Stamped()
    msg.header = Header(stamp=stamp, frame_id=frame_id)
    msg.vector.x, msg.vector.y, msg.vector.z = float(dx), float(dy), 0.0
    return msg


def criteria_message(stamp, frame_id, ratio, gamma_dot, force):
    """
    Return a JointState carrying the Earles-Wu criterion per joint (see the module docstring).

    Parameters
    ----------
    stamp : builtin_interfaces.msg.Time
        Stamp of the input.
    frame_id : str
        Ground frame.
    ratio, gamma_dot, force : sequence of float, length 4
        |dgamma/dt|/R [rad/(s N)], dgamma/dt [rad/s], R [N] for O2, A, B, O4.

    """
    msg = JointState()
    msg.header = Header(stamp=stamp, frame_id=frame_id)
    msg.name = list(JOINT_NAMES)
    msg.position = [float(v) for v in ratio]
    msg.velocity = [float(v) for v in gamma_dot]
    msg.effort = [float(v) for v in force]
    return msg


def quality_message(stamp, frame_id, error_indicator, nonlinearity):
    """
    Return the JointState carrying the quality indicators of one estimate.

    A JointState because it is a standard stamped message with named entries: a consumer
    pairs it with the estimate of the same stamp (message_filters), a plot selects an entry by
    index (``position[0]``), and further indicators can be added by name.

    Parameters
    ----------
    stamp : builtin_interfaces.msg.Time
        Stamp of the input (and of the estimate).
    frame_id : str
        Ground frame.
    error_indicator : float
        Size of the residual-flexibility correction relative to the deflection
        (core/estimation/sample.py) [-]: large means the reduced basis misses response.
    nonlinearity : float
        The nonlinearity indicator (core/validity.py) [-]: the amplitude-dependent frequency
        shift in units of the distance to resonance; NaN where the estimator does not compute it.

    """
    msg = JointState()
    msg.header = Header(stamp=stamp, frame_id=frame_id)
    msg.name = list(QUALITY_NAMES)
    msg.position = [float(error_indicator), float(nonlinearity)]
    return msg


def joint_level(ratio, flagged, warn, error):
    """Grade one joint by its criterion value and near-zero-force flag (a diagnostic level)."""
    if flagged or not math.isfinite(ratio) or ratio > error:
        return ERROR
    if ratio > warn:
        return WARN
    return OK


def status(name, level, message, values, hardware_id=''):
    """Build a DiagnosticStatus with key-value pairs (values formatted as strings)."""
    return DiagnosticStatus(
        level=level, name=name, message=message, hardware_id=hardware_id,
        values=[KeyValue(key=str(k), value=(f'{v:.6g}' if isinstance(v, float) else str(v)))
                for k, v in values.items()])


def diagnostics_message(stamp, statuses):
    """Build the DiagnosticArray of statuses."""
    msg = DiagnosticArray()
    msg.header = Header(stamp=stamp)
    msg.status = list(statuses)
    return msg


def parameter_descriptor(spec):
    """
    Describe a parameter to ROS: description, read-only flag, range or allowed values.

    Parameters
    ----------
    spec : parameters.ParameterSpec
        The parameter's table entry.

    Returns
    -------
    rcl_interfaces.msg.ParameterDescriptor

    """
    # A switch also takes YAML's booleans (unquoted on / off): its type may change.
    descriptor = ParameterDescriptor(description=spec.description, read_only=spec.read_only,
                                     dynamic_typing=spec.switch)
    if spec.choices:
        descriptor.additional_constraints = 'one of: ' + ', '.join(spec.choices)
    elif spec.max_bytes is not None:
        descriptor.additional_constraints = f'at most {spec.max_bytes} bytes (UTF-8)'
    if spec.low is not None and isinstance(spec.default, float):
        descriptor.floating_point_range = [FloatingPointRange(from_value=float(spec.low),
                                                              to_value=float(spec.high))]
    elif spec.low is not None and not isinstance(spec.default, bool):
        descriptor.integer_range = [IntegerRange(from_value=int(spec.low),
                                                 to_value=int(spec.high), step=1)]
    return descriptor
