"""
Launch flexlink_node as a managed (lifecycle) node, configured and activated by launch.

    ros2 launch flexlink_ros flexlink_lifecycle.launch.py
    ros2 launch flexlink_ros flexlink_lifecycle.launch.py namespace:=robot1 driver:=true

The node starts unconfigured (``flexlink_node --managed``); launch asks for ``configure`` at
once and for ``activate`` when the node reports ``inactive`` (the pattern of launch_ros's
``lifecycle_pub_sub_launch.py``). ``autostart:=false`` leaves it unconfigured, for a
lifecycle manager or ``ros2 lifecycle set``. The other arguments are those of
``flexlink.launch.py``.
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, EmitEvent, LogInfo, RegisterEventHandler
from launch.conditions import IfCondition
from launch.events import matches_action
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import LifecycleNode, Node
from launch_ros.event_handlers import OnStateTransition
from launch_ros.events.lifecycle import ChangeState
from launch_ros.parameter_descriptions import ParameterValue
from lifecycle_msgs.msg import Transition

PACKAGE = 'flexlink_ros'


def launch_arguments(config_dir):
    """Return the launch arguments, each with its default and description."""
    return [
        DeclareLaunchArgument('namespace', default_value='',
                              description='Namespace of the node and the driver'),
        DeclareLaunchArgument('params_file',
                              default_value=os.path.join(config_dir, 'flexlink_node.yaml'),
                              description='Parameter file of flexlink_node (keyed /**)'),
        DeclareLaunchArgument('mechanism', default_value='cho1992',
                              description='Mechanism file, or a name in '
                                          'share/flexlink_ros/config (overrides the file)'),
        DeclareLaunchArgument('use_sim_time', default_value='false',
                              description='Use /clock as the node clock (true/false)'),
        DeclareLaunchArgument('autostart', default_value='true',
                              description='Configure and activate the node at launch '
                                          '(true/false)'),
        DeclareLaunchArgument('driver', default_value='false',
                              description='Also start crank_driver publishing the crank '
                                          'JointState (true/false)'),
        DeclareLaunchArgument('driver_params_file',
                              default_value=os.path.join(config_dir, 'crank_driver.yaml'),
                              description='Parameter file of crank_driver (keyed /**)'),
        DeclareLaunchArgument('log_level', default_value='info',
                              description='Log level of both nodes (debug, info, warn, ...)'),
    ]


def change_state(node, transition_id, condition=None):
    """Return the action that asks ``node`` for a lifecycle transition."""
    return EmitEvent(event=ChangeState(lifecycle_node_matcher=matches_action(node),
                                       transition_id=transition_id), condition=condition)


def activate_when_inactive(node):
    """Return the handler that activates ``node`` once it reports ``inactive``."""
    return RegisterEventHandler(
        OnStateTransition(target_lifecycle_node=node, goal_state='inactive',
                          entities=[LogInfo(msg='flexlink_node is inactive: activating'),
                                    change_state(node, Transition.TRANSITION_ACTIVATE)]),
        condition=IfCondition(LaunchConfiguration('autostart')))


def generate_launch_description():
    """Return the launch description: the managed node, its bring-up, optionally the driver."""
    config_dir = os.path.join(get_package_share_directory(PACKAGE), 'config')
    node = LifecycleNode(
        package=PACKAGE, executable='flexlink_node', name='flexlink_node',
        namespace=LaunchConfiguration('namespace'), output='screen',
        parameters=[LaunchConfiguration('params_file'),
                    {'mechanism': ParameterValue(LaunchConfiguration('mechanism'), value_type=str),
                     'use_sim_time': ParameterValue(LaunchConfiguration('use_sim_time'),
                                                    value_type=bool)}],
        arguments=['--managed', '--ros-args', '--log-level', LaunchConfiguration('log_level')])
    driver = Node(package=PACKAGE, executable='crank_driver', name='crank_driver',
                  namespace=LaunchConfiguration('namespace'), output='screen',
                  parameters=[LaunchConfiguration('driver_params_file')],
                  arguments=['--ros-args', '--log-level', LaunchConfiguration('log_level')],
                  condition=IfCondition(LaunchConfiguration('driver')))
    configure = change_state(node, Transition.TRANSITION_CONFIGURE,
                             condition=IfCondition(LaunchConfiguration('autostart')))
    # The handler is registered before the node starts, so no transition is missed.
    return LaunchDescription([*launch_arguments(config_dir), activate_when_inactive(node),
                              node, configure, driver])
