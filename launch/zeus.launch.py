r"""ROS 2 launch file: sim_bridge, context_estimator and policy (+ recorder), self-contained.

    ros2 launch zeus_ros zeus.launch.py
    ros2 launch zeus_ros zeus.launch.py namespace:=robot1 use_sim_time:=true record:=true \
        checkpoint:=/path/to/ckpt.pt params_file:=/path/to/params.yaml log_level:=debug
    ros2 launch zeus_ros zeus.launch.py single_process:=true   # the loop's nodes in one process
    ros2 launch zeus_ros zeus.launch.py continual:=true   # record, retrain, gate, swap live
    ros2 launch zeus_ros zeus.launch.py namespace:=r1 use_sim_time:=true
        # a second simulated system beside another: its own /r1/clock (clock:=global: /clock)

Runs from any folder with only the installed files: the params file defaults to
share/zeus_ros/params/zeus.yaml and its relative checkpoint resolves against the params file's
folder, then the package share. Arguments, defaults and parameter overrides come from
`zeus_ros.system.launch_defaults`, which `zeus launch` uses too: the two cannot drift apart.
`ros2 launch zeus_ros zeus.launch.py --show-args` lists the arguments. A dead node is restarted
as the params file's `/**/zeus_launch` respawn: section says (launch_ros `respawn`,
`respawn_delay`, `respawn_max_retries`; defaults as `zeus launch`: context_estimator, policy
and recorder 3 times, 1 s / 0.5 s apart, the bridges never); past that, any node but the
recorder and the continual trainer ends the launch, and a node that died for good (or refused
its parameters, exit 2) makes `ros2 launch` exit 1, as `zeus launch` does. Discovery scope and
domain come from the environment (export ROS_AUTOMATIC_DISCOVERY_RANGE and ROS_DOMAIN_ID before
launching).
Every node gets the launch's pairing key ($ZEUS_PAIRING_KEY, kept if already set): a restarted
peer is re-paired only when its start hello proves it (docs/security.md).
"""

from functools import partial
from typing import Any

from launch import LaunchContext, LaunchDescription
from launch.actions import (
    DeclareLaunchArgument,
    EmitEvent,
    LogInfo,
    OpaqueFunction,
    RegisterEventHandler,
)
from launch.event_handlers import OnProcessExit
from launch.events import Shutdown
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

from zeus_ros.system import launch_defaults
from zeus_ros.system.respawn import LaunchExits


class NodeDiedError(RuntimeError):
    """Raised in an exit handler: launch's one way to end a launch with a non-zero status.

    LaunchService.run_async catches an exception from an event handler, shuts the launch down
    with its message as the reason and returns 1 (`ros2 launch` exits with it); a Shutdown
    event alone ends the launch with 0.
    """


def launch_nodes(context: LaunchContext) -> list:
    """The planned nodes for the given arguments, each with its respawn and exit handling."""
    values = {argument.name: LaunchConfiguration(argument.name).perform(context)
              for argument in launch_defaults.ARGUMENTS}
    plan = launch_defaults.plan_from_arguments(values)
    exits = launch_defaults.launch_exits(plan)
    env = {**dds_env(), **launch_defaults.launch_env()}
    actions = []
    if plan.contained:
        # No name, namespace or parameters on the container itself: each node inside gets its
        # own --ros-args (container_args), a process-wide remap would rename all of them.
        watch = exits[launch_defaults.CONTAINER]
        container = Node(package=launch_defaults.PACKAGE,
                         executable=launch_defaults.CONTAINER_EXECUTABLE,
                         arguments=plan.container_args(), output='screen',
                         additional_env=env, **watch.respawn.kwargs())
        actions += [container, _on_exit(container, watch)]
    for spec in plan.separate:
        watch = exits[spec.name]
        node = Node(package=launch_defaults.PACKAGE, executable=spec.executable,
                    name=spec.name, namespace=plan.namespace or None,
                    parameters=[str(plan.params_file), spec.parameters],
                    remappings=plan.remappings,
                    ros_arguments=['--log-level', plan.log_level], output='screen',
                    additional_env=env, **watch.respawn.kwargs())
        actions += [node, _on_exit(node, watch)]
    return actions


def dds_env() -> dict[str, str]:
    """The loopback-only Fast DDS profile for the nodes, unless the user has a profile set."""
    import os

    from zeus_ros.system.processes import loopback_dds_profile

    profile = loopback_dds_profile()
    if profile is None or 'FASTRTPS_DEFAULT_PROFILES_FILE' in os.environ:
        return {}
    return {'FASTRTPS_DEFAULT_PROFILES_FILE': str(profile)}


def _on_exit(process: Any, watch: LaunchExits) -> RegisterEventHandler:
    """Handle every exit of `process` (launch_ros may have restarted it: same action)."""
    return RegisterEventHandler(OnProcessExit(target_action=process,
                                              on_exit=partial(after_exit, watch)))


def after_exit(watch: LaunchExits, event: Any, context: LaunchContext) -> list | None:
    """Say what an exit means; stop the launch, or fail it (NodeDiedError), if it must.

    Exits while the launch shuts down are its own doing. A restart is launch_ros's (it
    decides on the same counts, `LaunchExits`); this only names it.
    """
    if context.is_shutdown:
        return None
    verdict = watch.after_exit(int(event.returncode))
    if verdict.action == 'fail':
        raise NodeDiedError(verdict.message)
    if verdict.action == 'stop':
        return [EmitEvent(event=Shutdown(reason=verdict.message))]
    return [LogInfo(msg=verdict.message)]


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
