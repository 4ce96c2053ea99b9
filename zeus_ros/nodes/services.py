"""Operator services of the nodes (docs/usage.md lists them): one line back, never a crash.

std_srvs where it fits (SetBool: a switch, Trigger: an act); the pair swap is
zeus_msgs/SwapCheckpoint. Names are private (`~/name`), so namespaced systems each get theirs.
A handler raises ValueError to refuse: the caller reads the reason in `message`; any other
error is refused the same way and logged, so a bad request never takes a node down.
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable
import inspect
from typing import Any

from rclpy.node import Node
from std_srvs.srv import SetBool, Trigger


def answer(node: Node, name: str, act: Callable[[], str], response: Any) -> Any:
    """Run `act`; fill success and message (its line, or the refusal's)."""
    try:
        response.message = act()
        response.success = True
    except ValueError as error:
        response.success, response.message = False, f'{node.get_name()}: {error}'
    except Exception as error:
        node.get_logger().error(f'{name}: {type(error).__name__}: {error}')
        response.success = False
        response.message = f'{node.get_name()}: {name} failed: {type(error).__name__}: {error}'
    return response


def serve_switch(node: Node, name: str, switch: Callable[[bool], str]) -> Any:
    """`~/name` as std_srvs/SetBool: `switch(data)` returns what it did."""
    return node.create_service(
        SetBool, f'~/{name}', lambda req, res: answer(node, name, lambda: switch(req.data), res))


def serve_trigger(node: Node, name: str, act: Callable[[], str]) -> Any:
    """`~/name` as std_srvs/Trigger: `act()` returns what it did."""
    return node.create_service(Trigger, f'~/{name}',
                               lambda _req, res: answer(node, name, act, res))


def serve_swap(node: Node, name: str,
               swap: Callable[[str, str], tuple[str, str] | Awaitable[tuple[str, str]]]) -> Any:
    """`~/name` as zeus_msgs/SwapCheckpoint; `swap(path, expect)` -> (message, sha256).

    A coroutine function may await other services while the node's executor spins on (rclpy's
    SingleThreadedExecutor runs it as a task); a plain function suits any executor (the
    events executor of the loop's nodes calls service callbacks synchronously only).
    """
    from zeus_msgs.srv import SwapCheckpoint

    def refuse(response: Any, error: Exception) -> Any:
        if not isinstance(error, ValueError):  # a request must not end the node
            node.get_logger().error(f'{name}: {type(error).__name__}: {error}')
        response.success, response.message = False, f'{node.get_name()}: {error}'
        return response

    def fill(response: Any, result: tuple[str, str]) -> Any:
        response.success = True
        response.message, response.sha256 = result
        return response

    async def serve_async(request: Any, response: Any) -> Any:
        try:
            result = swap(request.checkpoint, request.expect_sha256)
            assert inspect.isawaitable(result)
            return fill(response, await result)
        except Exception as error:
            return refuse(response, error)

    def serve(request: Any, response: Any) -> Any:
        try:
            result = swap(request.checkpoint, request.expect_sha256)
            assert not inspect.isawaitable(result)
            return fill(response, result)
        except Exception as error:
            return refuse(response, error)

    callback = serve_async if inspect.iscoroutinefunction(swap) else serve
    return node.create_service(SwapCheckpoint, f'~/{name}', callback)
