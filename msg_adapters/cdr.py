"""A small plain-CDR (XCDR1) little-endian writer and reader for the fixed parts of a ROS 2
message.

Layout rules (OMG CDR as used by Fast-CDR / rmw_fastrtps for ROS 2 messages):
- a 4-byte encapsulation header ``00 01 00 00`` (CDR_LE, no options) precedes the body;
- every primitive is aligned to its own size (bool/uint8 1, int32/uint32/float32 4,
  uint64/float64 8) *relative to the start of the body*, i.e. after the 4-byte header;
- a string is a uint32 length that counts the terminating NUL, then the UTF-8 bytes and NUL;
- a sequence is a uint32 element count, then the elements (the first element aligns as its
  first primitive does; an empty sequence adds no padding);
- nested messages are their fields in order, with no padding of their own.

Padding bytes are written as zeros. (Fast-CDR leaves them uninitialised, so
``rclpy.serialization.serialize_message`` may put arbitrary bytes there; everything else is
identical, and any deserializer ignores padding.)

Bulk data (point arrays) is not copied through this writer: :meth:`CdrWriter.hole` reserves
space and returns its offset, and the caller fills it in the final buffer with numpy;
:meth:`CdrReader.array` reads it back as a numpy view.
"""
import ctypes
import struct

import numpy as np

ENCAPSULATION_LE = b'\x00\x01\x00\x00'


class CdrWriter:
    """Writes CDR primitives; offsets are relative to the body start (after the header).

    ``origin`` is the body offset of the first byte this writer produces, so a writer can lay
    out a piece (one marker, say) that will sit at a given position of a larger message.
    """

    def __init__(self, origin=0):
        self._origin = origin
        self._start = origin            # body offset of the pending bytes in _buf
        self._buf = bytearray()
        self._pieces = []               # (body offset, bytes) of the written runs

    @property
    def offset(self):
        """Body offset of the next byte."""
        return self._start + len(self._buf)

    def align(self, n):
        self._buf.extend(bytes(-self.offset % n))

    def _put(self, fmt, size, value):
        self.align(size)
        at = self.offset
        self._buf.extend(struct.pack(fmt, value))
        return at

    def boolean(self, v):
        return self._put('<?', 1, bool(v))

    def uint8(self, v):
        return self._put('<B', 1, v)

    def int32(self, v):
        return self._put('<i', 4, v)

    def uint32(self, v):
        return self._put('<I', 4, v)

    def float32(self, v):
        return self._put('<f', 4, v)

    def uint64(self, v):
        return self._put('<Q', 8, v)

    def float64(self, v):
        return self._put('<d', 8, v)

    def string(self, s):
        """A CDR string; ``s`` must not contain NUL (it would end the string)."""
        data = s.encode('utf-8')
        if b'\x00' in data:
            raise ValueError(f'string {s!r} contains a NUL character')
        at = self.uint32(len(data) + 1)
        self._buf.extend(data)
        self._buf.append(0)
        return at

    def time(self, sec, nanosec):
        """builtin_interfaces/Time or Duration: int32 sec, uint32 nanosec."""
        at = self.int32(sec)
        self.uint32(nanosec)
        return at

    def hole(self, nbytes, align=1):
        """Reserve ``nbytes`` (after aligning) to be filled later; returns their body offset."""
        self.align(align)
        at = self.offset
        if self._buf:
            self._pieces.append((self._start, bytes(self._buf)))
        self._buf = bytearray()
        self._start = at + nbytes
        return at

    def pieces(self):
        """The written runs as ``[(body offset, bytes)]``; holes lie between them."""
        out = list(self._pieces)
        if self._buf:
            out.append((self._start, bytes(self._buf)))
        return out

    def template(self):
        """All bytes from ``origin`` to :attr:`offset`, holes zero-filled (for small pieces)."""
        out = bytearray(self.offset - self._origin)
        for at, data in self.pieces():
            out[at - self._origin:at - self._origin + len(data)] = data
        return bytes(out)


class CdrReader:
    """Reads the CDR primitives of one serialized message (``bytes``, a ``memoryview`` or a uint8
    array, encapsulation header included) in field order.

    Little-endian plain CDR only; ValueError names ``what`` (the message type) when the header is
    another encapsulation or the data ends before a field does.
    """

    def __init__(self, data, what='message'):
        self._data = memoryview(data).cast('B')
        self._what = what
        if len(self._data) < len(ENCAPSULATION_LE):
            raise ValueError(f'{what}: {len(self._data)} bytes are no CDR message')
        head = bytes(self._data[:2])
        if head != ENCAPSULATION_LE[:2]:
            raise ValueError(f'{what}: encapsulation {head.hex()} is not little-endian plain CDR '
                             f'({ENCAPSULATION_LE[:2].hex()})')
        self._at = 0                    # body offset of the next byte

    @property
    def remaining(self):
        """Body bytes after the last one read."""
        return len(self._data) - len(ENCAPSULATION_LE) - self._at

    def _take(self, size, align, field):
        self._at += -self._at % align
        start = len(ENCAPSULATION_LE) + self._at
        if start + size > len(self._data):
            raise ValueError(f'{self._what}: the data ends at byte {len(self._data)}, inside '
                             f'{field} (bytes {start}..{start + size})')
        self._at += size
        return start

    def _get(self, fmt, size, field):
        return struct.unpack_from(fmt, self._data, self._take(size, size, field))[0]

    def int32(self, field='int32'):
        return self._get('<i', 4, field)

    def uint32(self, field='uint32'):
        return self._get('<I', 4, field)

    def uint64(self, field='uint64'):
        return self._get('<Q', 8, field)

    def float64(self, field='float64'):
        return self._get('<d', 8, field)

    def string(self, field='string'):
        """A CDR string (its length counts the terminating NUL)."""
        n = self.uint32(field)
        start = self._take(n, 1, field)
        raw = bytes(self._data[start:start + n])
        if not n or raw[-1] != 0:
            raise ValueError(f'{self._what}: {field} is not a NUL-terminated CDR string')
        return raw[:-1].decode('utf-8')

    def time(self, field='stamp'):
        """builtin_interfaces/Time or Duration -> ``(sec, nanosec)``."""
        return self.int32(field + '.sec'), self.uint32(field + '.nanosec')

    def array(self, dtype, count, field='array'):
        """``count`` elements of the little-endian numpy ``dtype`` (aligned to its item size) as
        a read-only view of the data."""
        dt = np.dtype(dtype)
        start = self._take(count * dt.itemsize, dt.itemsize, field)
        out = np.frombuffer(self._data, dtype=dt, count=count, offset=start)
        out.flags.writeable = False
        return out


def _bytes_allocator():
    """CPython's ``PyBytes_FromStringAndSize(NULL, n)`` and ``PyBytes_AsString`` via ctypes.

    The C API's way to build a ``bytes`` object in place: create it uninitialised, fill it,
    then hand it out. It saves a full copy of the message (``ndarray.tobytes``), which
    ``Publisher.publish`` would otherwise need because it accepts only ``bytes``. None where
    the interpreter has no ``pythonapi`` (not CPython); callers then copy.
    """
    try:
        api = ctypes.pythonapi
        new = api.PyBytes_FromStringAndSize
        as_string = api.PyBytes_AsString
    except (AttributeError, OSError):
        return None
    new.restype, new.argtypes = ctypes.py_object, (ctypes.c_void_p, ctypes.c_ssize_t)
    as_string.restype, as_string.argtypes = ctypes.c_void_p, (ctypes.py_object,)
    return new, as_string


_ALLOC = _bytes_allocator()


class MessageBuffer:
    """A serialized message under construction: ``body`` is a writable uint8 view.

    ``finish()`` returns the ``bytes``; with CPython they are written in place (no copy), and
    the views must not be used after ``finish()``. Every body byte must be written by the
    caller (the memory starts uninitialised).
    """

    def __init__(self, body_size):
        size = body_size + len(ENCAPSULATION_LE)
        if _ALLOC is not None and size > 1:
            self._bytes = _ALLOC[0](None, size)
            addr = _ALLOC[1](self._bytes)
            self._msg = np.frombuffer((ctypes.c_ubyte * size).from_address(addr), np.uint8)
        else:
            self._bytes = None
            self._msg = np.empty(size, dtype=np.uint8)
        self._msg[:4] = np.frombuffer(ENCAPSULATION_LE, dtype=np.uint8)
        self.body = self._msg[4:]

    def finish(self):
        out = self._bytes if self._bytes is not None else self._msg.tobytes()
        self._msg = self.body = self._bytes = None
        return out


def put_pieces(body, pieces):
    """Copy ``pieces()`` of a CdrWriter into the body view."""
    for at, data in pieces:
        body[at:at + len(data)] = np.frombuffer(data, dtype=np.uint8)
