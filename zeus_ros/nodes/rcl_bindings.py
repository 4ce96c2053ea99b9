"""rcl's C functions that rclpy in Jazzy does not expose, bound with ctypes.

Two callers need them: senders.py takes each message with its full message info (the
publisher's GID), and handshake.py, health.py and intra_process.py name the GIDs of the node's
own publishers. They live here, below both, so neither imports the other for them.
"""

from __future__ import annotations

import ctypes
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from rclpy.publisher import Publisher

__all__ = ['GID_SIZE', 'TAKE_OK', 'Bytes', 'MessageInfo', 'publisher_gid', 'rcl']

GID_SIZE = 16  # RMW_GID_STORAGE_SIZE in Jazzy's rmw/types.h
TAKE_OK = 0


class Allocator(ctypes.Structure):
    """rcutils_allocator_t."""

    _fields_ = [(name, ctypes.c_void_p) for name in
                ('allocate', 'deallocate', 'reallocate', 'zero_allocate', 'state')]


class Bytes(ctypes.Structure):
    """rcutils_uint8_array_t (= rmw_serialized_message_t)."""

    _fields_ = [('buffer', ctypes.POINTER(ctypes.c_uint8)), ('buffer_length', ctypes.c_size_t),
                ('buffer_capacity', ctypes.c_size_t), ('allocator', Allocator)]


class Gid(ctypes.Structure):
    """rmw_gid_t."""

    _fields_ = [('implementation_identifier', ctypes.c_char_p),
                ('data', ctypes.c_uint8 * GID_SIZE)]


class MessageInfo(ctypes.Structure):
    """rmw_message_info_t of Jazzy."""

    _fields_ = [('source_timestamp', ctypes.c_int64), ('received_timestamp', ctypes.c_int64),
                ('publication_sequence_number', ctypes.c_uint64),
                ('reception_sequence_number', ctypes.c_uint64), ('publisher_gid', Gid),
                ('from_intra_process', ctypes.c_bool)]


class Rcl:
    """The three C functions we need, from the librcl/librcutils rclpy has already loaded."""

    def __init__(self) -> None:
        rcl = ctypes.CDLL('librcl.so')
        rcutils = ctypes.CDLL('librcutils.so')
        self.take = rcl.rcl_take_serialized_message
        self.take.argtypes = [ctypes.c_void_p, ctypes.POINTER(Bytes),
                              ctypes.POINTER(MessageInfo), ctypes.c_void_p]
        self.take.restype = ctypes.c_int32
        self.default_allocator = rcutils.rcutils_get_default_allocator
        self.default_allocator.restype = Allocator
        self.init = rcutils.rcutils_uint8_array_init
        self.init.argtypes = [ctypes.POINTER(Bytes), ctypes.c_size_t,
                              ctypes.POINTER(Allocator)]
        self.fini = rcutils.rcutils_uint8_array_fini
        self.fini.argtypes = [ctypes.POINTER(Bytes)]
        self.rmw_publisher = rcl.rcl_publisher_get_rmw_handle
        self.rmw_publisher.argtypes = [ctypes.c_void_p]
        self.rmw_publisher.restype = ctypes.c_void_p
        self.publisher_gid = rcl.rmw_get_gid_for_publisher  # found through librcl's rmw
        self.publisher_gid.argtypes = [ctypes.c_void_p, ctypes.POINTER(Gid)]
        self.publisher_gid.restype = ctypes.c_int32


_RCL: Rcl | None = None


def rcl() -> Rcl:
    """The bindings, loaded on first use (rclpy has loaded the libraries by then)."""
    global _RCL
    if _RCL is None:
        _RCL = Rcl()
    return _RCL


def publisher_gid(publisher: Publisher) -> bytes:
    """The GID of one of our own publishers: what its messages carry as publisher_gid."""
    gid = Gid()
    with publisher.handle:
        rmw_handle = rcl().rmw_publisher(publisher.handle.pointer)
        if not rmw_handle or rcl().publisher_gid(rmw_handle, ctypes.byref(gid)) != TAKE_OK:
            raise RuntimeError(f'no GID for the publisher of {publisher.topic_name}')
    return bytes(gid.data)
