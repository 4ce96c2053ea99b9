"""Steps per second of the sim_bridge node in lockstep, next to the in-process task loop.

The node is driven by a minimal responder (answers Action k as soon as observation k arrives),
state-only and with 84x84 rendering; the in-process loop does the same physics (and rendering)
with no ROS. Both run in this one process run, side by side, and the ratio is printed.

    source scripts/env.sh && python benchmarks/bench_sim_bridge.py [--steps 600]
"""

from __future__ import annotations

import argparse
from pathlib import Path
import subprocess
import sys
import time

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from sim_bridge.env import ScheduledEnv  # noqa: E402
from sim_bridge.registry import make_task  # noqa: E402
from sim_bridge.schedules import schedule_from_config  # noqa: E402

SCHEDULE = {'kind': 'switch', 'values': 'train', 'every': 100}


def in_process_rate(task_name: str, steps: int, pixels: bool) -> float:
    """Agent steps per second of ScheduledEnv alone (random actions, optional rendering)."""
    task = make_task(task_name, seed=0)
    env = ScheduledEnv(task, schedule_from_config(SCHEDULE, task, 0))
    rng = np.random.default_rng(0)
    low, high = task.action_bounds
    env.reset()
    start = time.perf_counter()
    for _ in range(steps):
        env.step(rng.uniform(low, high))
        if pixels:
            task.render(84, 84)
    elapsed = time.perf_counter() - start
    task.close()
    return steps / elapsed


def node_rate(task_name: str, steps: int, pixels: bool) -> float:
    """Agent steps per second of the sim_bridge node driven by a minimal lockstep responder."""
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from zeus_msgs.msg import Action, StateVector

    from zeus_ros.nodes.topics import TOPICS, step_qos
    from zeus_ros.system.processes import ros_env

    env = ros_env()  # $ROS_DOMAIN_ID, else one from $ZEUS_DOMAIN_RANGE; loopback only
    domain = int(env['ROS_DOMAIN_ID'])
    argv = [sys.executable, '-m', 'zeus_ros.nodes.sim_bridge_node', '--ros-args',
            '-p', f'task:={task_name}', '-p', f'max_steps:={steps}',
            '-p', f'pixels:={"true" if pixels else "false"}', '-p', 'peer_grace:=0.5',
            '-p', 'schedule.kind:=switch', '-p', 'schedule.values:=train',
            '-p', 'schedule.every:=100']
    process = subprocess.Popen(argv, env=env, stdout=subprocess.DEVNULL,
                               stderr=subprocess.DEVNULL, start_new_session=True)
    context = Context()
    rclpy.init(context=context, domain_id=domain)
    node = rclpy.create_node('bench_responder', context=context)
    publisher = node.create_publisher(Action, TOPICS.ACTION, step_qos())
    action = [0.0] * make_task(task_name).action_dim
    times: list[float] = []

    def answer(msg: StateVector) -> None:
        times.append(time.perf_counter())
        publisher.publish(Action(header=msg.header, step=msg.step, data=action))

    node.create_subscription(StateVector, TOPICS.STATE, answer, step_qos())
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    try:
        deadline = time.monotonic() + 300
        while process.poll() is None and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)
    finally:
        process.terminate()
        process.wait(timeout=10)
        executor.shutdown()
        node.destroy_node()
        rclpy.shutdown(context=context)
    if len(times) < 10:
        raise RuntimeError(f'the node published only {len(times)} observations')
    return (len(times) - 1) / (times[-1] - times[0])


def main() -> None:
    """Measure and print the table."""
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument('--task', default='Cheetah-Run-v0')
    parser.add_argument('--steps', type=int, default=600)
    args = parser.parse_args()
    print(f'sim_bridge lockstep benchmark: {args.task}, {args.steps} steps per run')
    print(f'{"observation":<12} {"in-process steps/s":>19} {"node steps/s":>13} {"ratio":>7}')
    for pixels in (False, True):
        steps = args.steps if not pixels else max(args.steps // 3, 50)
        local = in_process_rate(args.task, steps, pixels)
        live = node_rate(args.task, steps, pixels)
        label = '84x84 rgb' if pixels else 'state'
        print(f'{label:<12} {local:>19.1f} {live:>13.1f} {live / local:>7.3f}', flush=True)


if __name__ == '__main__':
    main()
