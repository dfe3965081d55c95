"""Publish serialized (CDR) messages through rcl itself, with the GIL released.

rclpy's raw publish holds the GIL for the whole transfer: ``Publisher.publish(bytes)`` first
copies the bytes into a ``std::string`` (pybind11's argument conversion), then calls
``rcl_publish_serialized_message``, which hands them to the middleware (Fast DDS copies them
into its history and, for a reader in the same process, into the reader's).  With a 3.2 MB
cloud (10 k strands x 16 points) those copies take milliseconds, and every other Python thread
of the process waits for them.

:class:`SerializedPublisher` calls the same rcl function through :mod:`ctypes`, which releases
the GIL for the duration of a foreign call, from the caller's buffer in place (``bytes``,
``bytearray``, a ``memoryview`` or a contiguous uint8 numpy array): one copy less, and the
middleware's copies run without the GIL.  The buffer may be reused as soon as ``publish``
returns: rcl's publish is synchronous (rclpy's own raw publish relies on the same: its
``std::string`` is freed on return).

The entry point is part of rcl's public C API (``rcl/publisher.h``; the message struct is
``rcutils_uint8_array_t``), but rclpy has no public way to it: the structure layouts are
written out here by hand, and the rcl pointer is read from the publisher's handle
(``Publisher.handle.pointer``) after loading rcl through ``rclpy.impl``, neither of which is
rclpy's public API.  So the direct path is opt-in (``SerializedPublisher(..., direct=True)``,
the node's ``publish_through_rcl``) and used only with the rclpy release it was verified
against (:data:`VERIFIED_RCLPY`); with any other release, or where ``librcl`` cannot be found
in the process, :func:`unusable_reason` says why and the publisher keeps rclpy's own
``publish``.  Linux only: the libraries are located through the process's own memory map when
the dynamic loader does not know them by name.  (``scripts/rcl_take.py`` takes messages the
same way, for the benchmarks' probes.)
"""
import ctypes
import importlib.metadata
import os
from typing import Optional

import numpy as np

#: The rclpy release (Jazzy) whose rcl structures and handles this module was verified against.
VERIFIED_RCLPY = '7.1.5'


class Allocator(ctypes.Structure):
    """``rcutils_allocator_t``."""

    _fields_ = [('allocate', ctypes.c_void_p), ('deallocate', ctypes.c_void_p),
                ('reallocate', ctypes.c_void_p), ('zero_allocate', ctypes.c_void_p),
                ('state', ctypes.c_void_p)]


class Uint8Array(ctypes.Structure):
    """``rcutils_uint8_array_t`` = ``rcl_serialized_message_t``."""

    _fields_ = [('buffer', ctypes.c_void_p), ('buffer_length', ctypes.c_size_t),
                ('buffer_capacity', ctypes.c_size_t), ('allocator', Allocator)]


class _ErrorString(ctypes.Structure):
    """``rcutils_error_string_t`` (``RCUTILS_ERROR_MESSAGE_MAX_LENGTH`` = 1024)."""

    _fields_ = [('str', ctypes.c_char * 1024)]


RET_OK = 0


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
    """(librcl, librcutils) with the argument types of the publish and of rcutils' error
    string set, or None when either is missing."""
    from rclpy.impl.implementation_singleton import rclpy_implementation  # noqa: F401 (loads rcl)
    try:
        rcl, rcutils = _load('librcl.so'), _load('librcutils.so')
    except OSError:
        return None
    if rcl is None or rcutils is None:
        return None
    try:
        rcl.rcl_publish_serialized_message.argtypes = [
            ctypes.c_void_p, ctypes.POINTER(Uint8Array), ctypes.c_void_p]
        rcl.rcl_publish_serialized_message.restype = ctypes.c_int
        rcutils.rcutils_get_error_string.restype = _ErrorString
        rcutils.rcutils_reset_error.restype = None
    except AttributeError:
        return None
    return rcl, rcutils


_LIBS = None
_BOUND = False


def libraries():
    """(librcl, librcutils) as loaded in this process (ctypes), None where they are not."""
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
    if libraries() is None:
        return 'librcl / librcutils are not loaded in this process'
    if publisher is not None and not hasattr(publisher.handle, 'pointer'):
        return 'the rclpy publisher does not expose its rcl pointer'
    return None


def available() -> bool:
    """True when rcl's serialized publish can be called directly in this process."""
    return unusable_reason() is None


def rcl_error(what: str, ret: int) -> RuntimeError:
    """rcl's error message for a failed call, as an exception (the error state is reset)."""
    rcutils = libraries()[1]
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
        msg = Uint8Array()
        msg.buffer = view.ctypes.data
        msg.buffer_length = msg.buffer_capacity = view.size
        handle = self.publisher.handle
        publish = libraries()[0].rcl_publish_serialized_message
        with handle:                    # keeps the publisher alive during the call
            ret = publish(handle.pointer, ctypes.byref(msg), None)
        if ret != RET_OK:
            raise rcl_error(f'publishing on {self.publisher.topic_name}', ret)
