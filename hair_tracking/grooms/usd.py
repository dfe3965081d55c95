"""USD ``BasisCurves`` (what Blender exports hair curves as), read and written with Pixar's
``usd-core`` (``pip install usd-core``, the optional extra ``hair_tracking[usd]``); the one module
of the package that imports it.

Every ``BasisCurves`` prim of the stage contributes its curves: ``points`` (in the prim's local
space, carried to the stage's by its local-to-world transform at the default time) split by
``curveVertexCounts``.  The vertices are used as the strand's polyline (a cubic basis's control
points lie close to the curve for the dense curves of a groom).  The stage's
``metersPerUnit`` and ``upAxis`` give the units and the up axis.
"""
import os
from typing import Optional

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


# ----------------------------------------------------------------------------- writing
def _pxr(path: str):
    try:
        import pxr  # noqa: F401
    except ImportError:
        raise GroomFileError(path, '', '', MISSING.replace('reading', 'writing')) from None


def usd_stage(path: str, meters_per_unit: Optional[float], up_axis: Optional[str]):
    """A new USD stage at ``path`` with its units and up axis (USD has only y and z up: another
    up axis is left unstated), and the ``/groom/hair`` linear BasisCurves prim; returns
    ``(stage, curves)``."""
    _pxr(path)
    from pxr import Usd, UsdGeom
    stage = Usd.Stage.CreateNew(str(path))
    if meters_per_unit is not None:
        UsdGeom.SetStageMetersPerUnit(stage, float(meters_per_unit))
    if up_axis in ('y', 'z'):
        UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y if up_axis == 'y' else UsdGeom.Tokens.z)
    stage.SetDefaultPrim(UsdGeom.Xform.Define(stage, '/groom').GetPrim())
    curves = UsdGeom.BasisCurves.Define(stage, '/groom/hair')
    curves.CreateTypeAttr(UsdGeom.Tokens.linear)
    return stage, curves


def write_usd(path: str, points: np.ndarray, counts: np.ndarray,
              meters_per_unit: Optional[float] = None, up_axis: Optional[str] = None) -> None:
    """A USD stage of one linear BasisCurves prim holding ``points`` (P, 3) float32 split by
    ``counts`` (S,)."""
    from pxr import Vt
    stage, curves = usd_stage(path, meters_per_unit, up_axis)
    curves.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(points, np.float32)))
    curves.CreateCurveVertexCountsAttr(Vt.IntArray.FromNumpy(counts.astype(np.int32)))
    stage.GetRootLayer().Save()


class AnimatedCurves:
    """A USD stage whose ``/groom/hair`` curves move: :meth:`add` one frame after another (time
    code ``k`` is the ``k``-th; the curve vertex counts are time-sampled where they change, and
    the first frame is also the default value, what a reader of still grooms takes), then
    :meth:`save` with the frames' rate.  Metres, z up (REP-103)."""

    def __init__(self, path: str):
        self.stage, self.curves = usd_stage(path, 1.0, 'z')
        self.points = self.curves.CreatePointsAttr()
        self.counts = self.curves.CreateCurveVertexCountsAttr()
        self.frames = 0
        self.shape = None

    def add(self, strands: np.ndarray) -> None:
        """The next frame: ``strands`` (S, N, 3)."""
        from pxr import Usd, Vt
        k = self.frames
        flat = Vt.Vec3fArray.FromNumpy(
            np.ascontiguousarray(strands.reshape(-1, 3), dtype=np.float32))
        if strands.shape[:2] != self.shape:
            self.shape = strands.shape[:2]
            per = Vt.IntArray.FromNumpy(np.full(self.shape[0], self.shape[1], dtype=np.int32))
            self.counts.Set(per, Usd.TimeCode(k))
            if k == 0:
                self.counts.Set(per)
        self.points.Set(flat, Usd.TimeCode(k))
        if k == 0:
            self.points.Set(flat)
        self.frames += 1

    def save(self, rate_hz: float) -> None:
        """Time codes 0 .. frames - 1 at ``rate_hz`` codes (and frames) a second; written."""
        self.stage.SetStartTimeCode(0)
        self.stage.SetEndTimeCode(max(0, self.frames - 1))
        self.stage.SetTimeCodesPerSecond(rate_hz)
        self.stage.SetFramesPerSecond(rate_hz)
        self.stage.GetRootLayer().Save()
