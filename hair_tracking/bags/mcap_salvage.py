"""MCAP files cut short: the records before the cut, closed into a file other readers accept.

A recorder that dies (killed, out of disk, power lost) leaves an MCAP file without its summary,
footer and closing magic, which rosbags and ``ros2 bag`` refuse ("File end magic is invalid").
:func:`salvage` reads such a file record by record and writes a copy that ends properly: every
whole record, in file order, then a Data End record, a Footer without a summary and the magic.
Readers index such a file by scanning it (rosbags does).

The record layout is that of the MCAP specification (https://mcap.dev/spec): the 8-byte magic
``\\x89MCAP0\\r\\n``, then records of an opcode (uint8), a content length (uint64) and the
content, little-endian; strings are a uint32 length and UTF-8 bytes.  A Chunk record (opcode
0x06) holds message start and end times (uint64), the uncompressed size (uint64) and CRC-32
(uint32), the compression ('' , 'zstd' or 'lz4') and the length-prefixed (uint64) records:
Schema (0x03), Channel (0x04) and Message (0x05; channel id uint16, sequence uint32, log time
uint64, publish time uint64, data).  A chunk the file ends inside keeps its whole records: its
data are decompressed as far as they go (zstd and lz4 frames decode block by block) and the
whole records are written again as an uncompressed chunk.

What is not a cut raises :class:`McapError` naming the byte offset and what was expected: a
file without the magic, a first record that is no Header, a chunk of an unknown compression or
whose data do not decompress.  Zeros where a record should start (a file system that kept the
file's length but not its last writes) end the data like a cut.
"""
from binascii import crc32
from dataclasses import dataclass
import os
import struct
import sys

MAGIC = b'\x89MCAP0\r\n'

#: MCAP record names by opcode (for messages)
RECORDS = {0x01: 'Header', 0x02: 'Footer', 0x03: 'Schema', 0x04: 'Channel', 0x05: 'Message',
           0x06: 'Chunk', 0x07: 'Message Index', 0x08: 'Chunk Index', 0x09: 'Attachment',
           0x0A: 'Attachment Index', 0x0B: 'Statistics', 0x0C: 'Metadata',
           0x0D: 'Metadata Index', 0x0E: 'Summary Offset', 0x0F: 'Data End'}
HEADER, FOOTER, MESSAGE, CHUNK, DATA_END = 0x01, 0x02, 0x05, 0x06, 0x0F
_RECORD = struct.Struct('<BQ')
_FOOTER_SIZE = 1 + 8 + 20 + len(MAGIC)
_COPY_BLOCK = 1 << 20


class McapError(ValueError):
    """An MCAP file that is damaged, not cut: ``offset`` is the byte where it shows."""

    def __init__(self, offset: int, message: str):
        super().__init__(f'at byte {offset}: {message}')
        self.offset = offset


@dataclass
class Cut:
    """What :func:`salvage` found: the file's ``size``, the bytes of whole records it kept
    (``kept``, from the start of the file), ``stop`` what the file ends inside, and the
    messages taken from a chunk the file ends inside (``partial_messages``)."""

    size: int
    kept: int
    stop: str
    partial_messages: int = 0


def is_cut(path) -> bool:
    """Whether an MCAP file lacks its closing Footer record and magic (a recorder that died)."""
    size = os.path.getsize(path)
    if size < len(MAGIC) + _FOOTER_SIZE:
        return True
    with open(path, 'rb') as fh:
        fh.seek(size - _FOOTER_SIZE)
        tail = fh.read(_FOOTER_SIZE)
    return not (tail.endswith(MAGIC) and tail[0] == FOOTER)


def footer_problem(path) -> str:
    """What is wrong with the Footer record of an MCAP file that has one ('' when nothing is):
    its summary start (uint64 at 9 bytes into the record) must lie between the Header and
    the Footer."""
    size = os.path.getsize(path)
    if is_cut(path):
        return ''
    footer = size - _FOOTER_SIZE
    with open(path, 'rb') as fh:
        fh.seek(footer)
        tail = fh.read(_FOOTER_SIZE)
    op, length = _RECORD.unpack_from(tail)
    if length != 20:
        return (f'at byte {footer}: expected a Footer record of 20 bytes, its length says '
                f'{length}')
    (summary,) = struct.unpack_from('<Q', tail, 9)
    if summary and not len(MAGIC) < summary <= footer:
        return (f'at byte {footer + 9}: the Footer puts the summary at byte {summary}, expected '
                f'one between the Header and the Footer (byte {footer})')
    return ''


def _name(op: int) -> str:
    return f"{RECORDS.get(op, 'unknown')} record (opcode 0x{op:02x})"


def _record(op: int, content: bytes) -> bytes:
    return _RECORD.pack(op, len(content)) + content


def _decompress_prefix(data: bytes, compression: str, offset: int) -> bytes:
    """As much of a compressed chunk's records as ``data`` (a prefix of them) decodes to."""
    if compression == '':
        return data
    try:
        if compression == 'zstd':
            if sys.version_info >= (3, 14):
                from compression import zstd
            else:
                from backports import zstd
            return zstd.ZstdDecompressor().decompress(data)
        if compression == 'lz4':
            from lz4.frame import LZ4FrameDecompressor
            return LZ4FrameDecompressor().decompress(data)
    except Exception as exc:       # noqa: B902 - any decoder's complaint about the data
        raise McapError(offset, f'expected {compression} data in the chunk, the decoder says: '
                                f'{exc}') from None
    raise McapError(offset, f"a chunk compressed with {compression!r}; expected '', 'zstd' or "
                            "'lz4'")


def _partial_chunk(content: bytes, offset: int):
    """``(Chunk record bytes or b'', messages)`` of the whole records in the start ``content``
    of a chunk the file ends inside (``offset``: the chunk record's byte)."""
    fixed = 8 + 8 + 8 + 4
    if len(content) < fixed + 4:
        return b'', 0
    (n,) = struct.unpack_from('<I', content, fixed)
    start = fixed + 4 + n + 8
    if len(content) < start:
        return b'', 0
    try:
        compression = content[fixed + 4:fixed + 4 + n].decode()
    except UnicodeDecodeError:
        raise McapError(offset, 'expected the compression name of a chunk (UTF-8)') from None
    (size,) = struct.unpack_from('<Q', content, start - 8)
    raw = _decompress_prefix(content[start:start + size], compression, offset + 9 + start)
    pos, messages, first, last = 0, 0, None, None
    while pos + 9 <= len(raw):
        op, length = _RECORD.unpack_from(raw, pos)
        if op == 0 or pos + 9 + length > len(raw):
            break
        if op == MESSAGE:
            if length < 22:
                raise McapError(offset, f'a Message record of {length} bytes in the chunk; '
                                        'expected at least 22')
            (t,) = struct.unpack_from('<Q', raw, pos + 9 + 6)
            first = t if first is None else min(first, t)
            last = t if last is None else max(last, t)
            messages += 1
        pos += 9 + length
    if pos == 0:
        return b'', 0
    body = raw[:pos]
    head = struct.pack('<QQQI', first or 0, last or 0, len(body), crc32(body))
    return _record(CHUNK, head + struct.pack('<I', 0) + struct.pack('<Q', len(body)) + body), \
        messages


def salvage(path, out_path) -> Cut:
    """Write the whole records of the MCAP file ``path`` to ``out_path``, closed (see the module
    doc); returns the :class:`Cut`.  Raises McapError for damage that is not a cut, OSError
    for files that cannot be read or written."""
    size = os.path.getsize(path)
    with open(path, 'rb') as src, open(out_path, 'wb') as out:
        if src.read(len(MAGIC)) != MAGIC:
            raise McapError(0, f'expected the MCAP magic {MAGIC!r}')
        out.write(MAGIC)
        pos, cut = len(MAGIC), Cut(size, len(MAGIC), '')
        while True:
            head = src.read(9)
            if not head:
                cut.stop = 'nothing: it ends after a whole record'
                break
            if len(head) < 9:
                cut.stop = f'a record header at byte {pos} ({len(head)} of its 9 bytes)'
                break
            op, length = _RECORD.unpack(head)
            if pos == len(MAGIC) and op != HEADER:
                raise McapError(pos, f'expected the Header record (opcode 0x01), found '
                                     f'opcode 0x{op:02x}')
            if op == 0:
                cut.stop = f'zeros from byte {pos} on (no record there)'
                break
            if op in (DATA_END, FOOTER):
                cut.stop = f'the summary, after the Data End record at byte {pos}'
                break
            if pos + 9 + length > size:
                left = size - pos - 9
                if op == HEADER:
                    raise McapError(pos, f'expected a Header record of {length} bytes, the '
                                         f'file holds {left} of them')
                cut.stop = f'a {_name(op)} at byte {pos}: {left} of its {length} bytes'
                if op == CHUNK:
                    record, n = _partial_chunk(src.read(left), pos)
                    out.write(record)
                    cut.partial_messages = n
                    cut.stop += f', {n} whole messages in them'
                break
            out.write(head)
            left = length
            while left:
                block = src.read(min(left, _COPY_BLOCK))
                out.write(block)
                left -= len(block)
            pos += 9 + length
            cut.kept = pos
        out.write(_record(DATA_END, struct.pack('<I', 0)))
        out.write(_record(FOOTER, struct.pack('<QQI', 0, 0, 0)))
        out.write(MAGIC)
    return cut
