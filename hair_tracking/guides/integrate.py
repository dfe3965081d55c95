"""Time integration of guide strands: the parts of a substep around the constraint projection.

One substep of a guide solver (see :mod:`hair_tracking.guides.solver`) is

1. **predict** (:func:`predict_block`): the attached roots (nodes 0 and 1) are placed
   kinematically at ``head.to_world(rest[:, :2])``; the free nodes are optionally carried with the
   head's rigid motion (velocity shock propagation, TressFX 4.1, AMD 2017), their velocity gets
   damping and gravity by explicit (symplectic) Euler and the predicted positions are
   ``p = x + v dt`` (Müller, Heidelberger, Hennix & Ratcliff 2007, "Position Based Dynamics");
2. constraint projection (:mod:`~hair_tracking.guides.pbd_constraints`,
   :mod:`~hair_tracking.guides.ftl`);
3. optional head collision (:mod:`~hair_tracking.colliders.head`);
4. **finalize** (:func:`finalize_block`, kernel :func:`finalize`): per-substep displacement clamp
   and the velocity update ``v = (p - x) / dt``, with the Follow-The-Leader damping correction
   ``v_i -= s_damp d_{i+1} / dt`` (Müller, Kim & Chentanez 2012) when ``s_damp > 0``.

Shock propagation with coefficient ``s`` (0..1) moves every free node by the fraction ``s`` of the
head's rigid motion ``M(p) = R_rel (p - t_prev) + t`` (``R_rel = R R_prev^T``) and rotates its
velocity by the same fraction *before* integrating; the old positions are carried too, so the
carried displacement is not counted as velocity (it would otherwise be applied twice on the next
substep, as in TressFX, which carries both the current and the previous positions). With ``s > 0``
the stored ``v`` is therefore the velocity relative to the carried fraction of the head's motion;
with ``s = 0`` it is the world-frame velocity.

All positions are in the world frame [m], velocities [m/s], ``dt`` [s]; rest shapes in the head
frame. Arrays are C-contiguous float64 ``(S, N, 3)``. The block helpers work on the strands
``s0 <= s < s1`` so that a fused solver kernel can run them back to back on a block of strands
while it is in cache (see :data:`BLOCK`).
"""
from collections import namedtuple
import math

import numpy as np
from numba import njit, prange

from hair_tracking.core.kernels import BLOCK, FASTMATH, parallel_and_serial


#: Arguments of the guide kernels (:func:`hair_tracking.guides.pbd_constraints.pbd_step`,
#: :func:`~hair_tracking.guides.pbd_constraints.xpbd_step`,
#: :func:`hair_tracking.guides.ftl.ftl_step`), grouped as NVIDIA Warp / Newton separate a
#: solver's inputs.  The kernels take them as plain tuples in these fields' order
#: (``tuple(GuideState(x, v, x_old))``): numba types a named tuple by encoding its class and
#: field names on every call.
#: The guides' state, advanced in place: positions ``x`` and velocities ``v`` (S, N, 3) [m],
#: [m/s], and ``x_old`` (S, N, 3), written: the start positions after the rigid carry.
GuideState = namedtuple('GuideState', ['x', 'v', 'x_old'])
#: What drives one substep (the predict stage, :func:`predict_block`): head pose ``rot`` (3, 3),
#: ``pos`` (3,) now, ``rot_rel`` = ``rot rot_prev^T`` and ``pos_prev`` of the previous pose,
#: ``gravity`` (3,) [m/s^2], ``damp`` = exp(-damping dt), ``dt`` [s], ``shock`` 0..1, ``shape``
#: the pull toward the groomed shape [1/s^2] (``solver.shape_stiffness``; 0: none).
StepMotion = namedtuple('StepMotion', ['rot', 'pos', 'rot_rel', 'pos_prev', 'gravity', 'damp',
                                       'dt', 'shock', 'shape'])


def block_count(strands: int) -> int:
    """Number of :data:`BLOCK`-sized groups covering ``strands`` strands."""
    return (strands + BLOCK - 1) // BLOCK


def relative_rotation(rot_prev, rot):
    """``R_rel = R R_prev^T`` (3, 3): the head's rigid motion over a substep is
    ``M(p) = R_rel (p - t_prev) + t`` for head rotations ``R_prev`` -> ``R`` and positions
    ``t_prev`` -> ``t``."""
    out = np.empty((3, 3))
    head_motion(np.ascontiguousarray(rot_prev, dtype=np.float64), np.zeros(3),
                np.ascontiguousarray(rot, dtype=np.float64), np.zeros(3), out)
    return out


@njit(cache=True)
def head_motion(rot_prev, pos_prev, rot, pos, rot_rel):
    """Write ``R_rel = R R_prev^T`` into ``rot_rel`` (3, 3); True if all four inputs are finite.

    One small compiled call instead of several numpy calls: the per-substep Python overhead of
    the solver matters at real-time rates.
    """
    ok = True
    for i in range(3):
        ok = ok and math.isfinite(pos[i]) and math.isfinite(pos_prev[i])
        for j in range(3):
            ok = ok and math.isfinite(rot[i, j]) and math.isfinite(rot_prev[i, j])
            rot_rel[i, j] = (rot[i, 0] * rot_prev[j, 0] + rot[i, 1] * rot_prev[j, 1]
                             + rot[i, 2] * rot_prev[j, 2])
    return ok


@njit(cache=True)
def head_motions(rots, poss, rels):
    """:func:`head_motion` of every substep of a run: ``rels[k]`` (K, 3, 3) from the poses
    ``rots`` (K + 1, 3, 3), ``poss`` (K + 1, 3) at the start and at the end of each substep;
    True if all are finite."""
    ok = True
    for k in range(rels.shape[0]):
        ok = head_motion(rots[k], poss[k], rots[k + 1], poss[k + 1], rels[k]) and ok
    return ok


@njit(cache=True, fastmath=FASTMATH, error_model='numpy')
def predict_block(state, rest, inv_mass, motion, s0, s1):
    """Predict positions of strands ``s0..s1-1`` in place (step 1 of the module docstring).

    ``state``: the fields of :data:`GuideState`; on return ``x_old`` holds the (carried)
    start-of-substep positions and ``x`` the predicted positions (roots at ``rot @ rest +
    pos``). ``v`` is read, not written: the velocity of the substep is set by
    :func:`finalize_block` from the displacement (saves a pass over memory).

    ``motion``: the fields of :data:`StepMotion`: ``rot``/``pos`` head pose at the end of the
    substep; ``rot_rel``/``pos_prev`` the head motion (see :func:`relative_rotation`);
    ``gravity`` (3,) [m/s^2] world frame; ``damp`` the velocity factor ``exp(-damping dt)``;
    ``shock`` the shock-propagation fraction 0..1; ``shape`` [1/s^2] the stiffness of a spring
    pulling every free node toward its rest place carried by the head, ``rot @ rest + pos``
    (the global shape constraint of Han & Harada 2012, "Real-time hair simulation with
    efficient hair style preservation", as a force), integrated implicitly (backward Euler:
    ``v' = (v damp + g dt + k dt (target - p)) / (1 + k dt^2)``, stable at any stiffness and
    step).  Nodes with ``inv_mass == 0`` beyond the roots are carried but not integrated
    (static).
    """
    x, v, x_old = state
    rot, pos, rot_rel, pos_prev, gravity, damp, dt, shock, shape = motion
    spring = shape_spring(shape, dt)
    n = x.shape[1]
    r00, r01, r02 = rot[0, 0], rot[0, 1], rot[0, 2]
    r10, r11, r12 = rot[1, 0], rot[1, 1], rot[1, 2]
    r20, r21, r22 = rot[2, 0], rot[2, 1], rot[2, 2]
    q00, q01, q02 = rot_rel[0, 0], rot_rel[0, 1], rot_rel[0, 2]
    q10, q11, q12 = rot_rel[1, 0], rot_rel[1, 1], rot_rel[1, 2]
    q20, q21, q22 = rot_rel[2, 0], rot_rel[2, 1], rot_rel[2, 2]
    tx, ty, tz = pos[0], pos[1], pos[2]
    ux, uy, uz = pos_prev[0], pos_prev[1], pos_prev[2]
    gx, gy, gz = gravity[0] * dt, gravity[1] * dt, gravity[2] * dt
    for s in range(s0, s1):
        for i in range(n):
            px, py, pz = x[s, i, 0], x[s, i, 1], x[s, i, 2]
            vx, vy, vz = v[s, i, 0], v[s, i, 1], v[s, i, 2]
            if shock > 0.0:
                # carry by the fraction `shock` of the head's rigid motion M
                ax, ay, az = px - ux, py - uy, pz - uz
                mx = q00 * ax + q01 * ay + q02 * az + tx
                my = q10 * ax + q11 * ay + q12 * az + ty
                mz = q20 * ax + q21 * ay + q22 * az + tz
                px += shock * (mx - px)
                py += shock * (my - py)
                pz += shock * (mz - pz)
                wx = q00 * vx + q01 * vy + q02 * vz
                wy = q10 * vx + q11 * vy + q12 * vz
                wz = q20 * vx + q21 * vy + q22 * vz
                vx += shock * (wx - vx)
                vy += shock * (wy - vy)
                vz += shock * (wz - vz)
            x_old[s, i, 0] = px
            x_old[s, i, 1] = py
            x_old[s, i, 2] = pz
            if i < 2:
                # attached root: kinematic, pins the root position and the root direction
                bx, by, bz = rest[s, i, 0], rest[s, i, 1], rest[s, i, 2]
                x[s, i, 0] = r00 * bx + r01 * by + r02 * bz + tx
                x[s, i, 1] = r10 * bx + r11 * by + r12 * bz + ty
                x[s, i, 2] = r20 * bx + r21 * by + r22 * bz + tz
            elif inv_mass[s, i] > 0.0:
                vx = vx * damp + gx
                vy = vy * damp + gy
                vz = vz * damp + gz
                if shape > 0.0:
                    vx, vy, vz = shape_pulled(vx, vy, vz, px, py, pz, rest[s, i], rot, pos,
                                              spring)
                x[s, i, 0] = px + vx * dt
                x[s, i, 1] = py + vy * dt
                x[s, i, 2] = pz + vz * dt
            else:
                x[s, i, 0] = px
                x[s, i, 1] = py
                x[s, i, 2] = pz


@njit(cache=True, inline='always', fastmath=FASTMATH, error_model='numpy')
def shape_spring(shape, dt):
    """The shape spring of stiffness ``shape`` [1/s^2] over a step ``dt`` [s] as
    :func:`shape_pulled` takes it: ``(k dt, 1 / (1 + k dt^2))``."""
    kdt = shape * dt
    return kdt, 1.0 / (1.0 + kdt * dt)


@njit(cache=True, inline='always', fastmath=FASTMATH, error_model='numpy')
def shape_pulled(vx, vy, vz, px, py, pz, rest_node, rot, pos, spring):
    """The velocity ``v`` of a node at ``p`` after the shape spring's implicit step toward its
    rest place ``rest_node`` (3,) carried by the head pose ``rot``, ``pos``: ``(v + k dt
    (target - p)) / (1 + k dt^2)``, with ``spring`` from :func:`shape_spring`
    (:func:`predict_block`)."""
    kdt, keep = spring
    bx, by, bz = rest_node[0], rest_node[1], rest_node[2]
    return ((vx + kdt * (rot[0, 0] * bx + rot[0, 1] * by + rot[0, 2] * bz + pos[0] - px)) * keep,
            (vy + kdt * (rot[1, 0] * bx + rot[1, 1] * by + rot[1, 2] * bz + pos[1] - py)) * keep,
            (vz + kdt * (rot[2, 0] * bx + rot[2, 1] * by + rot[2, 2] * bz + pos[2] - pz)) * keep)


@njit(cache=True, inline='always', fastmath=FASTMATH, error_model='numpy')
def capped(dx, dy, dz, max_disp, lim2):
    """The step ``d`` scaled down to the length ``max_disp`` [m] when longer (``lim2`` its
    square; ``max_disp`` 0: no cap), and whether it was."""
    if max_disp > 0.0:
        d2 = dx * dx + dy * dy + dz * dz
        if d2 > lim2:
            f = max_disp / math.sqrt(d2)
            return dx * f, dy * f, dz * f, True
    return dx, dy, dz, False


@njit(cache=True, fastmath=FASTMATH, error_model='numpy')
def finalize_block(x, v, x_old, inv_mass, corr, s0, s1, dt, max_disp, s_damp):
    """Displacement clamp and velocity update of strands ``s0..s1-1``; returns the clamped count.

    For every node with ``inv_mass > 0``: if ``max_disp > 0`` and ``|x - x_old| > max_disp`` [m]
    the displacement is scaled down to ``max_disp``; then ``v = (x - x_old) / dt``, minus
    ``s_damp * corr[i+1] / dt`` (Follow-The-Leader damping; ``corr`` is only read when
    ``s_damp > 0``) and, with the clamp on, ``|v| dt`` is capped at ``max_disp`` as well (so the
    FTL correction cannot inject more than the clamp allows). A node counts once as clamped.
    Kinematic nodes (``inv_mass == 0``) only get ``v = (x - x_old) / dt``.
    """
    n = x.shape[1]
    inv_dt = 1.0 / dt
    lim2 = max_disp * max_disp
    clamped = 0
    for s in range(s0, s1):
        for i in range(n):
            dx = x[s, i, 0] - x_old[s, i, 0]
            dy = x[s, i, 1] - x_old[s, i, 1]
            dz = x[s, i, 2] - x_old[s, i, 2]
            hit = False
            if inv_mass[s, i] > 0.0:
                dx, dy, dz, hit = capped(dx, dy, dz, max_disp, lim2)
                if hit:
                    x[s, i, 0] = x_old[s, i, 0] + dx
                    x[s, i, 1] = x_old[s, i, 1] + dy
                    x[s, i, 2] = x_old[s, i, 2] + dz
                if s_damp > 0.0 and i + 1 < n:
                    dx, dy, dz, damped_hit = capped(dx - s_damp * corr[s, i + 1, 0],
                                                    dy - s_damp * corr[s, i + 1, 1],
                                                    dz - s_damp * corr[s, i + 1, 2],
                                                    max_disp, lim2)
                    hit = hit or damped_hit
            v[s, i, 0] = dx * inv_dt
            v[s, i, 1] = dy * inv_dt
            v[s, i, 2] = dz * inv_dt
            if hit:
                clamped += 1
    return clamped


@njit(cache=True, error_model='numpy')
def max_step_sq(x, x_old):
    """Largest squared displacement ``|x - x_old|^2`` of a node [m^2] (the simulator's speed
    estimate for splitting substeps); one serial pass, no temporary arrays.  NaN if any
    displacement is NaN."""
    return max_step_sq_block(x, x_old, 0, x.shape[0])


@njit(cache=True, error_model='numpy')
def max_step_sq_block(x, x_old, s0, s1):
    """:func:`max_step_sq` of the strands ``s0 <= s < s1``."""
    best = 0.0
    for s in range(s0, s1):
        for i in range(x.shape[1]):
            d0 = x[s, i, 0] - x_old[s, i, 0]
            d1 = x[s, i, 1] - x_old[s, i, 1]
            d2 = x[s, i, 2] - x_old[s, i, 2]
            d = d0 * d0 + d1 * d1 + d2 * d2
            if d > best or d != d:
                best = d
    return best


def finalize(x, v, x_old, inv_mass, corr, dt, max_disp, s_damp):
    """Kernel: :func:`finalize_block` over all strands (used when a collider runs in between)."""
    total = 0
    for s in prange(x.shape[0]):
        i = np.int64(s)       # (the index as in the serial variant: one compiled block body)
        total += finalize_block(x, v, x_old, inv_mass, corr, i, i + 1, dt, max_disp, s_damp)
    return total


finalize, finalize_serial = parallel_and_serial(finalize, fastmath=FASTMATH, error_model='numpy')


def carry_rigid(x, rot_rel, pos_prev, pos, out):
    """Kernel: ``out = R_rel (x - pos_prev) + pos``, the points moved rigidly with the head.

    Used as the friction reference of the collider: where a node would be had it stuck to the
    head during the substep.
    """
    for s in prange(x.shape[0]):
        i = np.int64(s)       # (the index as in the serial variant: one compiled block body)
        carry_rigid_block(x, rot_rel, pos_prev, pos, out, i, i + 1)


carry_rigid, carry_rigid_serial = parallel_and_serial(
    carry_rigid, fastmath=FASTMATH, error_model='numpy')


@njit(cache=True, fastmath=FASTMATH, error_model='numpy')
def carry_rigid_block(x, rot_rel, pos_prev, pos, out, s0, s1):
    """:func:`carry_rigid` of the strands ``s0 <= s < s1``."""
    q00, q01, q02 = rot_rel[0, 0], rot_rel[0, 1], rot_rel[0, 2]
    q10, q11, q12 = rot_rel[1, 0], rot_rel[1, 1], rot_rel[1, 2]
    q20, q21, q22 = rot_rel[2, 0], rot_rel[2, 1], rot_rel[2, 2]
    n = x.shape[1]
    for s in range(s0, s1):
        for i in range(n):
            ax = x[s, i, 0] - pos_prev[0]
            ay = x[s, i, 1] - pos_prev[1]
            az = x[s, i, 2] - pos_prev[2]
            out[s, i, 0] = q00 * ax + q01 * ay + q02 * az + pos[0]
            out[s, i, 1] = q10 * ax + q11 * ay + q12 * az + pos[1]
            out[s, i, 2] = q20 * ax + q21 * ay + q22 * az + pos[2]
