"""ROS 2 launch file: sim_bridge, context_estimator and policy (+ recorder) with a params file.

    ros2 launch zeus_ros zeus.launch.py params_file:=/path/to/params.yaml record:=true

Same nodes and parameters as `zeus launch`; any node exiting shuts the whole launch down.
Discovery scope and domain come from the environment (export ROS_AUTOMATIC_DISCOVERY_RANGE and
ROS_DOMAIN_ID before launching).
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, EmitEvent, RegisterEventHandler
from launch.conditions import IfCondition
from launch.event_handlers import OnProcessExit
from launch.events import Shutdown
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node


def generate_launch_description() -> LaunchDescription:
    """Declare the arguments and the four nodes; stop everything when one exits."""
    default_params = os.path.join(get_package_share_directory('zeus_ros'), 'params',
                                  'zeus.yaml')
    params = LaunchConfiguration('params_file')
    nodes = [
        Node(package='zeus_ros', executable='sim_bridge_node', name='sim_bridge',
             parameters=[params], output='screen'),
        Node(package='zeus_ros', executable='context_estimator_node', name='context_estimator',
             parameters=[params], output='screen'),
        Node(package='zeus_ros', executable='policy_node', name='policy',
             parameters=[params], output='screen'),
        Node(package='zeus_ros', executable='recorder_node', name='recorder',
             parameters=[params], output='screen',
             condition=IfCondition(LaunchConfiguration('record'))),
    ]
    stop_all = [RegisterEventHandler(OnProcessExit(
        target_action=node, on_exit=[EmitEvent(event=Shutdown(reason='a node exited'))]))
        for node in nodes[:3]]
    return LaunchDescription([
        DeclareLaunchArgument('params_file', default_value=default_params,
                              description='ROS 2 params file for all nodes'),
        DeclareLaunchArgument('record', default_value='false',
                              description='also start the recorder'),
        *nodes,
        *stop_all,
    ])
