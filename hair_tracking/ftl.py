"""Follow-The-Leader (FTL) guide strands: exactly inextensible in one root-to-tip pass.

Müller, Kim & Chentanez 2012, "Fast Simulation of Inextensible Hair and Fur": after prediction,
walk the strand from the root to the tip and put every node at its rest distance from its
(already placed) predecessor, along the current direction::

    p_i <- p_{i-1} + r_{i-1} (p_i - p_{i-1}) / |p_i - p_{i-1}|,    d_i = p_i(new) - p_i(old)

The correction ``d_i`` is recorded; the velocity update then subtracts ``s_damp d_{i+1} / dt``
from node ``i`` (see :func:`hair_tracking.integrate.finalize_block`), which removes the large
unphysical whip of plain FTL; ``s_damp`` 0.8–0.9 is usual (it adds numerical damping, Han &
Harada 2013). Nodes 0 and 1 are the attached roots and are not moved. A known property of the
correction: in a strand resting under gravity the positions stay put but the stored velocities do
not vanish (each substep gravity's prediction is undone by the pass, and ``v_i = s_damp (v_{i+1} +
g dt)`` settles at up to ``s_damp g dt / (1 - s_damp)``, 0.37 m/s at dt = 1/240 s and
``s_damp = 0.9``); use displacements, not ``v``, to judge whether FTL hair is at rest.

Bending comes first: ``bend_passes`` PBD Gauss–Seidel sweeps of the second-neighbour distance
constraints with ``bend_stiffness`` (:func:`hair_tracking.pbd_constraints.pbd_sweep_block`), then
the FTL pass restores the lengths exactly. ``iterations`` of the scene does not apply to FTL.

Degenerate input: if a segment has collapsed (``|p_i - p_{i-1}| < 1e-12`` m) the node is placed
along the segment's rest direction carried by the head (``R (rest_i - rest_{i-1})``); a
zero rest length places the node on its predecessor. No NaN can arise.
"""
import math

from numba import njit, prange

from hair_tracking.integrate import BLOCK, FASTMATH, finalize_block, predict_block
from hair_tracking.pbd_constraints import pbd_sweep_block

#: Below this squared segment length [m²] the current direction is unreliable.
FTL_TINY_SQ = 1e-24


@njit(cache=True, fastmath=FASTMATH, error_model='numpy')
def ftl_pass_block(x, rest, rest_length, rot, corr, s0, s1):
    """FTL pass over strands ``s0..s1-1`` in place; ``corr`` (S, N, 3) receives the ``d_i``.

    ``rot`` (3, 3) is the head rotation (only used for collapsed segments).
    """
    n = x.shape[1]
    for s in range(s0, s1):
        for i in range(2):
            corr[s, i, 0] = 0.0
            corr[s, i, 1] = 0.0
            corr[s, i, 2] = 0.0
    for i in range(2, n):
        for s in range(s0, s1):
            r = rest_length[s, i - 1]
            dx = x[s, i, 0] - x[s, i - 1, 0]
            dy = x[s, i, 1] - x[s, i - 1, 1]
            dz = x[s, i, 2] - x[s, i - 1, 2]
            l2 = dx * dx + dy * dy + dz * dz
            if l2 > FTL_TINY_SQ:
                f = r / math.sqrt(l2)
            else:
                bx = rest[s, i, 0] - rest[s, i - 1, 0]
                by = rest[s, i, 1] - rest[s, i - 1, 1]
                bz = rest[s, i, 2] - rest[s, i - 1, 2]
                dx = rot[0, 0] * bx + rot[0, 1] * by + rot[0, 2] * bz
                dy = rot[1, 0] * bx + rot[1, 1] * by + rot[1, 2] * bz
                dz = rot[2, 0] * bx + rot[2, 1] * by + rot[2, 2] * bz
                lb2 = bx * bx + by * by + bz * bz
                if lb2 > FTL_TINY_SQ:
                    f = r / math.sqrt(lb2)
                else:
                    dx, dy, dz = 0.0, 0.0, -1.0
                    f = r
            nx = x[s, i - 1, 0] + f * dx
            ny = x[s, i - 1, 1] + f * dy
            nz = x[s, i - 1, 2] + f * dz
            corr[s, i, 0] = nx - x[s, i, 0]
            corr[s, i, 1] = ny - x[s, i, 1]
            corr[s, i, 2] = nz - x[s, i, 2]
            x[s, i, 0] = nx
            x[s, i, 1] = ny
            x[s, i, 2] = nz


@njit(cache=True, parallel=True, fastmath=FASTMATH, error_model='numpy')
def ftl_step(x, v, x_old, corr, rest, inv_mass, rest_length, bend_rest, bend_w,
             rot, pos, rot_rel, pos_prev, gravity, damp, dt, shock,
             bend_passes, bend_stiffness, s_damp, max_disp, do_finalize):
    """Kernel: one FTL substep of all strands (predict, bending, FTL pass, finalize).

    ``bend_w`` from :func:`hair_tracking.pbd_constraints.pair_weights` with gap 2; ``corr``
    (S, N, 3) receives the FTL corrections (needed by :func:`hair_tracking.integrate.finalize`
    when a collider runs before finalizing). ``s_damp`` is the FTL velocity correction 0..1.
    Returns the clamped node count (0 when not finalizing).
    """
    nblk = (x.shape[0] + BLOCK - 1) // BLOCK
    clamped = 0
    for blk in prange(nblk):
        s0 = blk * BLOCK
        s1 = min(s0 + BLOCK, x.shape[0])
        predict_block(x, v, x_old, rest, inv_mass, s0, s1, rot, pos, rot_rel, pos_prev,
                      gravity, damp, dt, shock)
        if bend_stiffness > 0.0:
            for _ in range(bend_passes):
                pbd_sweep_block(x, bend_rest, bend_w, 2, bend_stiffness, s0, s1)
        ftl_pass_block(x, rest, rest_length, rot, corr, s0, s1)
        if do_finalize:
            clamped += finalize_block(x, v, x_old, inv_mass, corr, s0, s1, dt, max_disp, s_damp)
    return clamped
