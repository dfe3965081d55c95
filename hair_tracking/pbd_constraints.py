"""Distance constraints of guide strands: classic PBD and XPBD Gauss–Seidel sweeps, fused kernels.

Two families of distance constraints ``C(p_i, p_j) = |p_j - p_i| - r`` per strand:

- stretching, between neighbours ``(i, i+1)``, rest distance ``rest_length`` (``StrandSet``);
- bending, between second neighbours ``(i, i+2)``, rest distance from the rest shape
  (:func:`second_neighbour_rest`) — the bending model the paper leaves open (the digest allows a
  dihedral or a second-neighbour distance; the latter is cheap and direction-free).

**PBD** (Müller, Heidelberger, Hennix & Ratcliff 2007): each projection moves the two nodes by
``dp_i = +k w_i/(w_i+w_j) C n``, ``dp_j = -k w_j/(w_i+w_j) C n`` with ``n = (p_j-p_i)/|p_j-p_i|``
and stiffness ``k`` in (0, 1]. The effective stiffness depends on the iteration count (each
iteration removes a fraction of the error), which the tests document.

**XPBD** (Macklin, Müller & Chentanez 2016, "XPBD: Position-Based Simulation of Compliant
Constrained Dynamics"): one Lagrange multiplier per constraint, reset to 0 at the start of each
substep, ``dλ = (-C - α̃ λ) / (w_i + w_j + α̃)`` with ``α̃ = α / dt²`` (``α`` the compliance,
inverse stiffness, [m/N]), ``λ += dλ``, ``dp_i = -w_i n dλ``, ``dp_j = +w_j n dλ``. ``α = 0`` is a
rigid constraint; the stiffness no longer depends on the iteration count once converged.

Sweeps are Gauss–Seidel, root to tip: each iteration projects all stretch constraints, then all
bending constraints. Inside a block of strands the strand index is the innermost loop, so the
independent strands' dependency chains overlap in the CPU (see :data:`integrate.BLOCK`); every
strand is still projected in the same order with the same arithmetic, so the result of a strand
does not depend on its block or on the thread count.

Zero-length segments are safe: ``1/|d|`` is computed as ``1/sqrt(max(|d|², 1e-30))``, so a
degenerate pair moves by at most about its rest distance and never produces NaN.
"""
import math

import numpy as np
from numba import njit, prange

from hair_tracking.integrate import (BLOCK, FASTMATH, finalize_block, NO_REFCOUNT,
                                     predict_block, serial_twin)

#: Floor of ``|p_j - p_i|²`` [m²] when inverting a distance (zero-length segments).
TINY_SQ = 1e-30


def second_neighbour_rest(rest: np.ndarray) -> np.ndarray:
    """Rest distances ``|rest[:, i+2] - rest[:, i]|`` (S, N-2) [m] of the bending constraints."""
    rest = np.asarray(rest, dtype=np.float64)
    return np.ascontiguousarray(np.linalg.norm(rest[:, 2:] - rest[:, :-2], axis=2))


def pair_weights(inv_mass: np.ndarray, gap: int) -> np.ndarray:
    """PBD mass split of the constraints between nodes ``(i, i+gap)``: (S, N-gap, 2).

    ``[..., 0] = w_i / (w_i + w_j)``, ``[..., 1] = w_j / (w_i + w_j)``; both 0 where both nodes are
    pinned (the constraint is then skipped).
    """
    inv_mass = np.asarray(inv_mass, dtype=np.float64)
    wi, wj = inv_mass[:, :-gap], inv_mass[:, gap:]
    ws = wi + wj
    out = np.zeros(wi.shape + (2,))
    np.divide(wi, ws, out=out[..., 0], where=ws > 0)
    np.divide(wj, ws, out=out[..., 1], where=ws > 0)
    return out


def xpbd_gain(inv_mass: np.ndarray, gap: int, alpha_tilde: float) -> np.ndarray:
    """XPBD denominators ``1 / (w_i + w_j + α̃)`` (S, N-gap); 0 where both nodes are pinned."""
    inv_mass = np.asarray(inv_mass, dtype=np.float64)
    ws = inv_mass[:, :-gap] + inv_mass[:, gap:]
    out = np.zeros(ws.shape)
    np.divide(1.0, ws + alpha_tilde, out=out, where=ws > 0)
    return out


@njit(cache=True, fastmath=FASTMATH, error_model='numpy', **NO_REFCOUNT)
def pbd_sweep_block(x, rest_dist, weights, gap, k, s0, s1):
    """One PBD Gauss–Seidel sweep over the constraints ``(i, i+gap)`` of strands ``s0..s1-1``.

    ``rest_dist`` (S, N-gap) [m]; ``weights`` from :func:`pair_weights`; ``k`` stiffness.
    """
    n = x.shape[1]
    for i in range(n - gap):
        j = i + gap
        for s in range(s0, s1):
            a = k * weights[s, i, 0]
            c = k * weights[s, i, 1]
            if a == 0.0 and c == 0.0:
                continue
            dx = x[s, j, 0] - x[s, i, 0]
            dy = x[s, j, 1] - x[s, i, 1]
            dz = x[s, j, 2] - x[s, i, 2]
            l2 = dx * dx + dy * dy + dz * dz
            f = 1.0 - rest_dist[s, i] / math.sqrt(max(l2, TINY_SQ))   # C / |d|
            a *= f
            c *= f
            x[s, i, 0] += a * dx
            x[s, i, 1] += a * dy
            x[s, i, 2] += a * dz
            x[s, j, 0] -= c * dx
            x[s, j, 1] -= c * dy
            x[s, j, 2] -= c * dz


@njit(cache=True, fastmath=FASTMATH, error_model='numpy', **NO_REFCOUNT)
def xpbd_sweep_block(x, inv_mass, rest_dist, gain, lam, gap, alpha_tilde, s0, s1):
    """One XPBD Gauss–Seidel sweep over the constraints ``(i, i+gap)`` of strands ``s0..s1-1``.

    ``gain`` from :func:`xpbd_gain` for the same ``alpha_tilde``; ``lam`` (S, N-gap) the
    multipliers of this substep (updated in place).
    """
    n = x.shape[1]
    for i in range(n - gap):
        j = i + gap
        for s in range(s0, s1):
            g = gain[s, i]
            if g == 0.0:
                continue
            dx = x[s, j, 0] - x[s, i, 0]
            dy = x[s, j, 1] - x[s, i, 1]
            dz = x[s, j, 2] - x[s, i, 2]
            l2 = dx * dx + dy * dy + dz * dz
            inv_l = 1.0 / math.sqrt(max(l2, TINY_SQ))
            c = l2 * inv_l - rest_dist[s, i]
            dlam = (-c - alpha_tilde * lam[s, i]) * g
            lam[s, i] += dlam
            h = dlam * inv_l
            a = inv_mass[s, i] * h
            b = inv_mass[s, j] * h
            x[s, i, 0] -= a * dx
            x[s, i, 1] -= a * dy
            x[s, i, 2] -= a * dz
            x[s, j, 0] += b * dx
            x[s, j, 1] += b * dy
            x[s, j, 2] += b * dz


@njit(cache=True, nogil=True, parallel=True, fastmath=FASTMATH, error_model='numpy')
def pbd_step(x, v, x_old, rest, inv_mass, rest_length, bend_rest, stretch_w, bend_w,
             rot, pos, rot_rel, pos_prev, gravity, damp, dt, shock,
             iterations, stiffness, bend_stiffness, max_disp, do_finalize):
    """Kernel: one PBD substep of all strands (predict, ``iterations`` sweeps, finalize).

    Per block of strands: :func:`integrate.predict_block`, then ``iterations`` times a stretch
    sweep (stiffness ``stiffness``) and a bending sweep (``bend_stiffness``, skipped when 0), then
    — if ``do_finalize`` (no collider in between) — :func:`integrate.finalize_block`. Returns the
    number of clamped nodes (0 when not finalizing). ``stretch_w``/``bend_w`` from
    :func:`pair_weights` with gap 1 and 2. Units: see :mod:`hair_tracking.integrate`.
    """
    nblk = (x.shape[0] + BLOCK - 1) // BLOCK
    clamped = 0
    for blk in prange(nblk):
        s0 = blk * BLOCK
        s1 = min(s0 + BLOCK, x.shape[0])
        predict_block(x, v, x_old, rest, inv_mass, s0, s1, rot, pos, rot_rel, pos_prev,
                      gravity, damp, dt, shock)
        for _ in range(iterations):
            pbd_sweep_block(x, rest_length, stretch_w, 1, stiffness, s0, s1)
            if bend_stiffness > 0.0:
                pbd_sweep_block(x, bend_rest, bend_w, 2, bend_stiffness, s0, s1)
        if do_finalize:
            clamped += finalize_block(x, v, x_old, inv_mass, x_old, s0, s1, dt, max_disp, 0.0)
    return clamped


@njit(cache=True, nogil=True, parallel=True, fastmath=FASTMATH, error_model='numpy')
def xpbd_step(x, v, x_old, rest, inv_mass, rest_length, bend_rest, stretch_gain, bend_gain,
              lam_stretch, lam_bend, rot, pos, rot_rel, pos_prev, gravity, damp, dt, shock,
              iterations, alpha_stretch, alpha_bend, max_disp, do_finalize):
    """Kernel: one XPBD substep of all strands (predict, reset λ, ``iterations`` sweeps, finalize).

    ``alpha_stretch``/``alpha_bend`` are the time-step scaled compliances ``α̃ = α / dt²``;
    ``stretch_gain``/``bend_gain`` from :func:`xpbd_gain` with the same ``α̃``; ``lam_*`` scratch
    (S, N-1) and (S, N-2), reset here. A negative ``alpha_bend`` disables bending. Returns the
    clamped node count (0 when not finalizing).
    """
    nblk = (x.shape[0] + BLOCK - 1) // BLOCK
    clamped = 0
    for blk in prange(nblk):
        s0 = blk * BLOCK
        s1 = min(s0 + BLOCK, x.shape[0])
        predict_block(x, v, x_old, rest, inv_mass, s0, s1, rot, pos, rot_rel, pos_prev,
                      gravity, damp, dt, shock)
        lam_stretch[s0:s1] = 0.0
        lam_bend[s0:s1] = 0.0
        for _ in range(iterations):
            xpbd_sweep_block(x, inv_mass, rest_length, stretch_gain, lam_stretch, 1,
                             alpha_stretch, s0, s1)
            if alpha_bend >= 0.0:
                xpbd_sweep_block(x, inv_mass, bend_rest, bend_gain, lam_bend, 2,
                                 alpha_bend, s0, s1)
        if do_finalize:
            clamped += finalize_block(x, v, x_old, inv_mass, x_old, s0, s1, dt, max_disp, 0.0)
    return clamped


pbd_step_serial = serial_twin(pbd_step)
xpbd_step_serial = serial_twin(xpbd_step)
