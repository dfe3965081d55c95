"""The groom readers on broken files: truncated, with inflated header counts, with random
bytes.  Every one is refused with a one-line GroomFileError (``hair_sim_groom``: exit 3) or read,
never anything else, and the memory a read takes is bounded by the file's size whatever its
header declares (numpy's allocations are traced by tracemalloc: exact, no timing)."""
import struct
import tracemalloc
import zipfile

import numpy as np
import pytest

import groom_files as gf
from hair_tracking.bags.groom_cli import main
from hair_tracking.grooms.formats import read_strands
from hair_tracking.grooms.polylines import GroomFileError

FORMATS = [ext for ext in gf.WRITERS if not ext.startswith('.usd')]
#: A read may take this much memory beyond PEAK_PER_BYTE bytes a byte of the file.
PEAK_SLACK = 8 << 20
PEAK_PER_BYTE = 50


def _read(path):
    """``(what happened, peak bytes)``: 'read', or the GroomFileError's message."""
    tracemalloc.start()
    try:
        read_strands(str(path))
        what = 'read'
    except GroomFileError as e:
        what = str(e)
    finally:
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
    return what, peak


def _broken(data: bytes, rng):
    """Truncations, inflated 32-bit words near the start, scattered random bytes, noise."""
    for n in sorted(set(rng.integers(0, len(data), 30).tolist())):
        yield data[:n]
    for _ in range(60):
        b = bytearray(data)
        at = int(rng.integers(0, min(len(b) - 4, 200)))
        big = [0xFFFFFFFF, 0x7FFFFFFF, 200_000_000, 1 << 28, int(rng.integers(0, 1 << 32))]
        b[at:at + 4] = struct.pack('<I', big[int(rng.integers(0, len(big)))])
        yield bytes(b)
    for _ in range(20):
        b = bytearray(data)
        for i, v in zip(rng.integers(0, len(b), 8), rng.integers(0, 256, 8)):
            b[int(i)] = int(v)
        yield bytes(b)
    yield rng.integers(0, 256, 300).astype(np.uint8).tobytes()


@pytest.mark.parametrize('ext', FORMATS)
def test_broken_files_are_refused_in_one_line_in_bounded_memory(tmp_path, ext):
    src = tmp_path / ('src' + ext)
    gf.WRITERS[ext](src, gf.to_file_frame(gf.synthetic_groom(12, 6, seed=1)))
    data = src.read_bytes()
    rng = np.random.default_rng(list(gf.WRITERS).index(ext))
    refused = 0
    for k, blob in enumerate(_broken(data, rng)):
        case = tmp_path / f'case{k}{ext}'
        case.write_bytes(blob)
        what, peak = _read(case)
        assert peak < PEAK_SLACK + PEAK_PER_BYTE * len(data), (k, what, peak)
        if what != 'read':
            refused += 1
            assert '\n' not in what and what.startswith(str(case)), what
    assert refused > 20


def test_declared_sizes_are_checked_before_they_are_allocated(tmp_path, capsys):
    strands = [s[:6] for s in gf.to_file_frame(gf.synthetic_groom(12, 6, seed=1))]
    hair = tmp_path / 'noseg.hair'
    gf.write_hair(hair, strands, segments_array=False)
    b = bytearray(hair.read_bytes())
    for hairs in (200_000_000, 0xFFFFFFFF):
        b[4:8] = struct.pack('<I', hairs)
        for blob in (bytes(b), bytes(b[:164])):        # a whole file, a 164-byte header
            hair.write_bytes(blob)
            what, peak = _read(hair)
            assert 'expected a default segment count' in what and peak < PEAK_SLACK, what
    assert main(['info', str(hair)]) == 3
    err = capsys.readouterr().err.strip()
    assert err.count('\n') == 0 and 'byte 16' in err
    # an .npz whose array header declares 900 M points (the archive's checksums right)
    npz = tmp_path / 'big.npz'
    gf.write_npz(npz, strands)
    with zipfile.ZipFile(npz) as z:
        members = {n: z.read(n) for n in z.namelist()}
    header = members['points.npy']
    i = header.find(b"'shape': (")
    j = header.find(b')', i)
    end = header.find(b'}', j)
    new = b"'shape': (900000000, 3)"
    members['points.npy'] = header[:i] + new + header[j + 1:end + 1] + \
        header[end + 1 + len(new) - (j + 1 - i):]
    with zipfile.ZipFile(npz, 'w') as z:
        for name, blob in members.items():
            z.writestr(name, blob)
    what, peak = _read(npz)
    assert "array 'points': expected a shape that fits its" in what and peak < PEAK_SLACK, what
