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
bending constraints.  The PBD and XPBD kernels work on blocks of :data:`LANES` strands held side
by side ([node][axis][strand], :func:`lane_major`): every projection of a sweep is one loop over
the block's strands, which LLVM turns into SIMD instructions (four strands per instruction with
AVX2).  Every strand is still projected in the same order with the same arithmetic, so the
result of a strand does not depend on its block or on the thread count, and equals the one of
:func:`pbd_sweep_block` (the plain strand-by-strand sweep) bit for bit.  FTL bends with a Jacobi
sweep (:func:`jacobi_bend_block`).

Zero-length segments are safe: ``1/|d|`` is computed as ``1/sqrt(max(|d|², 1e-30))``, so a
degenerate pair moves by at most about its rest distance and never produces NaN.
"""
from collections import namedtuple
import math

import numpy as np
from numba import njit, prange, uint64

from hair_tracking.core.kernels import FASTMATH, parallel_and_serial
from hair_tracking.guides.integrate import finalize_block, predict_block

#: Static data of :func:`pbd_step` (the last four in :func:`lane_major` layout): ``rest``
#: (S, N, 3) head frame [m], ``inv_mass`` (S, N), ``rest_length``, ``bend_rest`` (rest
#: distances of neighbours and second neighbours [m]), ``stretch_w``, ``bend_w``
#: (:func:`pair_weights` with gap 1 and 2).
PbdModel = namedtuple('PbdModel', ['rest', 'inv_mass', 'rest_length', 'bend_rest', 'stretch_w',
                                   'bend_w'])
#: Parameters of :func:`pbd_step`: sweeps per substep, stretch and bending stiffness (0..1; a
#: bending stiffness of 0 skips bending), displacement clamp [m] (0: off), whether to finalize.
PbdParams = namedtuple('PbdParams', ['iterations', 'stiffness', 'bend_stiffness', 'max_disp',
                                     'do_finalize'])
#: Static data of :func:`xpbd_step` (all but ``rest`` and ``inv_mass`` in :func:`lane_major`
#: layout): ``inv_mass_l`` the inverse masses, ``stretch_gain``/``bend_gain`` from
#: :func:`xpbd_gain`.
XpbdModel = namedtuple('XpbdModel', ['rest', 'inv_mass', 'inv_mass_l', 'rest_length',
                                     'bend_rest', 'stretch_gain', 'bend_gain'])
#: Parameters of :func:`xpbd_step`: ``alpha_*`` the time-step scaled compliances
#: ``α̃ = α / dt²`` (a negative ``alpha_bend`` disables bending).
XpbdParams = namedtuple('XpbdParams', ['iterations', 'alpha_stretch', 'alpha_bend', 'max_disp',
                                       'do_finalize'])
#: Work space of :func:`xpbd_step`: the positions (:func:`lane_work`) and the multipliers
#: ``lam_stretch``, ``lam_bend`` (:func:`lane_major` layout, reset by the kernel).
XpbdWork = namedtuple('XpbdWork', ['p', 'lam_stretch', 'lam_bend'])

#: Floor of ``|p_j - p_i|²`` [m²] when inverting a distance (zero-length segments).
TINY_SQ = 1e-30

#: Strands a block of the PBD and XPBD kernels projects side by side.  A compile-time constant
#: on purpose: every row of a block (one node's x, y or z of all its strands) then sits at a
#: constant distance from the others, so LLVM proves that a projection's loads and stores do not
#: overlap and vectorises the loop over the strands.  It did not with the row length a run-time
#: value, with 3-d indexing (numba reads the strides at run time) or with signed indices (see
#: :func:`pbd_sweep_lanes`): the loop ran scalar.  16 strands are four AVX2 vectors, enough
#: to overlap the square-root and division chains of consecutive nodes.
LANES = 16


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


def lane_major(a: np.ndarray) -> np.ndarray:
    """Per-strand data (S, M) or (S, M, K) -> (B, M * K * LANES) for the lane kernels: block
    ``b`` holds strands ``b LANES .. (b+1) LANES - 1``, laid out [m][k][lane]; the lanes past
    the last strand are zero (a zero weight or gain makes a padding lane a no-op)."""
    a = np.asarray(a, dtype=np.float64)
    s = a.shape[0]
    blocks = lane_blocks(s)
    out = np.zeros((blocks * LANES,) + a.shape[1:])
    out[:s] = a
    out = out.reshape((blocks, LANES) + a.shape[1:])
    return np.ascontiguousarray(np.moveaxis(out, 1, -1)).reshape(blocks, -1)


def from_lane_major(a: np.ndarray, shape) -> np.ndarray:
    """Inverse of :func:`lane_major`: (B, M * K * LANES) -> ``shape`` (S, M[, K])."""
    s = shape[0]
    blocks = a.shape[0]
    out = np.moveaxis(np.asarray(a).reshape((blocks,) + tuple(shape[1:]) + (LANES,)), -1, 1)
    return np.ascontiguousarray(out.reshape((blocks * LANES,) + tuple(shape[1:]))[:s])


def lane_blocks(strands: int) -> int:
    """Blocks of :data:`LANES` strands covering ``strands`` strands."""
    return (strands + LANES - 1) // LANES


def lane_work(strands: int, nodes: int) -> np.ndarray:
    """Zeroed work space of :func:`pbd_step` / :func:`xpbd_step`: (B, nodes * 3 * LANES)."""
    return np.zeros((lane_blocks(strands), nodes * 3 * LANES))


@njit(cache=True, inline='always', fastmath=FASTMATH, error_model='numpy')
def pair_correction(x, rest_dist, s, i, j, a, c):
    """The projection of the distance constraint ``C = |d| - rest_dist[s, i]`` of the nodes
    ``i`` and ``j`` of strand ``s`` (``d = x_j - x_i``): ``(a C / |d|, c C / |d|, d)``, the
    factors of ``d`` that move node ``i`` (added) and node ``j`` (subtracted), given their
    weights ``a`` and ``c``."""
    dx = x[s, j, 0] - x[s, i, 0]
    dy = x[s, j, 1] - x[s, i, 1]
    dz = x[s, j, 2] - x[s, i, 2]
    l2 = dx * dx + dy * dy + dz * dz
    f = 1.0 - rest_dist[s, i] / math.sqrt(max(l2, TINY_SQ))   # C / |d|
    return a * f, c * f, dx, dy, dz


@njit(cache=True, fastmath=FASTMATH, error_model='numpy')
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
            a, c, dx, dy, dz = pair_correction(x, rest_dist, s, i, j, a, c)
            x[s, i, 0] += a * dx
            x[s, i, 1] += a * dy
            x[s, i, 2] += a * dz
            x[s, j, 0] -= c * dx
            x[s, j, 1] -= c * dy
            x[s, j, 2] -= c * dz


@njit(cache=True, fastmath=FASTMATH, error_model='numpy')
def jacobi_bend_block(x, rest_dist, weights, k, s0, s1):
    """One Jacobi sweep of the bending constraints ``(i, i+2)`` of strands ``s0..s1-1`` (FTL's
    bending, :mod:`hair_tracking.guides.ftl`): every projection is computed from the positions
    before the sweep and applied with half the PBD correction of stiffness ``k`` (each free node
    lies in two bending constraints), so the sweep moves node ``i`` by ``-k/2 w_i`` times the
    gradient of ``E = sum C^2 / (2 (w_i + w_j))`` (Jacobi projection with averaging, Macklin,
    Müller, Chentanez & Kim 2014, "Unified Particle Physics for Real-Time Applications",
    section 4.2, with one uniform factor so that it stays a gradient).

    Unlike a Gauss–Seidel sweep (:func:`pbd_sweep_block`), whose projections see the ones
    before them, it is then the same for every order of the constraints, and the forces of
    bending, gravity and the FTL pass balance at rest as those of an energy do: bent strands
    come to rest instead of turning on for ever.  ``rest_dist`` (S, N-2) [m]; ``weights`` from
    :func:`pair_weights` with gap 2.  Strand by strand; two corrections per strand wait in
    registers until no later constraint reads their node.
    """
    n = x.shape[1]
    h = 0.5 * k
    for s in range(s0, s1):
        ax, ay, az = 0.0, 0.0, 0.0      # waiting for node i (from the constraint (i-2, i))
        bx, by, bz = 0.0, 0.0, 0.0      # waiting for node i+1
        for i in range(n - 2):
            j = i + 2
            a = h * weights[s, i, 0]
            c = h * weights[s, i, 1]
            cx, cy, cz = 0.0, 0.0, 0.0
            if a != 0.0 or c != 0.0:
                a, c, dx, dy, dz = pair_correction(x, rest_dist, s, i, j, a, c)
                ax += a * dx
                ay += a * dy
                az += a * dz
                cx, cy, cz = -c * dx, -c * dy, -c * dz
            x[s, i, 0] += ax
            x[s, i, 1] += ay
            x[s, i, 2] += az
            ax, ay, az = bx, by, bz
            bx, by, bz = cx, cy, cz
        x[s, n - 2, 0] += ax
        x[s, n - 2, 1] += ay
        x[s, n - 2, 2] += az
        x[s, n - 1, 0] += bx
        x[s, n - 1, 1] += by
        x[s, n - 1, 2] += bz


@njit(cache=True, inline='always')
def _pair_offsets(i, gap):
    """Offsets in a block's arrays of the constraint ``(i, i+gap)``: node ``i``'s x row and node
    ``i+gap``'s in the positions, the constraint's row in per-constraint data (unsigned)."""
    return uint64(i * 3 * LANES), uint64((i + gap) * 3 * LANES), uint64(i * LANES)


@njit(cache=True, fastmath=FASTMATH, error_model='numpy')
def pbd_sweep_lanes(p, rest_dist, weights, n, gap, k):
    """One PBD Gauss–Seidel sweep over the constraints ``(i, i+gap)`` of the :data:`LANES` strands
    of one block, side by side: the same projections as :func:`pbd_sweep_block`, in the same
    order per strand, with the same arithmetic (bit-identical results).

    ``p`` (n * 3 * LANES,) the block's positions [node][axis][lane]; ``rest_dist``
    ((n-gap) * LANES,) and ``weights`` ((n-gap) * 2 * LANES,) from :func:`lane_major`.  A pair
    with both weights 0 (both nodes pinned, or a padding lane) moves by ``0 * d``, so the loop has
    no branch.  Indices are unsigned (``uint64``): with signed ones numba wraps negative
    indices around, and LLVM, seeing that select in every address, gave up on vectorising
    ("unsafe indirect dependence").
    """
    u1 = uint64(LANES)
    u2 = uint64(2 * LANES)
    for i in range(n - gap):
        b, e, r = _pair_offsets(i, gap)
        w = uint64(2 * i * LANES)
        for m in range(u1):
            a = k * weights[w + m]
            c = k * weights[w + u1 + m]
            dx = p[e + m] - p[b + m]
            dy = p[e + u1 + m] - p[b + u1 + m]
            dz = p[e + u2 + m] - p[b + u2 + m]
            l2 = dx * dx + dy * dy + dz * dz
            f = 1.0 - rest_dist[r + m] / math.sqrt(max(l2, TINY_SQ))   # C / |d|
            a *= f
            c *= f
            p[b + m] += a * dx
            p[b + u1 + m] += a * dy
            p[b + u2 + m] += a * dz
            p[e + m] -= c * dx
            p[e + u1 + m] -= c * dy
            p[e + u2 + m] -= c * dz


@njit(cache=True, fastmath=FASTMATH, error_model='numpy')
def xpbd_sweep_lanes(p, inv_mass, rest_dist, gain, lam, n, gap, alpha_tilde):
    """One XPBD Gauss–Seidel sweep over the constraints ``(i, i+gap)`` of the :data:`LANES`
    strands of one block, side by side (layout as in :func:`pbd_sweep_lanes`).

    ``inv_mass`` (n * LANES,), ``rest_dist``, ``gain`` (from :func:`xpbd_gain` for the same
    ``alpha_tilde``) and the multipliers ``lam`` of this substep ((n-gap) * LANES,, updated in
    place) in :func:`lane_major` layout.  A pair with gain 0 (both nodes pinned, or a padding
    lane) gets ``dλ = 0`` and moves by ``0 * d``: no branch.
    """
    u1 = uint64(LANES)
    u2 = uint64(2 * LANES)
    for i in range(n - gap):
        b, e, r = _pair_offsets(i, gap)
        rj = uint64((i + gap) * LANES)
        for m in range(u1):
            g = gain[r + m]
            dx = p[e + m] - p[b + m]
            dy = p[e + u1 + m] - p[b + u1 + m]
            dz = p[e + u2 + m] - p[b + u2 + m]
            l2 = dx * dx + dy * dy + dz * dz
            inv_l = 1.0 / math.sqrt(max(l2, TINY_SQ))
            c = l2 * inv_l - rest_dist[r + m]
            dlam = (-c - alpha_tilde * lam[r + m]) * g
            lam[r + m] += dlam
            h = dlam * inv_l
            wa = inv_mass[r + m] * h
            wb = inv_mass[rj + m] * h
            p[b + m] -= wa * dx
            p[b + u1 + m] -= wa * dy
            p[b + u2 + m] -= wa * dz
            p[e + m] += wb * dx
            p[e + u1 + m] += wb * dy
            p[e + u2 + m] += wb * dz


@njit(cache=True, fastmath=FASTMATH, error_model='numpy')
def _strain_limit_strand(x, v, inv_mass, rest_length, limit, inv_dt, s):
    """Strand ``s`` of :func:`strain_limit`; returns the nodes moved."""
    moved = 0
    for i in range(x.shape[1] - 1):
        if inv_mass[s, i + 1] <= 0.0:
            continue
        dx = x[s, i + 1, 0] - x[s, i, 0]
        dy = x[s, i + 1, 1] - x[s, i, 1]
        dz = x[s, i + 1, 2] - x[s, i, 2]
        l2 = dx * dx + dy * dy + dz * dz
        hi = (1.0 + limit) * rest_length[s, i]
        lo = (1.0 - limit) * rest_length[s, i]
        if l2 > hi * hi:
            f = hi / math.sqrt(l2) - 1.0
        elif lo * lo > l2 > 0.0:
            f = lo / math.sqrt(l2) - 1.0
        else:
            continue
        x[s, i + 1, 0] += f * dx
        x[s, i + 1, 1] += f * dy
        x[s, i + 1, 2] += f * dz
        v[s, i + 1, 0] += f * dx * inv_dt
        v[s, i + 1, 1] += f * dy * inv_dt
        v[s, i + 1, 2] += f * dz * inv_dt
        moved += 1
    return moved


def strain_limit(x, v, inv_mass, rest_length, limit, dt):
    """Strain limiting (Provot 1995, "Deformation constraints in a mass-spring model to describe
    rigid cloth behavior"), root to tip: a free node (``inv_mass`` > 0) farther from the node
    before it than ``1 + limit`` times their rest distance, or nearer than ``1 - limit`` times,
    is moved along their segment to that distance, its velocity by the move over ``dt``.  After
    a substep of PBD or XPBD, whose Gauss-Seidel sweeps converge slowly on long stiff strands
    under strong gravity, it bounds their stretch whatever the iteration count.  Returns the
    nodes moved."""
    moved = 0
    inv_dt = 1.0 / dt
    for s in prange(x.shape[0]):
        moved += _strain_limit_strand(x, v, inv_mass, rest_length, limit, inv_dt, s)
    return moved


strain_limit, strain_limit_serial = parallel_and_serial(
    strain_limit, fastmath=FASTMATH, error_model='numpy')


@njit(cache=True, fastmath=FASTMATH, error_model='numpy')
def lanes_in(x, s0, s1, p):
    """Positions of strands ``s0..s1-1`` (at most :data:`LANES`) into the block layout ``p``
    (its padding lanes are left as they are: zero from :func:`lane_work`)."""
    n = x.shape[1]
    for j in range(s1 - s0):
        for i in range(n):
            for a in range(3):
                p[(i * 3 + a) * LANES + j] = x[s0 + j, i, a]


@njit(cache=True, fastmath=FASTMATH, error_model='numpy')
def lanes_out(p, x, s0, s1):
    """Inverse of :func:`lanes_in`."""
    n = x.shape[1]
    for j in range(s1 - s0):
        for i in range(n):
            for a in range(3):
                x[s0 + j, i, a] = p[(i * 3 + a) * LANES + j]


@njit(cache=True, inline='always', fastmath=FASTMATH, error_model='numpy')
def _lanes_predicted(blk, state, rest, inv_mass, motion, work):
    """Step 1 for the strands of block ``blk`` (:func:`integrate.predict_block`), their
    predicted positions into the block's row of ``work``; returns the strand range (s0, s1)."""
    x, _, _ = state                                                     # GuideState
    s0 = blk * LANES
    s1 = min(s0 + LANES, x.shape[0])
    predict_block(state, rest, inv_mass, motion, s0, s1)
    lanes_in(x, s0, s1, work[blk])
    return s0, s1


@njit(cache=True, inline='always', fastmath=FASTMATH, error_model='numpy')
def _lanes_finished(p, state, inv_mass, s0, s1, dt, max_disp, do_finalize):
    """The block's projected positions ``p`` back into ``x``, then (if ``do_finalize``) the
    clamp and velocity update of its strands; returns the clamped count."""
    x, v, x_old = state
    lanes_out(p, x, s0, s1)
    if do_finalize:
        return finalize_block(x, v, x_old, inv_mass, x_old, s0, s1, dt, max_disp, 0.0)
    return 0


@njit(cache=True, fastmath=FASTMATH, error_model='numpy')
def _pbd_block(blk, model, state, motion, params, work):
    """Block ``blk`` of :func:`pbd_step` (a compiled body of its own: the parallel and the
    serial kernel run the same code)."""
    rest, inv_mass, rest_length, bend_rest, stretch_w, bend_w = model   # PbdModel
    iterations, stiffness, bend_stiffness, max_disp, do_finalize = params   # PbdParams
    _, _, _, _, _, _, dt, _, _ = motion                                 # StepMotion
    s0, s1 = _lanes_predicted(blk, state, rest, inv_mass, motion, work)
    n = inv_mass.shape[1]
    p = work[blk]
    for _ in range(iterations):
        pbd_sweep_lanes(p, rest_length[blk], stretch_w[blk], n, 1, stiffness)
        if bend_stiffness > 0.0:
            pbd_sweep_lanes(p, bend_rest[blk], bend_w[blk], n, 2, bend_stiffness)
    return _lanes_finished(p, state, inv_mass, s0, s1, dt, max_disp, do_finalize)


@njit(cache=True, fastmath=FASTMATH, error_model='numpy')
def _xpbd_block(blk, model, state, motion, params, xwork):
    """Block ``blk`` of :func:`xpbd_step` (see :func:`_pbd_block`)."""
    (rest, inv_mass, inv_mass_l, rest_length, bend_rest, stretch_gain,
     bend_gain) = model                                                 # XpbdModel
    work, lam_stretch, lam_bend = xwork                                 # XpbdWork
    iterations, alpha_stretch, alpha_bend, max_disp, do_finalize = params   # XpbdParams
    _, _, _, _, _, _, dt, _, _ = motion                                 # StepMotion
    s0, s1 = _lanes_predicted(blk, state, rest, inv_mass, motion, work)
    n = inv_mass.shape[1]
    p = work[blk]
    lam_stretch[blk, :] = 0.0
    lam_bend[blk, :] = 0.0
    for _ in range(iterations):
        xpbd_sweep_lanes(p, inv_mass_l[blk], rest_length[blk], stretch_gain[blk],
                         lam_stretch[blk], n, 1, alpha_stretch)
        if alpha_bend >= 0.0:
            xpbd_sweep_lanes(p, inv_mass_l[blk], bend_rest[blk], bend_gain[blk], lam_bend[blk],
                             n, 2, alpha_bend)
    return _lanes_finished(p, state, inv_mass, s0, s1, dt, max_disp, do_finalize)


def pbd_step(model, state, motion, params, work):
    """Kernel: one PBD substep of all strands (predict, ``iterations`` sweeps, finalize).

    ``model``, ``state``, ``motion``, ``params``: the fields of :data:`PbdModel`,
    :data:`~hair_tracking.guides.integrate.GuideState`,
    :data:`~hair_tracking.guides.integrate.StepMotion`,
    :data:`PbdParams` as plain tuples (``tuple(PbdModel(...))``, see
    :data:`~hair_tracking.guides.integrate.GuideState`); ``work`` from :func:`lane_work`.

    Per block of :data:`LANES` strands: :func:`integrate.predict_block`, the positions into the
    block's row of ``work`` (:func:`lane_work`), ``iterations`` times a stretch sweep
    (stiffness ``stiffness``) and a bending sweep (``bend_stiffness``, skipped when 0) side by
    side over the block's strands (:func:`pbd_sweep_lanes`), the positions back, then — if
    ``do_finalize`` (no collider in between) — :func:`integrate.finalize_block`. Returns the
    number of clamped nodes (0 when not finalizing).  ``rest_length``, ``bend_rest``,
    ``stretch_w`` and ``bend_w`` (:func:`pair_weights` with gap 1 and 2) in :func:`lane_major`
    layout.  Units: see :mod:`hair_tracking.guides.integrate`.
    """
    clamped = 0
    for blk in prange(work.shape[0]):
        # (the index as in the serial variant: one compiled block body)
        clamped += _pbd_block(np.int64(blk), model, state, motion, params, work)
    return clamped


pbd_step, pbd_step_serial = parallel_and_serial(pbd_step, fastmath=FASTMATH, error_model='numpy')


def xpbd_step(model, state, motion, params, work):
    """Kernel: one XPBD substep of all strands (predict, reset λ, ``iterations`` sweeps, finalize).

    The fields of :data:`XpbdModel`, :data:`~hair_tracking.guides.integrate.GuideState`,
    :data:`~hair_tracking.guides.integrate.StepMotion`, :data:`XpbdParams`, :data:`XpbdWork` as
    plain
    tuples.

    As :func:`pbd_step`, with :func:`xpbd_sweep_lanes`.  ``alpha_stretch``/``alpha_bend`` are
    the time-step scaled compliances ``α̃ = α / dt²``; ``stretch_gain``/``bend_gain`` from
    :func:`xpbd_gain` with the same ``α̃``; ``inv_mass_l``, the gains, ``rest_length``,
    ``bend_rest`` and the multipliers ``lam_*`` (scratch, reset here) in :func:`lane_major`
    layout. A negative ``alpha_bend`` disables bending. Returns the clamped node count (0 when
    not finalizing).
    """
    lanes, _, _ = work                                                  # XpbdWork
    clamped = 0
    for blk in prange(lanes.shape[0]):
        clamped += _xpbd_block(np.int64(blk), model, state, motion, params, work)
    return clamped


xpbd_step, xpbd_step_serial = parallel_and_serial(
    xpbd_step, fastmath=FASTMATH, error_model='numpy')
