r"""ROS 2 launch file: sim_bridge, context_estimator and policy (+ recorder), self-contained.

    ros2 launch zeus_ros zeus.launch.py
    ros2 launch zeus_ros zeus.launch.py namespace:=robot1 use_sim_time:=true record:=true \
        checkpoint:=/path/to/ckpt.pt params_file:=/path/to/params.yaml log_level:=debug
    ros2 launch zeus_ros zeus.launch.py single_process:=true   # the loop's nodes in one process
    ros2 launch zeus_ros zeus.launch.py continual:=true   # record, retrain, gate, swap live
    ros2 launch zeus_ros zeus.launch.py namespace:=r1 use_sim_time:=true clock:=namespace
        # a second simulated system beside another: its own /r1/clock

Runs from any folder with only the installed files: the params file defaults to
share/zeus_ros/params/zeus.yaml and its relative checkpoint resolves against the params file's
folder, then the package share. Arguments, defaults and parameter overrides come from
`zeus_ros.system.launch_defaults`, which `zeus launch` uses too: the two cannot drift apart.
`ros2 launch zeus_ros zeus.launch.py --show-args` lists the arguments. Any node but the recorder
and the continual trainer exiting shuts the whole launch down. Discovery scope and domain come
from the environment (export ROS_AUTOMATIC_DISCOVERY_RANGE and ROS_DOMAIN_ID before launching).
Every node gets the launch's pairing key ($ZEUS_PAIRING_KEY, kept if already set): a restarted
peer is re-paired only when its start hello proves it (docs/security.md).
"""

from launch import LaunchContext, LaunchDescription
from launch.actions import DeclareLaunchArgument, EmitEvent, OpaqueFunction, RegisterEventHandler
from launch.event_handlers import OnProcessExit
from launch.events import Shutdown
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

from zeus_ros.system import launch_defaults


def launch_nodes(context: LaunchContext) -> list:
    """The planned nodes for the given arguments, and a shutdown when a non-recorder exits."""
    values = {argument.name: LaunchConfiguration(argument.name).perform(context)
              for argument in launch_defaults.ARGUMENTS}
    plan = launch_defaults.plan_from_arguments(values)
    env = {**dds_env(), **launch_defaults.launch_env()}
    actions = []
    if plan.contained:
        # No name, namespace or parameters on the container itself: each node inside gets its
        # own --ros-args (container_args), a process-wide remap would rename all of them.
        container = Node(package=launch_defaults.PACKAGE,
                         executable=launch_defaults.CONTAINER_EXECUTABLE,
                         arguments=plan.container_args(), output='screen',
                         additional_env=env)
        actions += [container, _shutdown_on_exit(container, launch_defaults.CONTAINER)]
    for spec in plan.separate:
        if spec.name == launch_defaults.TRAINER:  # no console script: run its module
            actions.append(_trainer_process(plan, spec, env))
            continue
        node = Node(package=launch_defaults.PACKAGE, executable=spec.executable,
                    name=spec.name, namespace=plan.namespace or None,
                    parameters=[str(plan.params_file), spec.parameters],
                    remappings=plan.remappings,
                    ros_arguments=['--log-level', plan.log_level], output='screen',
                    additional_env=env)
        actions.append(node)
        if not spec.records_others:
            actions.append(_shutdown_on_exit(node, spec.name))
    return actions


def _trainer_process(plan: launch_defaults.LaunchPlan, spec: launch_defaults.NodePlan,
                     env: dict[str, str]) -> object:
    """The continual trainer, as `zeus launch` starts it; its exit does not stop the loop."""
    import sys

    from launch.actions import ExecuteProcess

    return ExecuteProcess(cmd=[sys.executable, '-m', spec.module, '--ros-args',
                               *plan.ros_args(spec)], name=spec.name, output='screen',
                          additional_env=env)


def dds_env() -> dict[str, str]:
    """The loopback-only Fast DDS profile for the nodes, unless the user has a profile set."""
    import os

    from zeus_ros.system.processes import loopback_dds_profile

    profile = loopback_dds_profile()
    if profile is None or 'FASTRTPS_DEFAULT_PROFILES_FILE' in os.environ:
        return {}
    return {'FASTRTPS_DEFAULT_PROFILES_FILE': str(profile)}


def _shutdown_on_exit(node: Node, name: str) -> RegisterEventHandler:
    """Any node of the control loop exiting ends the launch."""
    return RegisterEventHandler(OnProcessExit(
        target_action=node, on_exit=[EmitEvent(event=Shutdown(reason=f'{name} exited'))]))


def generate_launch_description() -> LaunchDescription:
    """Declare the shared launch arguments; build the nodes once their values are known."""
    arguments = [
        DeclareLaunchArgument(
            argument.name, description=argument.description,
            default_value=(str(launch_defaults.default_params_file())
                           if argument.name == 'params_file' else argument.default))
        for argument in launch_defaults.ARGUMENTS
    ]
    return LaunchDescription([*arguments, OpaqueFunction(function=launch_nodes)])
