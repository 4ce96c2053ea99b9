"""A second process that floods zeus/action (or zeus/context): the fault matrix's intruder.

It follows zeus/step to know the step sim_bridge waits for and publishes, as fast as it can,
well-formed actions for that step (every value MARK, so an applied one is recognisable),
actions for the next step, NaN, Inf, huge values and wrong lengths. Run:
`python flood_actions.py SECONDS SIZE [action|context]`; it prints `published N` when done.
With `context` it publishes ContextEstimates of SIZE values for the current step instead.
"""

from __future__ import annotations

import sys
import time

import rclpy
from rclpy.executors import SingleThreadedExecutor
from zeus_msgs.msg import Action, ContextEstimate, StepFeedback

from zeus_ros.nodes.topics import TOPICS, step_qos

MARK = 0.4321


def main(seconds: float, action_dim: int, topic: str = 'action') -> int:
    """Flood for `seconds`; return 0."""
    rclpy.init()
    node = rclpy.create_node('intruder')
    newest = {'step': 0}
    node.create_subscription(StepFeedback, TOPICS.STEP,
                             lambda m: newest.__setitem__('step', m.step), step_qos())
    msg_type, name = (Action, TOPICS.ACTION) if topic == 'action' else \
        (ContextEstimate, TOPICS.CONTEXT)
    publisher = node.create_publisher(msg_type, name, step_qos())
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    contents = [[MARK] * action_dim, [float('nan')] * action_dim, [float('inf')] * action_dim,
                [1e30] * action_dim, [MARK] * (action_dim + 3), [MARK] * action_dim]
    print('flooding', flush=True)
    published = 0
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        executor.spin_once(timeout_sec=0.0)
        for offset, data in enumerate(contents):
            step = newest['step'] + (1 if offset == len(contents) - 1 else 0)
            publisher.publish(msg_type(step=step, data=data))
            published += 1
    print(f'published {published}', flush=True)
    node.destroy_node()
    rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    raise SystemExit(main(float(sys.argv[1]), int(sys.argv[2]), *sys.argv[3:]))
