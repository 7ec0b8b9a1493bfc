"""
Launch flexlink_node, and optionally the crank_driver that stands in for the encoder.

    ros2 launch flexlink_ros flexlink.launch.py
    ros2 launch flexlink_ros flexlink.launch.py namespace:=robot1 driver:=true
    ros2 launch flexlink_ros flexlink.launch.py mechanism:=kang1990 params_file:=my.yaml

Both nodes run in ``namespace`` (so the node reads ``<namespace>/joint_states`` and publishes
under ``<namespace>/flexlink_node/``). The parameter files are keyed ``/**``, so they apply
under any namespace; ``mechanism`` and ``use_sim_time`` given here override the file.
``ros2 launch flexlink_ros flexlink.launch.py --show-args`` lists the arguments.
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue

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
        DeclareLaunchArgument('driver', default_value='false',
                              description='Also start crank_driver publishing the crank '
                                          'JointState (true/false)'),
        DeclareLaunchArgument('driver_params_file',
                              default_value=os.path.join(config_dir, 'crank_driver.yaml'),
                              description='Parameter file of crank_driver (keyed /**)'),
        DeclareLaunchArgument('log_level', default_value='info',
                              description='Log level of both nodes (debug, info, warn, ...)'),
    ]


def node_parameters():
    """Return the node's parameters: the file, then the arguments that override it."""
    return [LaunchConfiguration('params_file'),
            {'mechanism': ParameterValue(LaunchConfiguration('mechanism'), value_type=str),
             'use_sim_time': ParameterValue(LaunchConfiguration('use_sim_time'), value_type=bool)}]


def driver_node():
    """Return the crank_driver action, started when the ``driver`` argument is true."""
    return Node(package=PACKAGE, executable='crank_driver', name='crank_driver',
                namespace=LaunchConfiguration('namespace'), output='screen',
                parameters=[LaunchConfiguration('driver_params_file')],
                arguments=['--ros-args', '--log-level', LaunchConfiguration('log_level')],
                condition=IfCondition(LaunchConfiguration('driver')))


def generate_launch_description():
    """Return the launch description: flexlink_node and, on request, crank_driver."""
    config_dir = os.path.join(get_package_share_directory(PACKAGE), 'config')
    node = Node(package=PACKAGE, executable='flexlink_node', name='flexlink_node',
                namespace=LaunchConfiguration('namespace'), output='screen',
                parameters=node_parameters(),
                arguments=['--ros-args', '--log-level', LaunchConfiguration('log_level')])
    return LaunchDescription([*launch_arguments(config_dir), node, driver_node()])
