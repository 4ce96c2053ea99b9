"""A fake robot for robot_bridge's camera path: a MuJoCo half-cheetah behind ros2_control topics.

The plant is the project's own Cheetah-Motor-v0 task (sim_bridge), so the camera shows exactly
what sim_bridge renders as the task's pixel observation (its tracking camera, 84x84 rgb8: the
bridge's crop and resize are the identity) and the zoo's pixel checkpoints see what they were
trained on. What the outside sees is a ros2_control robot: JointState of every joint (the root
joints rootx/rootz/rooty too, so `velocity:rootx` is the forward speed) and the camera on
`camera/image_raw` at `rate_hz`, and a forward command controller taking the 6 motor commands
on `forward_command_controller/commands` in its own joint order (CONTROLLER_JOINTS, not the
model's). Each tick advances the physics by one agent step of the task (action repeat x
sub-steps, 0.04 s) with the newest command, so a rate below 25 Hz is slow motion: on a machine
that renders in software a frame takes ~0.1 s. The plant stands still until the controller's
first command (robot_bridge sends its safe command at step 0): a run's distance then starts
where the zero-command reference (`CheetahPlant`, same seed) starts. On SIGINT it writes the
commands it received (arrival order) and rootx after every tick since the start as JSON.

    python test/fake_cheetah.py out.json [rate_hz] [motor_gain] [seed]
"""

from __future__ import annotations

import json
import sys

import numpy as np
import rclpy
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions
from sensor_msgs.msg import Image, JointState
from std_msgs.msg import Float64MultiArray

from sim_bridge.dmc_base import DmcTask
from sim_bridge.registry import task_class
from zeus_ros.nodes.messages import image_from_array

from fake_robot import spin_until_signal

TASK = 'Cheetah-Motor-v0'
FRAME_SIZE = 84
"""sim_bridge's frame side for pixel observations (its image_size default)."""
CONTROLLER_JOINTS = ['ffoot', 'fshin', 'fthigh', 'bfoot', 'bshin', 'bthigh']
"""The controller's order: the model's actuators reversed, so a wrong order shows."""


class CheetahPlant:
    """The task's physics with no episode end: one agent step per call, no reset."""

    def __init__(self, motor_gain: float = 1.0, seed: int = 0) -> None:
        task = task_class(TASK)(seed=seed, context={'motor_gain': motor_gain},
                                episode_length=2**31 - 1)
        assert isinstance(task, DmcTask)  # its MuJoCo model and data are what a robot shows
        self.task = task
        self.task.reset()  # the suite's random pose, settled
        model = self.task.model
        self.joints = [model.joint(i).name for i in range(model.njnt)]
        self.actuated = [model.joint(int(j)).name for j in model.actuator_trnid[:, 0]]

    def step(self, command: dict[str, float]) -> None:
        """Advance one agent step with each motor's command (missing: 0)."""
        self.task.step(np.array([command.get(j, 0.0) for j in self.actuated]))

    @property
    def rootx(self) -> float:
        """How far forward the torso is (m)."""
        return float(self.task.data.joint('rootx').qpos[0])

    def joint_state(self) -> JointState:
        """Position, velocity and actuator force of every joint, as ros2_control reports."""
        data = self.task.data
        return JointState(name=self.joints,
                          position=[float(data.joint(j).qpos[0]) for j in self.joints],
                          velocity=[float(data.joint(j).qvel[0]) for j in self.joints],
                          effort=[float(data.joint(j).qfrc_actuator[0]) for j in self.joints])

    def frame(self) -> np.ndarray:
        """The camera: sim_bridge's rendering of the task's pixel observation."""
        return self.task.render(FRAME_SIZE, FRAME_SIZE)


class FakeCheetah(Node):
    """The plant behind JointState, a camera and a forward command controller."""

    def __init__(self, rate: float, motor_gain: float, seed: int) -> None:
        super().__init__('fake_cheetah')
        self.plant = CheetahPlant(motor_gain, seed)
        self.command: dict[str, float] | None = None  # None: not switched on yet
        self.received: list[list[float]] = []
        self.rootx: list[float] = []
        reliable = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
        self.pub_joints = self.create_publisher(JointState, 'joint_states', reliable)
        self.pub_camera = self.create_publisher(Image, 'camera/image_raw', reliable)
        self.create_subscription(Float64MultiArray, 'forward_command_controller/commands',
                                 self.on_command, reliable)
        self.create_timer(1.0 / rate, self.tick)

    def on_command(self, msg: Float64MultiArray) -> None:
        """Take a command in the controller's joint order; remember it for the test."""
        values = list(msg.data)
        self.received.append(values)
        if len(values) == len(CONTROLLER_JOINTS):
            if self.command is None:
                self.rootx.append(self.plant.rootx)
            self.command = dict(zip(CONTROLLER_JOINTS, values, strict=True))

    def tick(self) -> None:
        """Advance one agent step (once switched on), then publish joints and camera."""
        if self.command is not None:
            self.plant.step(self.command)
            self.rootx.append(self.plant.rootx)
        msg = self.plant.joint_state()
        msg.header.stamp = self.get_clock().now().to_msg()
        self.pub_joints.publish(msg)
        self.pub_camera.publish(image_from_array(self.plant.frame(), msg.header.stamp))


def main() -> None:
    """Run until SIGINT/SIGTERM, then write the commands and the rootx trajectory."""
    out = sys.argv[1]
    rate = float(sys.argv[2]) if len(sys.argv) > 2 else 5.0
    motor_gain = float(sys.argv[3]) if len(sys.argv) > 3 else 1.0
    seed = int(sys.argv[4]) if len(sys.argv) > 4 else 0
    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
    robot = FakeCheetah(rate, motor_gain, seed)
    spin_until_signal(robot, 'fake cheetah up')
    with open(out, 'w') as handle:
        json.dump({'commands': robot.received, 'rootx': robot.rootx}, handle)
    robot.plant.task.close()
    robot.destroy_node()
    rclpy.try_shutdown()


if __name__ == '__main__':
    main()
