"""Groom files written from their published layouts, for the tests and the groom benchmark:
a synthetic groom and a writer per format, independent of the package's readers.

* ``.hair`` (cyHairFile.h): 128-byte header ``"HAIR"``, u32 hairs, u32 points, u32 array flags
  (1 segments, 2 points, 4 thickness, 8 transparency, 16 colours), u32 default segments, f32
  default thickness, f32 default transparency, f32[3] default colour, char[88] info; then u16
  segments per hair, f32 xyz, then the optional arrays.
* ``.data`` (USC-HairSalon): int32 strands, per strand int32 vertices and float32 xyz each.
* ``.bin`` (CT2Hair): int32 strands, per strand int32 vertices and 7 float32 each (xyz,
  tangent, label).
* polyline PLY (hairutil): ``element vertex`` (float x y z), ``element strand`` (ushort nsegs).
* NPZ: ``points`` and ``counts``.
"""
import struct

import numpy as np

#: The synthetic groom's head: an ellipsoid a little smaller than the default scalp [m].
HEAD_RADII = np.array([0.092, 0.078, 0.1])


#: The styles of :func:`synthetic_groom`: (share of the strands curled, curl radius [m],
#: turns along a strand).
STYLES = {'mixed': (1 / 3, 0.012, 4), 'straight': (0.0, 0.0, 0), 'wavy': (1.0, 0.006, 2),
          'curly': (1.0, 0.012, 5)}


def synthetic_groom(strands=200, vertices=20, seed=0, ragged=True, style='mixed'):
    """A groom a hairdresser might have made, in the head frame [m] (x forward, z up, origin at
    the head centre): roots on the top of :data:`HEAD_RADII`'s ellipsoid, a fringe over the
    forehead, longer hair down the back and sides; ``style`` (:data:`STYLES`) says how many of
    the strands are curled and how (``mixed``: a third).  Returns a list of (n, 3) arrays
    (``vertices`` each, or 60-140 % of it when ``ragged``)."""
    share, radius, turns = STYLES[style]
    rng = np.random.default_rng(seed)
    out = []
    while len(out) < strands:
        u = rng.normal(size=3)
        u /= np.linalg.norm(u)
        polar = np.degrees(np.arccos(u[2]))
        if polar > (50.0 if u[0] > 0.3 else 100.0):
            continue
        root = u * HEAD_RADII
        normal = u / HEAD_RADII
        normal /= np.linalg.norm(normal)
        front = u[0] > 0.3
        length = rng.uniform(0.08, 0.12) if front else rng.uniform(0.2, 0.35)
        n = vertices if not ragged else int(rng.integers(int(0.6 * vertices),
                                                         int(1.4 * vertices) + 1))
        n = max(n, 3)
        curl = rng.random() < share
        s = np.linspace(0.0, 1.0, n)[:, None]
        down = np.array([0.0, 0.0, -1.0]) if not front else \
            np.array([0.35, 0.0, -0.94])
        w = np.clip(s * 8.0, 0.0, 1.0)
        d = (1.0 - w) * normal + w * down
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        p = root + np.cumsum(d * length / (n - 1), axis=0) - d[0] * length / (n - 1)
        if curl:
            side = np.cross(down, normal)
            side /= max(np.linalg.norm(side), 1e-9)
            other = np.cross(side, down)
            phase = 2 * np.pi * turns * s + rng.uniform(0, 2 * np.pi)
            p = p + radius * s * (np.cos(phase) * side + np.sin(phase) * other)
        rel = (p - 0.0) / (1.06 * HEAD_RADII)
        r = np.linalg.norm(rel, axis=1, keepdims=True)
        p[1:] = np.where(r[1:] < 1.0, rel[1:] / r[1:] * 1.06 * HEAD_RADII, p[1:])
        out.append(p)
    return out


def to_file_frame(strands, unit=0.01, up='y', origin=(0.0, 1.6, 0.0)):
    """Head-frame strands [m] as a DCC file holds them: ``unit`` metres per unit, y up (the face
    toward +z) or z up (as the head frame), the head at ``origin`` [m, file axes]."""
    out = []
    for p in strands:
        q = p[:, [1, 2, 0]] if up == 'y' else p.copy()
        out.append((q + np.asarray(origin)) / unit)
    return out


def flat(strands):
    return np.concatenate(strands).astype(np.float32), np.array([len(p) for p in strands])


def write_hair(path, strands, segments_array=True, info=b'written by the tests'):
    points, counts = flat(strands)
    flags = 2 | (1 if segments_array else 0) | 4 | 16
    d_seg = int(counts[0]) - 1
    head = struct.pack('<4sIIIIff3f88s', b'HAIR', len(counts), len(points), flags, d_seg,
                       0.5, 0.0, 0.3, 0.2, 0.1, info)
    assert len(head) == 128
    with open(path, 'wb') as f:
        f.write(head)
        if segments_array:
            f.write((counts - 1).astype('<u2').tobytes())
        f.write(points.astype('<f4').tobytes())
        f.write(np.full(len(points), 0.01, '<f4').tobytes())             # thickness
        f.write(np.tile(np.float32([0.3, 0.2, 0.1]), len(points)).astype('<f4').tobytes())


def write_data(path, strands):
    with open(path, 'wb') as f:
        f.write(struct.pack('<i', len(strands)))
        for p in strands:
            f.write(struct.pack('<i', len(p)))
            f.write(np.asarray(p, '<f4').tobytes())


def write_bin(path, strands):
    with open(path, 'wb') as f:
        f.write(struct.pack('<i', len(strands)))
        for p in strands:
            p = np.asarray(p, dtype=np.float64)
            tangent = np.gradient(p, axis=0) if len(p) > 1 else np.zeros_like(p)
            rows = np.concatenate([p, tangent, np.full((len(p), 1), 3.0)], axis=1)
            f.write(struct.pack('<i', len(p)))
            f.write(rows.astype('<f4').tobytes())


def write_ply(path, strands, binary=True):
    points, counts = flat(strands)
    head = ('ply\nformat ' + ('binary_little_endian' if binary else 'ascii') + ' 1.0\n'
            'comment written by the tests\n'
            f'element vertex {len(points)}\nproperty float x\nproperty float y\n'
            'property float z\n'
            f'element strand {len(counts)}\nproperty ushort nsegs\nend_header\n')
    with open(path, 'wb') as f:
        f.write(head.encode('ascii'))
        if binary:
            f.write(points.astype('<f4').tobytes())
            f.write((counts - 1).astype('<u2').tobytes())
        else:
            f.write(''.join(f'{x!r} {y!r} {z!r}\n' for x, y, z in points.tolist())
                    .encode('ascii'))
            f.write(''.join(f'{c - 1}\n' for c in counts.tolist()).encode('ascii'))


def write_npz(path, strands):
    points, counts = flat(strands)
    np.savez(path, points=points, counts=counts)


def write_usd(path, strands, meters_per_unit=0.01, up='Y'):
    from pxr import Usd, UsdGeom, Vt, Gf
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageMetersPerUnit(stage, meters_per_unit)
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y if up == 'Y' else UsdGeom.Tokens.z)
    UsdGeom.Xform.Define(stage, '/groom')
    curves = UsdGeom.BasisCurves.Define(stage, '/groom/hair')
    points, counts = flat(strands)
    curves.CreateTypeAttr(UsdGeom.Tokens.linear)
    curves.CreatePointsAttr(Vt.Vec3fArray([Gf.Vec3f(*map(float, p)) for p in points]))
    curves.CreateCurveVertexCountsAttr(Vt.IntArray([int(c) for c in counts]))
    stage.GetRootLayer().Save()


WRITERS = {'.hair': write_hair, '.data': write_data, '.bin': write_bin, '.ply': write_ply,
           '.npz': write_npz}
