"""A local process that changes a node's live parameters: the parameter attack of issue 49.

`python param_attacker.py NODE NAME=VALUE [NAME=VALUE ...]` starts a node named
`param_attacker` that sets each parameter of NODE on its own through rclpy's
AsyncParameterClient (what `ros2 param set` does) and prints one JSON line per attempt:
{"node", "name", "value", "successful", "reason"}. Values are read as YAML-ish numbers:
`1.0` a double, `true` a bool, anything else a string. Exit 0 once all were answered, 1 when
the node's parameter services never appeared.
"""

from __future__ import annotations

import json
import sys
import time
from typing import Any

import rclpy
from rclpy.parameter import Parameter
from rclpy.parameter_client import AsyncParameterClient


def _value(text: str) -> Any:
    if text in ('true', 'false'):
        return text == 'true'
    try:
        return int(text)
    except ValueError:
        pass
    try:
        return float(text)
    except ValueError:
        return text


def main(target: str, assignments: list[str]) -> int:
    """Set each `NAME=VALUE` on `target`, one call each; print the answers."""
    rclpy.init()
    node = rclpy.create_node('param_attacker')
    try:
        client = AsyncParameterClient(node, target)
        if not client.wait_for_services(30):
            print(json.dumps({'node': target, 'error': 'no parameter services'}), flush=True)
            return 1
        for assignment in assignments:
            name, _, text = assignment.partition('=')
            value = _value(text)
            future = client.set_parameters([Parameter(name, value=value)])
            deadline = time.monotonic() + 20
            while not future.done() and time.monotonic() < deadline:
                rclpy.spin_once(node, timeout_sec=0.1)
            result = future.result().results[0] if future.done() else None
            print(json.dumps({'node': target, 'name': name, 'value': value,
                              'successful': bool(result and result.successful),
                              'reason': result.reason if result else 'no answer'}), flush=True)
        return 0
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == '__main__':
    sys.exit(main(sys.argv[1], sys.argv[2:]))
