"""The head's row of the collider table: a sphere or an ellipsoid on the head frame, and the
kernels of its fast path.

The collision surface is the ellipsoid with semi-axes ``radii + margin`` around ``center`` (head
frame); a sphere is the ellipsoid with three equal radii. For a sphere this is exactly the surface
offset by ``margin``; for an ellipsoid it differs from the true offset surface by a small fraction
of ``margin`` (the head ellipsoids here are nearly spherical).

Projection and friction are the contact model's rule for an ellipsoid
(:func:`hair_tracking.colliders.contact.ellipsoid_contact`: the radial projection refined along
the normal, ``refine`` times; position-level friction relative to a reference position), which
this module applies to the head collider placed by each substep's head pose.  For a sphere the
radial projection is already exact (``refine = 0``).

All work happens in the head frame: points are transformed with the head pose inside the
kernels (``q = R^T (x - t) - center``); inputs and outputs are world-frame positions [m].
:func:`project_ellipsoid` and :func:`penetration_ellipsoid` are plain kernels usable on any
``(S, N, 3)`` arrays (the ghost tracker calls them through :class:`HeadCollider` on its own
arrays).  The head's row is the first of the scene's table
(:class:`~hair_tracking.colliders.table.ColliderTable`); :class:`HeadCollider` is that row as
the guide solvers and trackers run it, its margin fitted to their strands
(:meth:`HeadCollider.fitted`).
"""
from collections import namedtuple
import math
from typing import Optional

import numpy as np
from numba import njit, prange

from hair_tracking.colliders.contact import (ellipsoid_contact, ellipsoid_depth,
                                             ellipsoid_level, local_of, push_sorted,
                                             SHALLOW_LEVEL, sort_by_depth_class)
from hair_tracking.colliders.margin import fit_margin
from hair_tracking.colliders.shapes import HEAD_FRAME, Shape
from hair_tracking.core.kernels import BLOCK, FASTMATH, parallel_and_serial, runs_parallel


#: The collider as the kernels take it, a plain tuple in these fields' order
#: (:attr:`HeadCollider.model`; numba types a named tuple by encoding its class and field names on
#: every call): ``center`` (3,) and ``radii`` (3,) head frame [m], ``margin`` [m],
#: ``friction`` 0..1, ``refine`` projection refinements.
ColliderModel = namedtuple('ColliderModel', ['center', 'radii', 'margin', 'friction', 'refine'])
#: The collider placed by the head pose of one substep, as the per-node functions take it
#: (:func:`placed`): the head rotation's nine entries ``rot`` (:func:`rotation_entries`), the
#: ellipsoid's centre in the world ``cx, cy, cz`` [m], its semi-axes ``ax, ay, az`` [m] (the
#: margin included, head axes), ``friction`` and ``refine``.  Numbers only: numba counts the
#: references of an array handed to an inlined function, and in a loop over nodes that also
#: calls a compiled function (:func:`surface_point`) it keeps the count in the loop.
Contact = namedtuple('Contact', ['rot', 'cx', 'cy', 'cz', 'ax', 'ay', 'az', 'friction',
                                 'refine'])


@njit(cache=True, inline='always', fastmath=FASTMATH, error_model='numpy')
def world_center(rot, pos, center):
    """The ellipsoid centre ``pos + rot center`` in the world [m] (``center`` head frame)."""
    return (rot[0, 0] * center[0] + rot[0, 1] * center[1] + rot[0, 2] * center[2] + pos[0],
            rot[1, 0] * center[0] + rot[1, 1] * center[1] + rot[1, 2] * center[2] + pos[1],
            rot[2, 0] * center[0] + rot[2, 1] * center[1] + rot[2, 2] * center[2] + pos[2])


@njit(cache=True, inline='always', fastmath=FASTMATH, error_model='numpy')
def to_head(x0, x1, x2, rot, cx, cy, cz):
    """``R^T (x - c)``: a world point [m] relative to the world point ``c``, in the head axes
    (``rot`` the rotation matrix ``R``; the collision-aware FTL pass,
    :func:`~hair_tracking.guides.ftl.restore_node`)."""
    dx, dy, dz = x0 - cx, x1 - cy, x2 - cz
    return (rot[0, 0] * dx + rot[1, 0] * dy + rot[2, 0] * dz,
            rot[0, 1] * dx + rot[1, 1] * dy + rot[2, 1] * dz,
            rot[0, 2] * dx + rot[1, 2] * dy + rot[2, 2] * dz)


@njit(cache=True, inline='always')
def rotation_entries(rot):
    """The entries of the rotation ``rot`` (3, 3) as nine numbers, row by row (``R_ij`` at
    ``3 i + j``): the rotation of a :data:`Contact`."""
    return (rot[0, 0], rot[0, 1], rot[0, 2], rot[1, 0], rot[1, 1], rot[1, 2], rot[2, 0],
            rot[2, 1], rot[2, 2])


@njit(cache=True, inline='always', fastmath=FASTMATH, error_model='numpy')
def placed(collider, rot, pos):
    """The :data:`Contact` of ``collider`` (the fields of :data:`ColliderModel`) for the head
    pose ``rot``, ``pos``."""
    return (rotation_entries(rot),) + placed_shape(collider, rot, pos)


@njit(cache=True, inline='always', fastmath=FASTMATH, error_model='numpy')
def placed_shape(collider, rot, pos):
    """The fields of :func:`placed`'s :data:`Contact` after the rotation: ``(cx, cy, cz, ax,
    ay, az, friction, refine)`` (a parallel loop takes numbers and arrays, not tuples: it
    rebuilds the contact from these and the rotation)."""
    center, radii, margin, friction, refine = collider
    cx, cy, cz = world_center(rot, pos, center)
    return cx, cy, cz, radii[0] + margin, radii[1] + margin, radii[2] + margin, friction, refine


def project_ellipsoid(x, x_prev, inv_mass, rot, pos, collider):
    """Kernel: push nodes with ``inv_mass > 0`` out of the ellipsoid ``radii + margin``; friction.

    ``x``, ``x_prev`` (S, N, 3) world frame [m] (``x`` changed in place; ``x_prev`` is the friction
    reference); ``inv_mass`` (S, N); ``rot`` (3, 3), ``pos`` (3,) the head pose; ``collider``
    the fields of :data:`ColliderModel`. Returns the number of nodes projected.
    """
    cx, cy, cz, ax, ay, az, fr, refine = placed_shape(collider, rot, pos)
    n = x.shape[0]
    contacts = 0
    for blk in prange((n + BLOCK - 1) // BLOCK):
        s0 = np.int64(blk) * BLOCK   # (signed in both variants: one compiled block body)
        contact = (rotation_entries(rot), cx, cy, cz, ax, ay, az, fr, refine)
        contacts += project_block(x, x_prev, inv_mass, contact, s0, min(s0 + BLOCK, n))
    return contacts


#: Normal-line refinements :func:`project_block`'s pass over the pushed nodes unrolls (the
#: ellipsoid default is :data:`~hair_tracking.colliders.shapes.ELLIPSOID_REFINEMENTS`); more
#: take the node-by-node path.
MAX_VECTOR_REFINE = 2
#: Rows of :func:`project_block`'s work space (per node of the block): inside flag, index of a
#: pushed node, its position, its friction reference.
(_FLAG, _IDX, _PX, _PY, _PZ, _RX, _RY, _RZ) = range(8)


@njit(cache=True, fastmath=FASTMATH, error_model='numpy')
def project_block(x, x_prev, inv_mass, contact, s0, s1):
    """:func:`project_ellipsoid` of the strands ``s0 <= s < s1`` (``contact`` the fields of
    :data:`Contact`): its loop body.  Returns the number of nodes moved.

    Every node's arithmetic is :func:`~hair_tracking.colliders.contact.ellipsoid_contact`'s,
    in passes over the pushed nodes only, laid out contiguously (as the ghosts' contact,
    :mod:`hair_tracking.ghosts.contacts`): the inside test of every node, a branch-free
    compaction of the pushed ones (those the contact's fast path takes first), their positions
    and references gathered, two loops without data-dependent branches (the fast path's Newton
    step and friction; the surface point of
    :func:`~hair_tracking.colliders.contact.surface_point` with its refinements unrolled and the
    centre's exit as a select, friction; back to the world), the results scattered.  Hair
    resting on the head keeps many nodes in contact every substep; node by node each is a
    chain of dependent square roots and divisions behind a hard-to-predict branch."""
    rot, cx, cy, cz, ax, ay, az, mu, refine = contact
    n = x.shape[1]
    ix, iy, iz = 1.0 / (ax * ax), 1.0 / (ay * ay), 1.0 / (az * az)
    w = np.empty((8, (s1 - s0) * n))
    # 1. inside test of every node (NaN compares as ellipsoid_contact's tests: inside, deep),
    # then compaction: the nodes the contact's fast path takes first (m_fast), then the deeper
    m = 0
    for s in range(s0, s1):
        for i in range(n):
            q0, q1, q2 = local_of(x[s, i, 0], x[s, i, 1], x[s, i, 2], rot, cx, cy, cz)
            f = ellipsoid_level(q0, q1, q2, ix, iy, iz)
            depth_class = 0.0 if inv_mass[s, i] <= 0.0 or f >= 1.0 else \
                (2.0 if f > SHALLOW_LEVEL else 1.0)
            w[_FLAG, (s - s0) * n + i] = depth_class
            m += 1 if depth_class != 0.0 else 0
    if m == 0:
        return 0
    m_fast, m = sort_by_depth_class(w, (_FLAG, _IDX, _RX), (s1 - s0) * n)   # _RX: scratch
    # 2. gather
    for c in range(m):
        j = int(w[_IDX, c])
        s, i = s0 + j // n, j % n
        w[_PX, c] = x[s, i, 0]
        w[_PY, c] = x[s, i, 1]
        w[_PZ, c] = x[s, i, 2]
        w[_RX, c] = x_prev[s, i, 0]
        w[_RY, c] = x_prev[s, i, 1]
        w[_RZ, c] = x_prev[s, i, 2]
    # 3. the arithmetic of every pushed node
    if refine > MAX_VECTOR_REFINE:
        for c in range(m):
            _, w[_PX, c], w[_PY, c], w[_PZ, c] = ellipsoid_contact(
                w[_PX, c], w[_PY, c], w[_PZ, c], w[_RX, c], w[_RY, c], w[_RZ, c], contact)
    else:
        push_sorted(w, (_PX, _PY, _PZ, _RX, _RY, _RZ), m_fast, m, contact, (ix, iy, iz))
    # 4. scatter
    for c in range(m):
        j = int(w[_IDX, c])
        s, i = s0 + j // n, j % n
        x[s, i, 0] = w[_PX, c]
        x[s, i, 1] = w[_PY, c]
        x[s, i, 2] = w[_PZ, c]
    return m


def penetration_ellipsoid(x, inv_mass, use_mass, rot, pos, center, radii, refine, out):
    """Kernel: ``out[s]`` = deepest distance [m] of strand ``s``'s nodes inside the ellipsoid.

    The bare ellipsoid ``radii`` (no margin); only nodes with ``inv_mass > 0`` if ``use_mass``.
    Distance to the (approximate, see :func:`surface_point`) closest surface point; 0 if none.
    """
    cx, cy, cz, ax, ay, az, fr, n_ref = placed_shape((center, radii, 0.0, 0.0, refine), rot,
                                                     pos)
    for s in prange(x.shape[0]):
        contact = (rotation_entries(rot), cx, cy, cz, ax, ay, az, fr, n_ref)
        out[s] = strand_depth(x, inv_mass, use_mass, contact, np.int64(s))


@njit(cache=True, fastmath=FASTMATH, error_model='numpy')
def strand_depth(x, inv_mass, use_mass, contact, s):
    """The deepest distance [m] of strand ``s``'s nodes inside the ellipsoid of ``contact``
    (:func:`penetration_ellipsoid`'s loop body)."""
    rot, cx, cy, cz, ax, ay, az, _, refine = contact
    ix, iy, iz = 1.0 / (ax * ax), 1.0 / (ay * ay), 1.0 / (az * az)
    deepest = 0.0
    for i in range(x.shape[1]):
        if use_mass and inv_mass[s, i] <= 0.0:
            continue
        qx, qy, qz = local_of(x[s, i, 0], x[s, i, 1], x[s, i, 2], rot, cx, cy, cz)
        depth = ellipsoid_depth(qx, qy, qz, ax, ay, az, ix, iy, iz, refine)
        if depth > deepest:
            deepest = depth
    return deepest


project_ellipsoid, project_ellipsoid_serial = parallel_and_serial(
    project_ellipsoid, fastmath=FASTMATH, error_model='numpy')
penetration_ellipsoid, penetration_ellipsoid_serial = parallel_and_serial(
    penetration_ellipsoid, fastmath=FASTMATH, error_model='numpy')


def _points(name, arr, ndim=3, types=(np.float64,)):
    if not isinstance(arr, np.ndarray) or arr.dtype not in types or arr.ndim != ndim or \
            not arr.flags.c_contiguous or (ndim == 3 and arr.shape[2] != 3):
        shape = '(S, N, 3)' if ndim == 3 else '(S, N)'
        kind = '/'.join(np.dtype(t).name for t in types)
        raise ValueError(f'{name}: must be a C-contiguous {kind} array shaped {shape}, got '
                         f'{type(arr).__name__} {getattr(arr, "dtype", "")} '
                         f'{getattr(arr, "shape", "")}')
    return arr


def _pose(head):
    rot = np.ascontiguousarray(head.rotation, dtype=np.float64)
    pos = np.ascontiguousarray(head.position, dtype=np.float64)
    if rot.shape != (3, 3) or pos.shape != (3,):
        raise ValueError(f'head: rotation must be (3, 3) and position (3,), got {rot.shape} '
                         f'and {pos.shape}')
    return rot, pos


class HeadCollider:
    """The head's row (a sphere or ellipsoid on the head frame, see the module docstring) as
    the kernels of its fast path take it.

    ``center`` (3,) and ``radii`` (3,) [m] head frame, ``margin`` [m] kept between hair and
    surface, ``friction`` 0..1. ``refine`` is the number of projection refinements (0 for a
    sphere, :data:`~hair_tracking.colliders.shapes.ELLIPSOID_REFINEMENTS` otherwise), the
    row's (:meth:`~hair_tracking.colliders.shapes.Shape.refinements`).
    """

    def __init__(self, shape: str, center, radii, margin: float, friction: float):
        self.shape = shape
        self.center = np.ascontiguousarray(center, dtype=np.float64).reshape(3)
        self.radii = np.ascontiguousarray(radii, dtype=np.float64).reshape(3)
        if not np.all(np.isfinite(self.radii)) or np.any(self.radii <= 0):
            raise ValueError(f'collider radii: must be positive finite metres, got {self.radii}')
        if not np.all(np.isfinite(self.center)):
            raise ValueError(f'collider center: must be finite, got {self.center}')
        if not (math.isfinite(margin) and margin >= 0):
            raise ValueError(f'collider margin: must be >= 0 metres, got {margin}')
        if not (0.0 <= friction <= 1.0):
            raise ValueError(f'collider friction: must be in [0, 1], got {friction}')
        self.margin = float(margin)
        self.friction = float(friction)
        row = self.row()
        self.refine = row.refinements()
        self._pen_refine = row.refinements(measure=True)

    def row(self) -> Shape:
        """This collider as a row of the collider table (an ellipsoid on the head frame)."""
        return Shape('ellipsoid', frame=HEAD_FRAME, center=tuple(self.center),
                     radii=tuple(self.radii), margin=self.margin, friction=self.friction,
                     name=self.shape)

    def fitted(self, rest: np.ndarray, inv_mass: np.ndarray,
               rest_length: np.ndarray) -> 'HeadCollider':
        """This collider with the margin a strand set (``rest`` (S, N, 3) head frame,
        ``inv_mass`` (S, N), ``rest_length`` (S, N - 1)) can use: the rule of every shape
        (:func:`~hair_tracking.colliders.margin.fit_margin`) over its free nodes."""
        margin = fit_margin(self.row(), rest[inv_mass > 0], rest_length)
        return HeadCollider(self.shape, self.center, self.radii, margin, self.friction)

    @property
    def axes(self) -> np.ndarray:
        """The semi-axes the hair is kept outside of [m]: the radii plus the margin."""
        return np.ascontiguousarray(self.radii + self.margin)

    @property
    def model(self) -> tuple:
        """The fields of :data:`ColliderModel`, as the kernels take them (a plain tuple)."""
        return (self.center, self.radii, self.margin, self.friction, self.refine)

    def apply(self, x: np.ndarray, x_prev: np.ndarray, inv_mass: np.ndarray, head) -> int:
        """Project the free nodes of ``x`` (S, N, 3) out of the surface + margin, in place.

        ``x_prev`` (S, N, 3) is the friction reference (e.g. the start-of-substep positions carried
        with the head, so friction acts on the slip relative to the head); ``inv_mass`` (S, N):
        only nodes with ``inv_mass > 0`` move; ``head`` a
        :class:`~hair_tracking.core.model.HeadPose`.  Returns the number of contacts (nodes
        moved).  Small problems run the serial variant of the kernel
        (:func:`~hair_tracking.core.kernels.runs_parallel`).
        """
        _points('x', x)
        _points('x_prev', x_prev)
        _points('inv_mass', inv_mass, ndim=2)
        if x_prev.shape != x.shape or inv_mass.shape != x.shape[:2]:
            raise ValueError(f'x_prev {x_prev.shape} and inv_mass {inv_mass.shape} must match '
                             f'x {x.shape}')
        rot, pos = _pose(head)
        return self.project(x, x_prev, inv_mass, rot, pos,
                            runs_parallel(x.shape[0] * x.shape[1]))

    def project(self, x, x_prev, inv_mass, rot, pos, parallel: bool = True) -> int:
        """:meth:`apply` without input checks, the head pose given as ``rot`` (3, 3) and ``pos``
        (3,) C-contiguous float64 arrays: for callers that validated their arrays once.
        ``parallel`` false runs the serial variant of the kernel (small problems)."""
        kernel = project_ellipsoid if parallel else project_ellipsoid_serial
        return int(kernel(x, x_prev, inv_mass, rot, pos, self.model))

    def penetration(self, x: np.ndarray, head, inv_mass: Optional[np.ndarray] = None,
                    parallel: Optional[bool] = None) -> float:
        """Deepest distance [m] of a point of ``x`` (S, N, 3) inside the bare surface; 0 if none.

        With ``inv_mass`` only the free nodes (``inv_mass > 0``) count (attached roots lie on the
        scalp, which may be inside the collider).  ``x`` may be float32 (the stateless trackers'
        ghost positions).  ``parallel``: the kernel variant (default: by the size of ``x``,
        :func:`~hair_tracking.core.kernels.runs_parallel`).
        """
        _points('x', x, types=(np.float64, np.float32))
        if inv_mass is None:
            mass, use = np.zeros((0, 0)), False
        else:
            mass, use = _points('inv_mass', inv_mass, ndim=2), True
            if mass.shape != x.shape[:2]:
                raise ValueError(f'inv_mass {mass.shape} must match x {x.shape}')
        rot, pos = _pose(head)
        out = np.zeros(x.shape[0])
        if parallel is None:
            parallel = runs_parallel(x.shape[0] * x.shape[1])
        kernel = penetration_ellipsoid if parallel else penetration_ellipsoid_serial
        if x.flags.writeable:
            # always a read-only view: one compiled kernel for the guides' arrays and the
            # ghost tracker's read-only positions
            x = x.view()
            x.flags.writeable = False
        kernel(x, mass, use, rot, pos, self.center, self.radii, self._pen_refine, out)
        return float(out.max()) if out.size else 0.0


def head_collider(spec) -> Optional[HeadCollider]:
    """The head's row of a :class:`~hair_tracking.core.scene.ColliderSpec` as its kernels take
    it (a sphere is the ellipsoid of three equal radii); ``None`` for shape 'none'.
    ValueError of one line for an unusable spec."""
    if spec.shape == 'none':
        return None
    if spec.shape == 'sphere':
        radii = (spec.radius,) * 3
    elif spec.shape == 'ellipsoid':
        radii = spec.radii
    else:
        raise ValueError(f'collider.shape: {spec.shape!r} is not one of none, sphere, ellipsoid')
    return HeadCollider(spec.shape, spec.center, radii, spec.margin, spec.friction)
