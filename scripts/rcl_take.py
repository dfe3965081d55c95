"""The benchmarks' probes: take serialized messages through rcl itself, the GIL released.

rclpy's raw take (``create_subscription(..., raw=True)``) lets the middleware copy the message
into a freshly allocated buffer, then copies that into a new ``bytes`` object, holding the GIL:
with a 3.2 MB cloud those copies take milliseconds, and in ``bench_latency.py`` the probe's
take of one cloud kept the node it measures from starting on the next pose.  A C++ subscriber
would not stall it so; these classes take the way it would:

* :class:`SerializedTaker` calls ``rcl_take_serialized_message`` through :mod:`ctypes` (which
  releases the GIL for the call) into one buffer it keeps, grown when a message is larger, and
  returns a read-only view of it, valid until the next take;
* :class:`SerializedWaiter` waits until one of some subscriptions has a message: the wait set an
  executor would build for them (``rclpy.impl``'s ``WaitSet``, as ``rclpy.executors`` uses it).

Both reach past rclpy's public API, as :mod:`msg_adapters.rcl_serialized`'s publisher does,
whose loading of rcl and structure layouts they share; measurement only, not the product.
"""
import ctypes
from typing import Optional

from msg_adapters import rcl_serialized as rs

#: ``rmw_message_info_t`` is 72 bytes in Jazzy; room to spare for other versions.
MESSAGE_INFO_BYTES = 256
RET_TAKE_FAILED = 401          # RCL_RET_SUBSCRIPTION_TAKE_FAILED: nothing to take


def _take_functions():
    """(take, array init, array fini, default allocator) of the loaded rcl / rcutils."""
    rcl, rcutils = rs.libraries()
    take = rcl.rcl_take_serialized_message
    take.argtypes = [ctypes.c_void_p, ctypes.POINTER(rs.Uint8Array), ctypes.c_void_p,
                     ctypes.c_void_p]
    take.restype = ctypes.c_int
    init, fini = rcutils.rcutils_uint8_array_init, rcutils.rcutils_uint8_array_fini
    init.argtypes = [ctypes.POINTER(rs.Uint8Array), ctypes.c_size_t,
                     ctypes.POINTER(rs.Allocator)]
    init.restype = ctypes.c_int
    fini.argtypes = [ctypes.POINTER(rs.Uint8Array)]
    fini.restype = ctypes.c_int
    allocator = rcutils.rcutils_get_default_allocator
    allocator.restype = rs.Allocator
    return take, init, fini, allocator


class SerializedTaker:
    """Take serialized messages of an rclpy subscription through rcl, the GIL released, into
    one reused buffer.

    The subscription must not also be spun by an executor (the executor would take the
    messages first); wait for it with a :class:`SerializedWaiter` and call :meth:`take` until
    it returns None.
    """

    def __init__(self, subscription, capacity: int = 1 << 20):
        reason = rs.unusable_reason()
        if reason is not None:
            raise RuntimeError(f'rcl cannot be called directly here: {reason}')
        self.subscription = subscription
        self._take, init, self._fini, allocator = _take_functions()
        self._msg = rs.Uint8Array()
        alloc = allocator()
        ret = init(ctypes.byref(self._msg), max(1, int(capacity)), ctypes.byref(alloc))
        if ret != rs.RET_OK:
            raise rs.rcl_error('allocating the take buffer', ret)
        self._info = ctypes.create_string_buffer(MESSAGE_INFO_BYTES)

    def take(self) -> Optional[memoryview]:
        """The next message's CDR bytes as a read-only view of the buffer (valid until the next
        take), or None when nothing is waiting."""
        if self._msg.buffer is None:
            raise RuntimeError('take after close()')
        handle = self.subscription.handle
        with handle:
            ret = self._take(handle.pointer, ctypes.byref(self._msg), self._info, None)
        if ret == RET_TAKE_FAILED:
            return None
        if ret != rs.RET_OK:
            raise rs.rcl_error(f'taking from {self.subscription.topic_name}', ret)
        n = self._msg.buffer_length
        return memoryview((ctypes.c_char * n).from_address(self._msg.buffer)).toreadonly()

    def close(self) -> None:
        if self._msg.buffer is not None:
            self._fini(ctypes.byref(self._msg))
            self._msg.buffer = None

    def __del__(self):
        try:
            self.close()
        except Exception:                  # interpreter shutdown: nothing left to free into
            pass


class SerializedWaiter:
    """Wait, with the GIL released, until one of some subscriptions has a message: the wait
    set an executor would build for them, for subscriptions read with :class:`SerializedTaker`
    instead of a callback."""

    def __init__(self, context, subscriptions):
        from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
        self.context = context
        self.subscriptions = list(subscriptions)
        self._wait_set = _rclpy.WaitSet(len(self.subscriptions), 0, 0, 0, 0, 0, context.handle)

    def wait(self, timeout_sec: float):
        """The subscriptions with a message waiting (possibly none, after ``timeout_sec``)."""
        ws = self._wait_set
        handles = [s.handle for s in self.subscriptions]
        with self.context.handle:
            for h in handles:
                h.__enter__()
            try:
                ws.clear_entities()
                for h in handles:
                    ws.add_subscription(h)
                ws.wait(int(timeout_sec * 1e9))
                ready = set(ws.get_ready_entities('subscription'))
            finally:
                for h in handles:
                    h.__exit__(None, None, None)
        return [s for s, h in zip(self.subscriptions, handles) if h.pointer in ready]
