"""Follow-The-Leader runs of several heads' guides in one compiled call.

Several people each wear the same groom on a head of their own: the guides of head ``h`` are
``x[slots[h]]`` of arrays shaped ``(C, G, N, 3)`` (``C`` places, ``G`` guides of ``N``
nodes), and each head has its own poses, so its own roots and its own collider placement.
:func:`ftl_advance_heads` runs ``K`` substeps of every head's guides: each head's strands go
through exactly the arithmetic of :func:`~hair_tracking.guides.ftl.ftl_advance` with that head's
poses (its per-block loop body, :func:`~hair_tracking.guides.ftl.ftl_advance_blocks`), and the
work items of the one parallel region are the (head, run of blocks) pairs, so two people's hair
costs one launch, not two.  The stop rule (the simulator's split estimate) applies to every
head: the run stops before the first substep after the first that any head's rule would split.

Strands do not interact, so a head's hair is that of ``ftl_advance`` run for it alone (to the
rounding in which the compiler fuses multiply-adds, as between a kernel and its serial
variant).
"""
import numpy as np
from numba import njit, prange

from hair_tracking.guides.ftl import CHUNKS, ftl_advance_blocks
from hair_tracking.guides.ftl import _measured, _split_after
from hair_tracking.core.kernels import BLOCK, parallel_and_serial


def ftl_advance_heads(model, state, drive, params, collide, collider, work, stop, slots):
    """Kernel: ``K`` FTL substeps of the guides of every head ``h``, at ``slots[h]`` of the
    state.

    ``model``: :data:`~hair_tracking.guides.ftl.FtlModel` (one groom, shared); ``state``:
    ``(x, v, x_old)`` each ``(C, G, N, 3)``; ``drive``:
    :data:`~hair_tracking.guides.ftl.RunDrive` with a leading head axis on ``rots`` (H, K + 1,
    3, 3), ``poss`` (H, K + 1, 3) and ``rels`` (H, K, 3, 3); ``params``, ``collide``,
    ``collider``: as :func:`~hair_tracking.guides.ftl.ftl_advance`; ``work``:
    :data:`~hair_tracking.guides.ftl.FtlWork` with ``corr``, ``x_ref``, ``before`` shaped like
    ``x`` and ``counts`` (H, B, K, 2), ``steps`` (H, B, K) or (H, B, 0) with a head axis;
    ``stop``: ``(rigid (H, K), limit, gdt2)``.  On return ``steps[h, 0]`` holds head ``h``'s
    largest squared node displacement of every substep taken (when measured).  Returns the
    substeps taken.
    """
    heads, n_sub, nblk, chunks, limited = _plan(state, drive, work, stop, slots)
    done = n_sub
    if limited:
        for k in range(n_sub):
            for j in prange(heads * chunks):
                _head_run(model, state, drive, params, collide, collider, work, slots,
                          (np.int64(j), chunks, nblk, k, k + 1))
            if _any_split(drive, work, stop, k, nblk, heads):
                done = k + 1
                break
    else:
        for j in prange(heads * chunks):
            _head_run(model, state, drive, params, collide, collider, work, slots,
                      (np.int64(j), chunks, nblk, np.int64(0), n_sub))
        _all_measured(drive, work, n_sub, nblk, heads)
    return done


ftl_advance_heads, ftl_advance_heads_serial = parallel_and_serial(ftl_advance_heads)


@njit(cache=True, inline='always')
def _plan(state, drive, work, stop, slots):
    """``(heads, substeps, blocks per head, chunks per head, limited)`` of a run."""
    x, _, _ = state                                                     # GuideState
    _, _, rels, _, _, _, _ = drive                                      # FtlDrive
    _, _, _, steps, _ = work                                            # FtlWork
    _, limit, _ = stop
    heads = slots.shape[0]
    n_sub = rels.shape[1]
    nblk = (x.shape[1] + BLOCK - 1) // BLOCK
    measure = steps.shape[2] == n_sub
    return heads, n_sub, nblk, min(nblk, CHUNKS), measure and limit > 0.0


@njit(cache=True, inline='always')
def _head_run(model, state, drive, params, collide, collider, work, slots, item):
    """Work item ``item = (j, chunks, blocks, k0, k1)``: chunk ``j % chunks`` of head
    ``j // chunks``'s ``blocks`` blocks through the substeps ``k0 <= k < k1``."""
    j, chunks, nblk, k0, k1 = item
    h = j // chunks
    c = j - h * chunks
    s = slots[h]
    x, v, x_old = state                                                 # GuideState
    ftl_advance_blocks(model, (x[s], v[s], x_old[s]), _drive_of(drive, h),
                       params, collide, collider, _work_of(work, h, s),
                       (c * nblk // chunks, (c + 1) * nblk // chunks), (k0, k1))


@njit(cache=True, inline='always')
def _drive_of(drive, h):
    """Head ``h``'s :data:`~hair_tracking.guides.ftl.RunDrive`."""
    rots, poss, rels, gravity, damp, dt, shock = drive
    return (rots[h], poss[h], rels[h], gravity, damp, dt, shock)


@njit(cache=True, inline='always')
def _work_of(work, h, s):
    """Head ``h``'s :data:`~hair_tracking.guides.ftl.FtlWork` (its place ``s``)."""
    corr, x_ref, counts, steps, before = work
    return (corr[s], x_ref[s], counts[h], steps[h], before[s])


@njit(cache=True)
def _any_split(drive, work, stop, k, nblk, heads):
    """Whether any head's stop rule ends the run after substep ``k`` (every head's largest
    displacement of the substep gathered first)."""
    rigid, limit, gdt2 = stop
    split = False
    for h in range(heads):
        rule = (rigid[h], limit, gdt2)
        if _split_after(_drive_of(drive, h), _work_of(work, h, 0), rule, k, nblk):
            split = True
    return split


@njit(cache=True)
def _all_measured(drive, work, n_sub, nblk, heads):
    """Every head's largest displacement of every substep into ``steps[h, 0]``."""
    for h in range(heads):
        _measured(_work_of(work, h, 0), n_sub, nblk)
