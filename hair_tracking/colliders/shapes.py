"""The shapes hair is kept out of: what each is, the frame it rides on, and the two tables the
kernels read.

A :class:`Shape` is described in the frame it is attached to (``'head'``: moves with the head
pose; ``'fixed'``: the fixed frame of the pose stream; any other name: a TF frame), by its
centre and axes in that frame (a quaternion in ROS order; the capsule's axis and the plane's
normal are the shape's local z axis) and its size:

- ``sphere``: ``radius``;
- ``capsule``: the points within ``radius`` of the segment from ``-half_length`` to
  ``+half_length`` along its axis;
- ``ellipsoid``: semi-axes ``radii`` along its local x, y, z;
- ``plane``: the half-space below it (opposite its normal): a floor or a table top.

Each keeps the hair ``margin`` [m] outside its surface and has a ``friction`` 0..1 (0
frictionless, 1 sticks). The kernels read two float64 tables of one row a shape:

- the *local* table (:func:`shape_table`, columns ``L_*``): the description, built once;
- the *posed* table (:func:`~hair_tracking.colliders.pose.pose_shapes`, columns below): the
  shapes in the world at one substep, with their margins added, the motion of their frames over
  the substep (for friction and the push-out velocity bound) and the bounding-sphere radius of
  the cheap bound test.

A table is one array argument, so a kernel takes every collider of a scene in one argument and
its loops index it by shape (``sh[k, CX]``): no array is created per node.
"""
from dataclasses import dataclass
import math
import numbers
from typing import Sequence, Tuple

import numpy as np

from hair_tracking.core.transforms import quat_to_matrix

#: Shape kinds, as stored in the tables' kind column (a float).
SPHERE, CAPSULE, ELLIPSOID, PLANE = 0, 1, 2, 3
KINDS = {'sphere': SPHERE, 'capsule': CAPSULE, 'ellipsoid': ELLIPSOID, 'plane': PLANE}

#: Normal-line refinements of the ellipsoid projection (0 for three equal radii: the radial
#: projection of a sphere is exact).
ELLIPSOID_REFINEMENTS = 2
#: Refinements of a depth measurement (a few more).
PENETRATION_REFINEMENTS = 6

#: Frames every table knows: index 0 the fixed frame, index 1 the head; TF frames follow.
FIXED_FRAME, HEAD_FRAME = 'fixed', 'head'

# local table: kind, frame index, centre in the frame (3), rotation in the frame (9, row-major),
# whether that rotation is not the identity, size (3: radius | radius, half length | radii),
# margin, friction, refinements
(L_KIND, L_FRAME, L_CX, L_CY, L_CZ, L_R00, L_R01, L_R02, L_R10, L_R11, L_R12, L_R20, L_R21,
 L_R22, L_ROTATED, L_S0, L_S1, L_S2, L_MARGIN, L_FRICTION, L_REFINE) = range(21)
LOCAL_WIDTH = 21

# posed table (world, one substep):
#   KIND; C the centre (sphere, ellipsoid), the segment's midpoint (capsule), a point of the
#   plane; R the shape's axes (row-major; column 2 the capsule's axis and the plane's normal);
#   A: ellipsoid semi-axes + margin | sphere, capsule: radius + margin, half length | plane:
#   margin; I: ellipsoid 1 / A^2 | sphere, capsule: 1 / (radius + margin)^2; FRICTION;
#   REFINE; BOUND the bounding-sphere radius around C (inf for a plane); Q the ellipsoid's
#   quadric R diag(I) R^T (Q00 Q11 Q22 Q01 Q02 Q12); O, OP the frame's origin now and at the
#   previous substep; M = R_frame R_frame_prev^T (the identity when the frame jumped); MARGIN
(KIND, CX, CY, CZ, R00, R01, R02, R10, R11, R12, R20, R21, R22, A0, A1, A2, I0, I1, I2, FRICTION,
 REFINE, BOUND, Q00, Q11, Q22, Q01, Q02, Q12, OX, OY, OZ, PX, PY, PZ, M00, M01, M02, M10, M11,
 M12, M20, M21, M22, MARGIN) = range(44)
WIDTH = 44

#: Relative padding of the bounding-sphere radius: rounding can put a point that the exact test
#: finds inside a few ulps outside the unpadded sphere.
BOUND_PAD = 1e-9


@dataclass(frozen=True)
class Shape:
    """One collider shape in the frame it rides on (see the module docstring)."""

    kind: str
    frame: str = HEAD_FRAME
    center: Tuple[float, float, float] = (0.0, 0.0, 0.0)
    rotation: Tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)
    radius: float = 0.0
    half_length: float = 0.0
    radii: Tuple[float, float, float] = (0.0, 0.0, 0.0)
    margin: float = 0.0
    friction: float = 0.0
    name: str = ''

    def label(self) -> str:
        return f'collider {self.name}' if self.name else f'{self.kind} collider'

    def validate(self) -> 'Shape':
        """This shape; a ValueError of one line naming the field when one is unusable."""
        who = self.label()
        if self.kind not in KINDS:
            raise ValueError(f'{who}: shape {self.kind!r} is not one of '
                             f'{", ".join(KINDS)}')
        if not isinstance(self.frame, str) or not self.frame:
            raise ValueError(f'{who}: frame must be a frame name, got {self.frame!r}')
        _finite(who, 'center', self.center, 3)
        q = _finite(who, 'rotation', self.rotation, 4)
        if not 0.999 < float(np.linalg.norm(q)) < 1.001:
            raise ValueError(f'{who}: rotation must be a unit quaternion (x, y, z, w), got '
                             f'{tuple(q)}')
        if self.kind in ('sphere', 'capsule') and not _positive(self.radius):
            raise ValueError(f'{who}: radius must be a positive number of metres, got '
                             f'{self.radius!r}')
        if self.kind == 'capsule' and not (_finite_number(self.half_length)
                                           and self.half_length >= 0.0):
            raise ValueError(f'{who}: half_length must be >= 0 metres, got '
                             f'{self.half_length!r}')
        if self.kind == 'ellipsoid':
            radii = _finite(who, 'radii', self.radii, 3)
            if np.any(radii <= 0.0):
                raise ValueError(f'{who}: radii must be positive metres, got {tuple(radii)}')
        if not (_finite_number(self.margin) and self.margin >= 0.0):
            raise ValueError(f'{who}: margin must be >= 0 metres, got {self.margin!r}')
        if not (_finite_number(self.friction) and 0.0 <= self.friction <= 1.0):
            raise ValueError(f'{who}: friction must be in [0, 1], got {self.friction!r}')
        return self

    def size(self) -> Tuple[float, float, float]:
        """The size columns: ``(radius, 0, 0)``, ``(radius, half_length, 0)``, the radii, or
        zeros (plane)."""
        if self.kind == 'sphere':
            return float(self.radius), 0.0, 0.0
        if self.kind == 'capsule':
            return float(self.radius), float(self.half_length), 0.0
        if self.kind == 'ellipsoid':
            return tuple(float(r) for r in self.radii)
        return 0.0, 0.0, 0.0

    def refinements(self, measure: bool = False) -> int:
        """Normal-line refinements of the ellipsoid projection (0 for any other shape and for
        three equal radii); ``measure``: those of a depth measurement."""
        if self.kind != 'ellipsoid' or len(set(float(r) for r in self.radii)) == 1:
            return 0
        return PENETRATION_REFINEMENTS if measure else ELLIPSOID_REFINEMENTS


def frame_names(shapes: Sequence[Shape]) -> Tuple[str, ...]:
    """The frames a table of ``shapes`` indexes: the fixed frame, the head, then every other
    frame the shapes name, in order of first use."""
    names = [FIXED_FRAME, HEAD_FRAME]
    for s in shapes:
        if s.frame not in names:
            names.append(s.frame)
    return tuple(names)


def shape_table(shapes: Sequence[Shape], frames: Sequence[str] = (),
                measure: bool = False) -> np.ndarray:
    """The local table (K, :data:`LOCAL_WIDTH`) of ``shapes`` (validated), frames indexed as in
    ``frames`` (default :func:`frame_names`); ``measure``: the refinements of a depth
    measurement (:meth:`Shape.refinements`)."""
    frames = tuple(frames) or frame_names(shapes)
    table = np.zeros((len(shapes), LOCAL_WIDTH))
    for k, s in enumerate(shapes):
        s.validate()
        if s.frame not in frames:
            raise ValueError(f'{s.label()}: frame {s.frame!r} is not one of {", ".join(frames)}')
        row = table[k]
        row[L_KIND] = KINDS[s.kind]
        row[L_FRAME] = frames.index(s.frame)
        row[L_CX:L_CZ + 1] = s.center
        q = np.asarray(s.rotation, dtype=np.float64)
        q = q / np.linalg.norm(q)
        rotated = not (q[0] == 0.0 and q[1] == 0.0 and q[2] == 0.0)
        row[L_R00:L_R22 + 1] = quat_to_matrix(q).reshape(9) if rotated else np.eye(3).reshape(9)
        row[L_ROTATED] = 1.0 if rotated else 0.0
        row[L_S0:L_S2 + 1] = s.size()
        row[L_MARGIN] = s.margin
        row[L_FRICTION] = s.friction
        row[L_REFINE] = s.refinements(measure)
    return table


def capsule_between(a, b, radius: float, **fields) -> Shape:
    """The capsule of ``radius`` around the segment from ``a`` to ``b`` (frame coordinates):
    centre the midpoint, axis (local z) along ``b - a``; ``fields`` the other :class:`Shape`
    fields (frame, margin, friction, name)."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    d = b - a
    length = float(np.linalg.norm(d))
    return Shape('capsule', center=tuple(0.5 * (a + b)), rotation=_turn_z_to(d, length),
                 radius=float(radius), half_length=0.5 * length, **fields)


def _turn_z_to(d, length):
    """The shortest rotation (quaternion x, y, z, w) taking +z to ``d`` (identity for a zero
    ``d``; a half turn about x for ``-z``)."""
    if length <= 0.0:
        return 0.0, 0.0, 0.0, 1.0
    u = d / length
    w = 1.0 + u[2]
    if w < 1e-12:
        return 1.0, 0.0, 0.0, 0.0
    q = np.array([-u[1], u[0], 0.0, w])          # (z x u, 1 + z.u), normalised
    q /= np.linalg.norm(q)
    return tuple(float(v) for v in q)


def _finite(who, name, value, length):
    try:
        arr = np.asarray(value, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        arr = None
    if arr is None or arr.shape != (length,) or not np.all(np.isfinite(arr)):
        raise ValueError(f'{who}: {name} must be {length} finite numbers, got {value!r}')
    return arr


def _finite_number(v) -> bool:
    return isinstance(v, numbers.Real) and not isinstance(v, bool) and math.isfinite(v)


def _positive(v) -> bool:
    return _finite_number(v) and v > 0.0
