"""The shapes in the world at one substep: the posed table the contact kernels read.

A shape rides on its frame: its centre is ``C = R_f c + O_f`` and its axes ``R = R_f R_c`` for
the frame's pose ``(R_f, O_f)`` and the shape's centre ``c`` and axes ``R_c`` in the frame
(:mod:`hair_tracking.colliders.shapes`). The frame's motion over the substep, ``M = R_f
R_fp^T`` and the origins ``O_f``, ``O_fp`` now and at the previous substep, is kept with it:
:func:`~hair_tracking.colliders.contact.carried` moves a point as the shape moved
(``M (x - O_fp) + O_f``), which is what friction and the push-out velocity bound measure the
hair's motion against.

A frame whose pose changed by more than a body moves in a substep is taken to have *jumped*
(a re-detected person, a TF glitch, a reset): when the largest displacement of a point of the
shape, ``|C - C_prev| + angle(M) * bound radius``, exceeds ``jump`` [m], its motion is set to
none (``M = I``, ``O_fp = O_f``), so the hair it now overlaps is pushed out without being
given the jump as velocity. Pass ``math.inf`` to never declare a jump.

The arithmetic of the ellipsoid's columns is the head collider's, in the same order and with
the same compile flags (the centre and quadric as ``R c + p`` and ``R diag(1 / a^2) R^T`` with
fused multiply-adds, the frame motion without), so a head ellipsoid posed here gives the
projections of the copies it replaces bit for bit.
"""
import math

import numpy as np
from numba import njit

from hair_tracking.colliders.contact import FASTMATH, rotation_of
from hair_tracking.colliders.shapes import (A0, A1, A2, BOUND, BOUND_PAD, CAPSULE, CX, CY, CZ,
                                            ELLIPSOID, FRICTION, I0, I1, I2, KIND, L_CX, L_CY,
                                            L_CZ, L_FRAME, L_FRICTION, L_KIND, L_MARGIN, L_R00,
                                            L_REFINE, L_ROTATED, L_S0, L_S1, L_S2, M00, MARGIN,
                                            OX, OY, OZ, PLANE, PX, PY, PZ, Q00, R00, REFINE,
                                            WIDTH)


#: [m] The reach over which a plane's turn counts as its displacement in the jump test.
PLANE_SPAN = 1.0


@njit(cache=True, fastmath=False, error_model='numpy')
def frame_motion(rot, rot_prev, out, k):
    """``out[k, M00:M22 + 1]`` = ``rot rot_prev^T`` (row-major), without fused multiply-adds
    (the arithmetic of the guide solver's head motion; ``fastmath=False`` is explicit because
    numba lets a function that does not set it inherit its caller's flags)."""
    for i in range(3):
        for j in range(3):
            out[k, M00 + 3 * i + j] = (rot[i, 0] * rot_prev[j, 0] + rot[i, 1] * rot_prev[j, 1]
                                       + rot[i, 2] * rot_prev[j, 2])


@njit(cache=True, inline='always')
def _world(rot, pos, local, k):
    """``rot c + pos`` for the centre ``c`` of row ``k`` of the local table."""
    return (rot[0, 0] * local[k, L_CX] + rot[0, 1] * local[k, L_CY] + rot[0, 2] * local[k, L_CZ]
            + pos[0],
            rot[1, 0] * local[k, L_CX] + rot[1, 1] * local[k, L_CY] + rot[1, 2] * local[k, L_CZ]
            + pos[1],
            rot[2, 0] * local[k, L_CX] + rot[2, 1] * local[k, L_CY] + rot[2, 2] * local[k, L_CZ]
            + pos[2])


@njit(cache=True, fastmath=FASTMATH, error_model='numpy')
def pose_shapes(local, rot, pos, rot_prev, pos_prev, jump, out):
    """Kernel: ``out`` (K, :data:`~hair_tracking.colliders.shapes.WIDTH`) the posed table of
    the local table ``local`` (K, L) for the frames' poses ``rot`` (F, 3, 3), ``pos`` (F, 3)
    now and ``rot_prev``, ``pos_prev`` at the previous substep (frame 0 the fixed frame, 1 the
    head, then the TF frames of the table); ``jump`` [m] see the module docstring."""
    for k in range(local.shape[0]):
        f = int(local[k, L_FRAME])
        kind = int(local[k, L_KIND])
        rf, of = rot[f], pos[f]
        out[k, KIND] = local[k, L_KIND]
        out[k, CX], out[k, CY], out[k, CZ] = _world(rf, of, local, k)
        for i in range(3):
            for j in range(3):
                if local[k, L_ROTATED] == 0.0:
                    out[k, R00 + 3 * i + j] = rf[i, j]
                else:
                    out[k, R00 + 3 * i + j] = (rf[i, 0] * local[k, L_R00 + j]
                                               + rf[i, 1] * local[k, L_R00 + 3 + j]
                                               + rf[i, 2] * local[k, L_R00 + 6 + j])
        margin = local[k, L_MARGIN]
        out[k, MARGIN] = margin
        out[k, FRICTION] = local[k, L_FRICTION]
        out[k, REFINE] = local[k, L_REFINE]
        for i in range(6):
            out[k, Q00 + i] = 0.0
        if kind == ELLIPSOID:
            ax, ay, az = local[k, L_S0] + margin, local[k, L_S1] + margin, \
                local[k, L_S2] + margin
            out[k, A0], out[k, A1], out[k, A2] = ax, ay, az
            out[k, I0], out[k, I1], out[k, I2] = 1.0 / (ax * ax), 1.0 / (ay * ay), \
                1.0 / (az * az)
            out[k, BOUND] = max(ax, ay, az) * (1.0 + BOUND_PAD)
            _quadric(out, k)
        elif kind == PLANE:
            out[k, A0], out[k, A1], out[k, A2] = margin, 0.0, 0.0
            out[k, I0], out[k, I1], out[k, I2] = 0.0, 0.0, 0.0
            out[k, BOUND] = math.inf
        else:                                    # sphere, capsule
            r = local[k, L_S0] + margin
            h = local[k, L_S1] if kind == CAPSULE else 0.0
            out[k, A0], out[k, A1], out[k, A2] = r, h, 0.0
            out[k, I0], out[k, I1], out[k, I2] = 1.0 / (r * r), 0.0, 0.0
            out[k, BOUND] = (r + h) * (1.0 + BOUND_PAD)
        out[k, OX], out[k, OY], out[k, OZ] = of[0], of[1], of[2]
        out[k, PX], out[k, PY], out[k, PZ] = pos_prev[f, 0], pos_prev[f, 1], pos_prev[f, 2]
        frame_motion(rf, rot_prev[f], out, k)
        if jump < math.inf and _jumped(local, k, kind, rot_prev[f], pos_prev[f], out, jump):
            for i in range(9):
                out[k, M00 + i] = 1.0 if i % 4 == 0 else 0.0
            out[k, PX], out[k, PY], out[k, PZ] = of[0], of[1], of[2]


@njit(cache=True, inline='always')
def _jumped(local, k, kind, rot_prev, pos_prev, out, jump):
    """Whether shape ``k`` (posed in ``out``, its frame's motion included) moved farther than
    ``jump`` [m] in the substep: its centre's displacement plus its turn times its bounding
    radius (a plane: its offset along its normal plus its turn times :data:`PLANE_SPAN`)."""
    bx, by, bz = _world(rot_prev, pos_prev, local, k)
    turn = 0.5 * (out[k, M00] + out[k, M00 + 4] + out[k, M00 + 8] - 1.0)
    angle = math.acos(min(1.0, max(-1.0, turn)))
    dx, dy, dz = out[k, CX] - bx, out[k, CY] - by, out[k, CZ] - bz
    if kind == PLANE:
        shift = abs(dx * out[k, R00 + 2] + dy * out[k, R00 + 5] + dz * out[k, R00 + 8])
        return shift + angle * PLANE_SPAN > jump
    return math.sqrt(dx * dx + dy * dy + dz * dz) + angle * out[k, BOUND] > jump


@njit(cache=True, inline='always')
def world_quadric(rot, inv, out, at):
    """The ellipsoid's world quadric ``R diag(inv) R^T`` into ``out[at:at + 6]`` (entries Q00
    Q11 Q22 Q01 Q02 Q12): ``rot`` its axes' nine entries row by row (``R_ij`` at ``3 i + j``),
    ``inv`` its inverse squared semi-axes.  The posed table's columns and the stateless
    trackers' head collider (:func:`~hair_tracking.ghosts.stateless.world_collider`)."""
    for n, (a, b) in enumerate(((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))):
        out[at + n] = rot[3 * a] * rot[3 * b] * inv[0] + \
            rot[3 * a + 1] * rot[3 * b + 1] * inv[1] + rot[3 * a + 2] * rot[3 * b + 2] * inv[2]


@njit(cache=True, inline='always')
def _quadric(out, k):
    """The ellipsoid quadric of row ``k`` (:func:`world_quadric`)."""
    world_quadric(rotation_of(out, k), (out[k, I0], out[k, I1], out[k, I2]), out[k], Q00)


@njit(cache=True)
def pose_run(local, rots, poss, jump, out):
    """Kernel: ``out[k]`` the posed table of substep ``k`` (K substeps) for the frames' poses
    ``rots`` (K + 1, F, 3, 3), ``poss`` (K + 1, F, 3) at the start of the first substep and at
    the end of every substep (as the guide solver's run of substeps takes the head's)."""
    for k in range(out.shape[0]):
        pose_shapes(local, rots[k + 1], poss[k + 1], rots[k], poss[k], jump, out[k])


def posed(local, rot, pos, rot_prev=None, pos_prev=None, jump: float = math.inf) -> np.ndarray:
    """A new posed table (K, WIDTH) of the local table ``local`` for the frames ``rot`` (F, 3,
    3), ``pos`` (F, 3) (the previous substep's the same when not given: frames at rest)."""
    rot = np.ascontiguousarray(rot, dtype=np.float64)
    pos = np.ascontiguousarray(pos, dtype=np.float64)
    rot_prev = rot if rot_prev is None else np.ascontiguousarray(rot_prev, dtype=np.float64)
    pos_prev = pos if pos_prev is None else np.ascontiguousarray(pos_prev, dtype=np.float64)
    frames = int(local[:, 1].max()) + 1 if local.shape[0] else 0
    if rot.shape[0] < frames or pos.shape[0] < frames:
        raise ValueError(f'colliders: the table names {frames} frames, got poses of '
                         f'{rot.shape[0]}')
    out = np.empty((local.shape[0], WIDTH))
    pose_shapes(np.ascontiguousarray(local), rot, pos, rot_prev, pos_prev, float(jump), out)
    return out


def frames_at(head_rot, head_pos, others=()) -> tuple:
    """``(rot (F, 3, 3), pos (F, 3))`` of the frames a table indexes: the fixed frame (the
    identity), the head pose, then ``others`` (a sequence of ``(rot, pos)``)."""
    rots = [np.eye(3), np.asarray(head_rot, dtype=np.float64)]
    poss = [np.zeros(3), np.asarray(head_pos, dtype=np.float64)]
    for r, p in others:
        rots.append(np.asarray(r, dtype=np.float64))
        poss.append(np.asarray(p, dtype=np.float64))
    return np.ascontiguousarray(rots), np.ascontiguousarray(poss)
