"""USD ``BasisCurves`` (what Blender exports hair curves as), read with Pixar's ``usd-core``
(``pip install usd-core``, the optional extra ``hair_tracking[usd]``).

Every ``BasisCurves`` prim of the stage contributes its curves: ``points`` (in the prim's local
space, carried to the stage's by its local-to-world transform at the default time) split by
``curveVertexCounts``.  The vertices are used as the strand's polyline (a cubic basis's control
points lie close to the curve for the dense curves of a groom).  The stage's
``metersPerUnit`` and ``upAxis`` give the units and the up axis.
"""
import os

import numpy as np

from hair_tracking.grooms.polylines import GroomFileError, Polylines, strand_of

FORMAT = 'USD BasisCurves'
MISSING = ('reading USD needs usd-core (pip install usd-core, or the extra '
           'hair_tracking[usd])')


def available() -> bool:
    """Whether usd-core can be imported."""
    try:
        import pxr  # noqa: F401
    except ImportError:
        return False
    return True


def read_usd(path: str) -> Polylines:
    """The curves of every BasisCurves prim of a USD stage (see the module docstring)."""
    try:
        from pxr import Usd, UsdGeom
    except ImportError:
        raise GroomFileError(path, '', '', MISSING) from None
    if not os.path.isfile(path):
        raise GroomFileError(path, '', '', 'file not found')
    try:
        stage = Usd.Stage.Open(path)
    except Exception as e:       # noqa: B902 - pxr raises its own Tf.ErrorException
        raise GroomFileError(path, 'byte 0', 'a USD stage', str(e).strip().split('\n')[0]) \
            from None
    if stage is None:
        raise GroomFileError(path, 'byte 0', 'a USD stage', 'none')
    points, counts = [], []
    cache = UsdGeom.XformCache()
    for prim in stage.Traverse():
        if not prim.IsA(UsdGeom.BasisCurves):
            continue
        curves = UsdGeom.BasisCurves(prim)
        p = np.asarray(curves.GetPointsAttr().Get() or [], dtype=np.float64).reshape(-1, 3)
        c = np.asarray(curves.GetCurveVertexCountsAttr().Get() or [], dtype=np.int64)
        if c.size == 0 and p.size == 0:
            continue
        if (c < 0).any() or int(c.sum()) != p.shape[0]:
            raise GroomFileError(path, f'prim {prim.GetPath()}', f'curveVertexCounts summing '
                                 f'to its {p.shape[0]} points', f'{int(c.sum())}')
        m = np.asarray(cache.GetLocalToWorldTransform(prim), dtype=np.float64)
        points.append(p @ m[:3, :3] + m[3, :3])          # USD: row vectors, p' = p M
        counts.append(c)
    if not counts or sum(len(c) for c in counts) == 0:
        raise GroomFileError(path, 'the stage', 'a BasisCurves prim with curves', 'none')
    pts = np.concatenate(points)
    cnt = np.concatenate(counts)
    bad = ~np.isfinite(pts).all(axis=1)
    if bad.any():
        i = int(np.argmax(bad))
        raise GroomFileError(path, f'vertex {i} (curve {strand_of(cnt, i)})',
                             'a finite vertex', f'{pts[i].tolist()}')
    up = str(UsdGeom.GetStageUpAxis(stage)).lower()
    return Polylines(pts, cnt, FORMAT, meters_per_unit=float(
        UsdGeom.GetStageMetersPerUnit(stage)), up_axis=up if up in ('y', 'z') else None)
