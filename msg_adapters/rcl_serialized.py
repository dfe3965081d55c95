"""Publish and take serialized (CDR) messages through rcl itself, with the GIL released.

rclpy's raw paths hold the GIL for the whole transfer: ``Publisher.publish(bytes)`` first copies
the bytes into a ``std::string`` (pybind11's argument conversion), then calls
``rcl_publish_serialized_message``, which hands them to the middleware (Fast DDS copies them
into its history and, for a reader in the same process, into the reader's); a raw take
(``create_subscription(..., raw=True)``) lets the middleware copy the message into a freshly
allocated buffer and then copies that into a new ``bytes`` object.  With a 3.2 MB cloud (10 k
strands x 16 points) those copies take milliseconds, and every other Python thread of the
process waits for them: in ``scripts/bench_latency.py`` the probe's take of one cloud kept the
node from starting on the next pose.

The same two rcl functions are called here through :mod:`ctypes`, which releases the GIL for
the duration of a foreign call:

* :class:`SerializedPublisher` publishes from the caller's buffer in place (``bytes``,
  ``bytearray``, a ``memoryview`` or a contiguous uint8 numpy array): one copy less, and the
  middleware's copies run without the GIL.  The buffer may be reused as soon as ``publish``
  returns: rcl's publish is synchronous (rclpy's own raw publish relies on the same: its
  ``std::string`` is freed on return).
* :class:`SerializedTaker` takes into one buffer it keeps (grown when a message is larger),
  and returns a read-only view of it, valid until the next take.

The entry points are part of rcl's public C API (``rcl/publisher.h``, ``rcl/subscription.h``;
the message struct is ``rcutils_uint8_array_t``), but the structure layouts are written out here
by hand and the rcl pointer is read from rclpy's handle, which is not rclpy's public API.  So the
direct path is opt-in (``SerializedPublisher(..., direct=True)``, the node's
``publish_through_rcl``) and used only with the rclpy release it was verified against
(:data:`VERIFIED_RCLPY`); with any other release, or where ``librcl`` cannot be found in the
process, :func:`unusable_reason` says why and the publisher keeps rclpy's own ``publish``.
Linux only: the libraries are located through the process's own memory map when the dynamic
loader does not know them by name.
"""
import ctypes
import importlib.metadata
import os
from typing import Optional

import numpy as np

#: The rclpy release (Jazzy) whose rcl structures and handles this module was verified against.
VERIFIED_RCLPY = '7.1.5'


class _Allocator(ctypes.Structure):
    """``rcutils_allocator_t``."""

    _fields_ = [('allocate', ctypes.c_void_p), ('deallocate', ctypes.c_void_p),
                ('reallocate', ctypes.c_void_p), ('zero_allocate', ctypes.c_void_p),
                ('state', ctypes.c_void_p)]


class _Uint8Array(ctypes.Structure):
    """``rcutils_uint8_array_t`` = ``rcl_serialized_message_t``."""

    _fields_ = [('buffer', ctypes.c_void_p), ('buffer_length', ctypes.c_size_t),
                ('buffer_capacity', ctypes.c_size_t), ('allocator', _Allocator)]


class _ErrorString(ctypes.Structure):
    """``rcutils_error_string_t`` (``RCUTILS_ERROR_MESSAGE_MAX_LENGTH`` = 1024)."""

    _fields_ = [('str', ctypes.c_char * 1024)]


#: ``rmw_message_info_t`` is 72 bytes in Jazzy; room to spare for other versions.
_MESSAGE_INFO_BYTES = 256
_RET_OK = 0
_RET_TAKE_FAILED = 401          # RCL_RET_SUBSCRIPTION_TAKE_FAILED: nothing to take


def _mapped_library(name: str) -> Optional[str]:
    """Path of an already loaded shared library ``name`` (e.g. ``librcl.so``), from
    ``/proc/self/maps``; None if it is not mapped."""
    try:
        with open('/proc/self/maps', encoding='utf-8', errors='replace') as f:
            for line in f:
                path = line.rsplit(None, 1)[-1]
                if os.path.basename(path) == name:
                    return path
    except OSError:
        pass
    return None


def _load(name: str):
    try:
        return ctypes.CDLL(name)           # known to the loader (LD_LIBRARY_PATH, a ROS install)
    except OSError:
        path = _mapped_library(name)       # the pip wheels: loaded by rclpy from its own path
        return ctypes.CDLL(path) if path else None


def _bind():
    """(librcl, librcutils) with argument types set, or None when either is missing."""
    from rclpy.impl.implementation_singleton import rclpy_implementation  # noqa: F401 (loads rcl)
    try:
        rcl, rcutils = _load('librcl.so'), _load('librcutils.so')
    except OSError:
        return None
    if rcl is None or rcutils is None:
        return None
    try:
        rcl.rcl_publish_serialized_message.argtypes = [
            ctypes.c_void_p, ctypes.POINTER(_Uint8Array), ctypes.c_void_p]
        rcl.rcl_publish_serialized_message.restype = ctypes.c_int
        rcl.rcl_take_serialized_message.argtypes = [
            ctypes.c_void_p, ctypes.POINTER(_Uint8Array), ctypes.c_void_p, ctypes.c_void_p]
        rcl.rcl_take_serialized_message.restype = ctypes.c_int
        rcutils.rcutils_get_default_allocator.restype = _Allocator
        rcutils.rcutils_get_error_string.restype = _ErrorString
        rcutils.rcutils_reset_error.restype = None
        rcutils.rcutils_uint8_array_init.argtypes = [
            ctypes.POINTER(_Uint8Array), ctypes.c_size_t, ctypes.POINTER(_Allocator)]
        rcutils.rcutils_uint8_array_init.restype = ctypes.c_int
        rcutils.rcutils_uint8_array_fini.argtypes = [ctypes.POINTER(_Uint8Array)]
        rcutils.rcutils_uint8_array_fini.restype = ctypes.c_int
    except AttributeError:
        return None
    return rcl, rcutils


_LIBS = None
_BOUND = False


def _libs():
    global _LIBS, _BOUND
    if not _BOUND:
        _LIBS, _BOUND = _bind(), True
    return _LIBS


def rclpy_version() -> Optional[str]:
    """The installed rclpy's version (its package metadata), None if it has none."""
    try:
        return importlib.metadata.version('rclpy')
    except importlib.metadata.PackageNotFoundError:
        return None


def unusable_reason(publisher=None) -> Optional[str]:
    """Why rcl cannot be called directly here (for ``publisher``, if given), or None."""
    version = rclpy_version()
    if version != VERIFIED_RCLPY:
        return (f'rclpy {version or "of unknown version"} is not {VERIFIED_RCLPY}, the release '
                'the direct rcl path was verified against')
    if _libs() is None:
        return 'librcl / librcutils are not loaded in this process'
    if publisher is not None and not hasattr(publisher.handle, 'pointer'):
        return 'the rclpy publisher does not expose its rcl pointer'
    return None


def available() -> bool:
    """True when rcl's serialized publish and take can be called directly in this process."""
    return unusable_reason() is None


def _rcl_error(what: str, ret: int) -> RuntimeError:
    rcutils = _libs()[1]
    text = rcutils.rcutils_get_error_string().str.decode('utf-8', 'replace')
    rcutils.rcutils_reset_error()
    return RuntimeError(f'{what} failed (rcl return code {ret}): {text}')


def _byte_view(data) -> np.ndarray:
    """A flat uint8 view of ``data``'s memory (no copy); the buffer must be contiguous."""
    view = np.frombuffer(data, dtype=np.uint8) if not isinstance(data, np.ndarray) else data
    if view.dtype != np.uint8 or view.ndim != 1 or not view.flags.c_contiguous:
        raise TypeError('serialized data must be bytes, a bytearray or a contiguous 1-d uint8 '
                        f'array, got {type(data).__name__} {getattr(data, "dtype", "")}')
    return view


class SerializedPublisher:
    """Publish serialized messages of an rclpy publisher through rcl, the GIL released."""

    def __init__(self, publisher, direct: bool = False):
        """``direct``: False (default) = rclpy's own ``publish``; True = through rcl where
        :func:`unusable_reason` finds nothing against it, else rclpy's ``publish`` (the reason
        is in :attr:`reason`)."""
        self.publisher = publisher
        #: why the direct path cannot be used here (None where it can)
        self.reason = unusable_reason(publisher)
        self._direct = bool(direct) and self.reason is None

    @property
    def direct(self) -> bool:
        """Whether :meth:`publish` goes through rcl directly (else rclpy's ``publish``)."""
        return self._direct

    @direct.setter
    def direct(self, value: bool) -> None:
        """Asking for rcl where it cannot be used keeps rclpy's path (see :attr:`reason`)."""
        self._direct = bool(value) and self.reason is None

    def publish(self, data) -> None:
        """Publish ``data``, the CDR bytes of one message of the publisher's type."""
        if not self._direct:
            self.publisher.publish(data if isinstance(data, bytes) else bytes(data))
            return
        view = _byte_view(data)
        msg = _Uint8Array()
        msg.buffer = view.ctypes.data
        msg.buffer_length = msg.buffer_capacity = view.size
        handle = self.publisher.handle
        publish = _libs()[0].rcl_publish_serialized_message
        with handle:                    # keeps the publisher alive during the call
            ret = publish(handle.pointer, ctypes.byref(msg), None)
        if ret != _RET_OK:
            raise _rcl_error(f'publishing on {self.publisher.topic_name}', ret)


class SerializedTaker:
    """Take serialized messages of an rclpy subscription through rcl, the GIL released, into
    one reused buffer.

    The subscription must not also be spun by an executor (the executor would take the
    messages first); wait for it with a wait set (:class:`SerializedWaiter`) and call
    :meth:`take` until it returns None.
    """

    def __init__(self, subscription, capacity: int = 1 << 20):
        reason = unusable_reason()
        if reason is not None:
            raise RuntimeError(f'rcl cannot be called directly here: {reason}')
        self.subscription = subscription
        rcutils = _libs()[1]
        self._msg = _Uint8Array()
        alloc = rcutils.rcutils_get_default_allocator()
        ret = rcutils.rcutils_uint8_array_init(ctypes.byref(self._msg), max(1, int(capacity)),
                                               ctypes.byref(alloc))
        if ret != _RET_OK:
            raise _rcl_error('allocating the take buffer', ret)
        self._info = ctypes.create_string_buffer(_MESSAGE_INFO_BYTES)

    def take(self) -> Optional[memoryview]:
        """The next message's CDR bytes as a read-only view of the buffer (valid until the next
        take), or None when nothing is waiting."""
        if self._msg.buffer is None:
            raise RuntimeError('take after close()')
        handle = self.subscription.handle
        take = _libs()[0].rcl_take_serialized_message
        with handle:
            ret = take(handle.pointer, ctypes.byref(self._msg), self._info, None)
        if ret == _RET_TAKE_FAILED:
            return None
        if ret != _RET_OK:
            raise _rcl_error(f'taking from {self.subscription.topic_name}', ret)
        n = self._msg.buffer_length
        return memoryview((ctypes.c_char * n).from_address(self._msg.buffer)).toreadonly()

    def close(self) -> None:
        if self._msg.buffer is not None:
            _libs()[1].rcutils_uint8_array_fini(ctypes.byref(self._msg))
            self._msg.buffer = None

    def __del__(self):
        try:
            self.close()
        except Exception:                  # interpreter shutdown: nothing left to free into
            pass


class SerializedWaiter:
    """Wait, with the GIL released, until one of some subscriptions has a message: the wait
    set an executor would build for them, for subscriptions read with :class:`SerializedTaker`
    instead of a callback (rclpy's ``WaitSet``, as ``rclpy.executors`` uses it)."""

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
