"""`SenderSubscription`: a subscription that sees each message's publisher GID.

rclpy in Jazzy does not hand `rmw_message_info_t.publisher_gid` to Python (rclpy#1466 adds it
in later releases), so each message is taken through rcl's serialized take with ctypes, which
fills the whole message info, and deserialized with rclpy. Its own module so that the pairing
(senders.py) and the hellos it relies on (handshake.py) both use it without importing each
other.
"""

from __future__ import annotations

from collections.abc import Callable
import ctypes
from typing import TYPE_CHECKING, Any

from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.serialization import deserialize_message
from rclpy.type_support import check_is_valid_msg_type
from rclpy.waitable import NumberOfEntities, Waitable

from zeus_ros.nodes.rcl_bindings import TAKE_OK, Bytes, MessageInfo, rcl

if TYPE_CHECKING:
    from rclpy.callback_groups import CallbackGroup
    from rclpy.event_handler import SubscriptionEventCallbacks
    from rclpy.node import Node
    from rclpy.qos import QoSProfile

__all__ = ['SenderSubscription', 'raise_callback_error']

_TAKE_EMPTY = 401  # RCL_RET_SUBSCRIPTION_TAKE_FAILED: nothing to take
_MAX_TAKE = 256  # per wake-up: a flood cannot keep the executor in one callback forever


_ERROR_KEY = '_zeus_callback_error'


def raise_callback_error(node: Node) -> None:
    """Raise the exception a SenderSubscription callback of `node` raised (if any), here."""
    error = node.__dict__.pop(_ERROR_KEY, None)
    if error is not None:
        raise error


class SenderSubscription(Waitable):
    """A subscription that admits only messages whose publisher GID `admit` accepts.

    A refused message is never deserialized: a flood costs one C call per message, so the
    paired sender's messages are taken before the reader's history overflows. Resolves its
    topic like `create_subscription` (namespace, remaps) and shows in the graph like any
    subscription. `destroy()` before the node is destroyed.

    In a node of the single-process container (`node.intra_process`, nodes/intra_process.py)
    it also receives the messages of the container's publishers as Python objects, through the
    container's bus, and drops their DDS copies here, unread. `event_callbacks` adds rclpy's
    QoS event handlers (as `create_subscription` does; None: none). `with_sender`: the
    callback gets `(msg, gid)`, for a consumer that must know who sent each message (the
    start hellos: handshake.py).
    """

    def __init__(self, node: Node, msg_type: Any, topic: str, qos: QoSProfile,
                 callback: Callable[..., None], admit: Callable[[bytes], bool], *,
                 callback_group: CallbackGroup | None = None,
                 event_callbacks: SubscriptionEventCallbacks | None = None,
                 with_sender: bool = False) -> None:
        check_is_valid_msg_type(msg_type)
        with node.handle:
            self._handle = _rclpy.Subscription(node.handle, msg_type, topic,
                                               qos.get_c_qos_profile())
        super().__init__(callback_group or node.default_callback_group)
        self._node = node
        self.msg_type = msg_type
        self.qos = qos
        self.callback = callback
        self.admit = admit
        self.with_sender = with_sender
        self._index: int | None = None
        self._destroyed = False
        self._buffer = Bytes()
        allocator = rcl().default_allocator()
        if rcl().init(ctypes.byref(self._buffer), 256, ctypes.byref(allocator)) != TAKE_OK:
            raise MemoryError('could not allocate a serialized-message buffer')
        self._events = [] if event_callbacks is None else event_callbacks.create_event_handlers(
            self.callback_group, self._handle, self.topic_name)
        node.add_waitable(self)
        for handler in self._events:
            node.add_waitable(handler)
        self._bus = getattr(node, 'intra_process', None)
        self._local: set[bytes] | frozenset[bytes] = frozenset()  # GIDs delivered by the bus
        if self._bus is not None:
            self._local = self._bus.add_subscription(self)

    @property
    def topic_name(self) -> str:
        """The resolved topic name (namespace and remaps applied)."""
        with self._handle:
            return self._handle.get_topic_name()

    def get_publisher_count(self) -> int:
        """Publishers DDS has matched with this subscription."""
        with self._handle:
            return self._handle.get_publisher_count()

    def destroy(self) -> None:
        """Leave the executor and the bus; free the subscription and its buffer (once)."""
        if self._destroyed:
            return
        self._destroyed = True
        if self._bus is not None:
            self._bus.remove_subscription(self)
        for handler in self._events:
            self._node.remove_waitable(handler)
            handler.destroy()
        self._node.remove_waitable(self)
        self._handle.destroy_when_not_in_use()
        rcl().fini(ctypes.byref(self._buffer))

    # -- Waitable API (called by the executor) ---------------------------------------------
    def __enter__(self) -> None:
        self._handle.__enter__()

    def __exit__(self, *exc: object) -> None:
        self._handle.__exit__(*exc)

    def is_ready(self, wait_set: Any) -> bool:
        """True when the wait set says a message is waiting."""
        return self._index is not None and wait_set.is_ready('subscription', self._index)

    def deliver(self, msg: Any, gid: bytes) -> None:
        """Hand one admitted message (sent by publisher `gid`) to the callback."""
        if self.with_sender:
            self.callback(msg, gid)
        else:
            self.callback(msg)

    def take_data(self) -> list[tuple[Any, bytes]]:
        """Take what is waiting (at most _MAX_TAKE); keep the admitted messages and senders."""
        taken = []
        info = MessageInfo()
        for _ in range(_MAX_TAKE):
            with self._handle:
                result = rcl().take(self._handle.pointer, ctypes.byref(self._buffer),
                                     ctypes.byref(info), None)
            if result == _TAKE_EMPTY:
                break
            if result != TAKE_OK:
                raise RuntimeError(f'rcl_take_serialized_message on {self.topic_name} '
                                   f'returned {result}')
            gid = bytes(info.publisher_gid.data)
            if gid not in self._local and self.admit(gid):  # the bus delivered a local one
                data = ctypes.string_at(self._buffer.buffer, self._buffer.buffer_length)
                taken.append((deserialize_message(data, self.msg_type), gid))
        return taken

    async def execute(self, taken_data: list[tuple[Any, bytes]]) -> None:
        """Hand each admitted message to the callback.

        An exception the callback raises is kept on the node and raised again by the spin
        loop (`raise_callback_error`): out of a Waitable, rclpy's EventsExecutor (Jazzy)
        turns it into a SIGSEGV with no traceback (measured: `PyUnicode_FromString(NULL)` in
        _rclpy_pybind11), where a plain subscription's exception reaches `spin_once`.
        """
        try:
            for msg, gid in taken_data:
                self.deliver(msg, gid)
        except Exception as error:  # re-raised by the spin loop
            self._node.__dict__.setdefault(_ERROR_KEY, error)

    def get_num_entities(self) -> NumberOfEntities:
        """One subscription."""
        return NumberOfEntities(num_subs=1)

    def add_to_wait_set(self, wait_set: Any) -> None:
        """Add the subscription; remember its index."""
        self._index = wait_set.add_subscription(self._handle)
