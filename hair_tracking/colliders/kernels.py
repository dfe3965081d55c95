"""Array kernels of the contact model: strands ``(S, N, 3)`` against a posed table (every shape
of a scene), built from the one-node functions of :mod:`hair_tracking.colliders.contact`.

:func:`collide_block` is the collision stage of a position-based substep for a block of
strands (a guide solver runs it block by block inside its own parallel loop); :func:`collide`
runs it over all strands; :func:`deepest` measures how deep the hair lies inside the shapes.
Shapes are taken in table order: a node pushed out of one shape into another is pushed out of
that one next (one Gauss-Seidel pass, as a solver takes its constraints).
"""
from numba import njit

from hair_tracking.colliders.bounds import near
from hair_tracking.colliders.contact import (bounded_start, carried, depth, FASTMATH, push_out,
                                             surface_normal)
from hair_tracking.colliders.shapes import FRICTION


@njit(cache=True, fastmath=FASTMATH, error_model='numpy')
def collide_block(x, start, inv_mass, sh, cap, x_old, s0, s1):
    """The strands ``s0 <= s < s1`` of ``x`` (S, N, 3) world [m], in place: every node with
    ``inv_mass > 0`` near a shape of ``sh`` (:func:`~hair_tracking.colliders.bounds.near`) is
    pushed out of it with its friction relative to ``carried(start)`` (``start`` (S, N, 3) the
    nodes' positions at the start of the substep); with ``cap >= 0`` [m] the push-out velocity
    bound moves the node's entry of ``x_old`` (S, N, 3), the positions its velocity is measured
    from (:func:`~hair_tracking.colliders.contact.bounded_start`; ``x_old`` may be ``start``).
    Returns the number of nodes moved."""
    n = x.shape[1]
    moved_nodes = 0
    for s in range(s0, s1):
        for i in range(n):
            if inv_mass[s, i] <= 0.0:
                continue
            x0, x1, x2 = x[s, i, 0], x[s, i, 1], x[s, i, 2]
            t0, t1, t2 = start[s, i, 0], start[s, i, 1], start[s, i, 2]
            o0, o1, o2 = x_old[s, i, 0], x_old[s, i, 1], x_old[s, i, 2]
            hit = False
            for k in range(sh.shape[0]):
                if not near(x0, x1, x2, sh, k):
                    continue
                r0, r1, r2 = t0, t1, t2
                if sh[k, FRICTION] > 0.0 or cap >= 0.0:
                    r0, r1, r2 = carried(t0, t1, t2, sh, k)
                moved, y0, y1, y2 = push_out(x0, x1, x2, r0, r1, r2, sh, k)
                if not moved:
                    continue
                if cap >= 0.0:
                    n0, n1, n2 = surface_normal(y0, y1, y2, sh, k)
                    o0, o1, o2 = bounded_start(o0, o1, o2, y0, y1, y2, r0, r1, r2, n0, n1, n2,
                                               cap)
                x0, x1, x2 = y0, y1, y2
                hit = True
            if hit:
                x[s, i, 0], x[s, i, 1], x[s, i, 2] = x0, x1, x2
                if cap >= 0.0:
                    x_old[s, i, 0], x_old[s, i, 1], x_old[s, i, 2] = o0, o1, o2
                moved_nodes += 1
    return moved_nodes


@njit(cache=True, fastmath=FASTMATH, error_model='numpy')
def collide(x, start, inv_mass, sh, cap, x_old):
    """:func:`collide_block` over all strands; returns the number of nodes moved."""
    return collide_block(x, start, inv_mass, sh, cap, x_old, 0, x.shape[0])


@njit(cache=True, fastmath=FASTMATH, error_model='numpy')
def deepest(x, inv_mass, use_mass, sh, out):
    """``out[s]`` = the deepest [m] a node of strand ``s`` of ``x`` (S, N, 3) lies inside a
    shape of ``sh`` (pose it without margins to measure the bare shapes); only nodes with
    ``inv_mass > 0`` when ``use_mass``; 0 where none is inside."""
    for s in range(x.shape[0]):
        worst = 0.0
        for i in range(x.shape[1]):
            if use_mass and inv_mass[s, i] <= 0.0:
                continue
            for k in range(sh.shape[0]):
                if near(x[s, i, 0], x[s, i, 1], x[s, i, 2], sh, k):
                    d = depth(x[s, i, 0], x[s, i, 1], x[s, i, 2], sh, k)
                    if d > worst:
                        worst = d
        out[s] = worst
