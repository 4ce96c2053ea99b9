"""A fake robot for the robot_bridge tests: what a ros2_control robot shows to the outside.

JointState (gripper, elbow, shoulder: another order than the bridge observes) at 50 Hz, a
payload sensor (Float64MultiArray), a 64x48 bgr8 camera, and a forward command controller
taking velocity commands in its own joint order (elbow, shoulder) on
`forward_command_controller/commands`. The plant is
first order: each joint's velocity follows its command with time constant `tau`. On SIGINT it
writes every command it received (arrival order) as JSON to the path in argv[1].

    python test/fake_robot.py commands.json [rate_hz] [payload_kg]
"""

from __future__ import annotations

import json
import signal
import sys
import time

import numpy as np
import rclpy
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions
from sensor_msgs.msg import Image, JointState
from std_msgs.msg import Float64MultiArray

NAMES = ['gripper', 'elbow', 'shoulder']
CONTROLLER_JOINTS = ['elbow', 'shoulder']


class FakeRobot(Node):
    """First-order velocity plant behind a forward command controller."""

    def __init__(self, rate: float, payload: float, tau: float = 0.1) -> None:
        super().__init__('fake_robot')
        self.dt, self.tau, self.payload = 1.0 / rate, tau, payload
        self.position = dict.fromkeys(NAMES, 0.0)
        self.velocity = dict.fromkeys(NAMES, 0.0)
        self.command = dict.fromkeys(NAMES, 0.0)
        self.received: list[list[float]] = []
        reliable = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
        self.pub_joints = self.create_publisher(JointState, 'joint_states', reliable)
        self.pub_payload = self.create_publisher(Float64MultiArray, 'payload_sensor', reliable)
        self.pub_camera = self.create_publisher(Image, 'camera/image_raw', reliable)
        self.create_subscription(Float64MultiArray, 'forward_command_controller/commands',
                                 self.on_command, reliable)
        self.create_timer(self.dt, self.tick)

    def on_command(self, msg: Float64MultiArray) -> None:
        """Take a command in the controller's joint order; remember it for the test."""
        values = list(msg.data)
        self.received.append(values)
        if len(values) == len(CONTROLLER_JOINTS):
            self.command.update(zip(CONTROLLER_JOINTS, values, strict=True))

    def tick(self) -> None:
        """Advance the plant one sample and publish what the sensors see."""
        for name in NAMES:
            gain = 1.0 / (1.0 + self.payload) if name == 'shoulder' else 1.0
            self.velocity[name] += self.dt / self.tau * (gain * self.command[name]
                                                         - self.velocity[name])
            self.position[name] += self.dt * self.velocity[name]
        msg = JointState(name=NAMES, position=[self.position[n] for n in NAMES],
                         velocity=[self.velocity[n] for n in NAMES],
                         effort=[self.command[n] for n in NAMES])
        msg.header.stamp = self.get_clock().now().to_msg()
        self.pub_joints.publish(msg)
        self.pub_payload.publish(Float64MultiArray(data=[self.payload]))
        # A 64x48 bgr8 camera: blue = 200, green = 100, red = 50 (the bridge turns it to rgb8).
        frame = np.zeros((48, 64, 3), np.uint8)
        frame[:] = (200, 100, 50)
        self.pub_camera.publish(Image(header=msg.header, height=48, width=64, encoding='bgr8',
                                      step=64 * 3, data=frame.tobytes()))


def spin_until_signal(node: Node, banner: str) -> None:
    """Print `banner` (what the tests wait for), then spin `node` until SIGINT or SIGTERM.

    The fake robots (this one, fake_cheetah.py) write what they received after this returns.
    """
    stop: list[bool] = []
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.append(True))
    print(banner, flush=True)
    while not stop:
        rclpy.spin_once(node, timeout_sec=0.05)


def main() -> None:
    """Run until SIGINT/SIGTERM, then write the received commands."""
    out = sys.argv[1]
    rate = float(sys.argv[2]) if len(sys.argv) > 2 else 50.0
    payload = float(sys.argv[3]) if len(sys.argv) > 3 else 0.5
    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
    robot = FakeRobot(rate, payload)
    spin_until_signal(robot, 'fake robot up')
    with open(out, 'w') as handle:
        json.dump({'commands': robot.received, 'time': time.time()}, handle)
    robot.destroy_node()
    rclpy.try_shutdown()


if __name__ == '__main__':
    main()
