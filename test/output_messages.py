"""
The node's output messages built with rclpy: the oracle of the package's own CDR encoders.

The node writes its outputs' CDR directly (io/output_cdr.py); these build the same messages
as rclpy objects, field by field as docs/node.md describes them, for the tests to compare
the bytes with rclpy's and to read them back.
"""

from flexlink_ros.names import JOINT_NAMES, QUALITY_NAMES
from geometry_msgs.msg import Vector3Stamped
from sensor_msgs.msg import JointState
from std_msgs.msg import Header


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
