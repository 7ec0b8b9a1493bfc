"""
Names shared by every layer: links, joints, estimator outputs, the node and its topics.

One place for what a subscriber, a recording and the physics must agree on. Imports nothing.
"""

LINK_NAMES = ('crank', 'coupler', 'lever')
# Revolute joints in loop order: ground-crank, crank-coupler, coupler-lever, lever-ground.
JOINT_NAMES = ('O2', 'A', 'B', 'O4')
# The deflections the estimator reports, in the order of its output vector [m].
OUTPUT_NAMES = ('lever_tip_dx', 'lever_tip_dy', 'coupler_mid_dx', 'coupler_mid_dy')
OUTPUT_POINTS = ('lever_tip', 'coupler_mid')

NODE_NAME = 'flexlink_node'
# Log lines of the node that tools wait for: subscribed and ready; the first input arrived.
READY_MESSAGE = 'ready: listening on'
FIRST_INPUT_MESSAGE = 'first crank sample'
DEFAULT_FRAME_ID = 'linkage_ground'
# Output topics relative to the node's namespace (~ = the node's private namespace).
TOPICS = {'lever_tip': '~/lever_tip/deflection', 'coupler_mid': '~/coupler_mid/deflection',
          'criteria': '~/joint_criteria', 'quality': '~/quality', 'markers': '~/markers',
          'diagnostics': '/diagnostics'}
# Entries of the per-sample quality message (~/quality), both dimensionless.
QUALITY_NAMES = ('error_indicator', 'nonlinearity')

JOINT_STATE = 'sensor_msgs/msg/JointState'
VECTOR3_STAMPED = 'geometry_msgs/msg/Vector3Stamped'
MARKER_ARRAY = 'visualization_msgs/msg/MarkerArray'


def output_topics(node_name):
    """
    Return the output topic names of a node called ``node_name``, as flexlink_node publishes them.

    Parameters
    ----------
    node_name : str
        The node's name, with or without a leading slash.

    Returns
    -------
    dict
        ``lever_tip``, ``coupler_mid``, ``criteria``, ``quality``, ``markers`` -> absolute
        topic name.

    """
    base = '/' + node_name.strip('/')
    keys = ('lever_tip', 'coupler_mid', 'criteria', 'quality', 'markers')
    return {key: base + TOPICS[key][1:] for key in keys}
