"""Plain-numpy reference step of the paper's ghost tracker (Park & Kim): the readable statement
of what :mod:`hair_tracking.ghosts.kernels` computes, stages (a)-(h), calling the equation
functions of :mod:`hair_tracking.ghosts.weights` and :mod:`hair_tracking.ghosts.spread`.  The
tests hold the kernel to it (to about 1e-12 m: the kernel uses fused multiply-add).  Slow; for
reading and testing.  (The blend tracker's reference is
:func:`hair_tracking.ghosts.blend.reference_blend`; the guide solvers' are in
:mod:`hair_tracking.guides.reference`.)

Units: positions [m], velocities [m/s], world frame; rest shapes in the head frame; head poses
``p_world = pos + rot p_head``.
"""
import numpy as np

from hair_tracking.core.transforms import rotation_between
from hair_tracking.ghosts.spread import group_variance, spread_factor
from hair_tracking.ghosts.weights import (com_weight, elastic_code, elastic_weight, tip_weights,
                                          weighted_position)
from hair_tracking.colliders.contact import ellipsoid_contact
from hair_tracking.guides.ftl import restore_node


# ------------------------------------------------------------------------- ghost tracking
def guide_segment_frames(guide_rest, gx, rot):
    """(G, M-1, 3, 3) frame ``Q`` of every guide segment: the smallest rotation of the
    head-carried rest tangent onto the current tangent, composed with the head rotation ``rot``
    (``rot`` itself for a degenerate segment)."""
    G, M = gx.shape[:2]
    frames = np.empty((G, M - 1, 3, 3))
    for g in range(G):
        for s in range(M - 1):
            a = guide_rest[g, s + 1] - guide_rest[g, s]
            b = gx[g, s + 1] - gx[g, s]
            if np.linalg.norm(a) < 1e-12 or np.linalg.norm(b) < 1e-300:
                frames[g, s] = rot
            else:
                frames[g, s] = rotation_between(rot @ (a / np.linalg.norm(a)),
                                                b / np.linalg.norm(b)) @ rot
    return frames


def ghost_step(x, v, ghost_rest, ghost_len, guide_of, seg, t, guide_rest, gx, gx_old, head,
               dt, tracking, collider=None):
    """One ghost-tracking substep, stages (a)-(g) of :mod:`.tracking_kernels`, and (h) node by
    node with ``collider`` (a :class:`~hair_tracking.colliders.head.HeadCollider`).

    ``x``, ``v`` (S, N, 3) the ghosts' state; ``ghost_rest`` (S, N, 3) and ``ghost_len``
    (S, N-1) their rest shapes and segment lengths; ``guide_of`` (S,) the guide of each ghost
    (equation (1)); ``seg``, ``t`` (S, N) the guide segment and fraction of each ghost node's
    target point (:func:`.correspondence.node_correspondence`); ``guide_rest`` (G, M, 3),
    ``gx`` / ``gx_old`` the guides now and at the previous ghost step; ``head`` the
    :class:`.model.HeadPose` now; ``tracking`` a :class:`.scene.TrackingSpec`.
    Returns the new ``(x, v)``."""
    tr = tracking
    x = x.copy()
    v = v.copy()
    R, pos = head.rotation, head.position
    n_nodes = x.shape[1]
    w_tip = tip_weights(ghost_len, tr.tip_weight)
    inv_len = 1.0 / ghost_len.sum(axis=1)
    rows = np.arange(x.shape[0])[:, None]
    point_rest = ((1 - t)[..., None] * guide_rest[guide_of][rows, seg] +
                  t[..., None] * guide_rest[guide_of][rows, seg + 1])
    # rest offsets of the targets (c), carrying the requested spread; target variances (e)
    target_rest = ghost_rest.copy()
    var_target = {}
    for g in np.unique(guide_of):
        m = np.flatnonzero(guide_of == g)
        com = ghost_rest[m].mean(axis=0)
        dev = ghost_rest[m] - com
        var_target[g] = tr.spread_target * np.einsum('snk,snk->n', dev, dev)
        if tr.spread > 0 and tr.spread_target != 1.0:
            target_rest[m, 2:] = com[2:] + np.sqrt(tr.spread_target) * dev[:, 2:]
    off = target_rest - point_rest
    frames = guide_segment_frames(guide_rest, gx, R)
    mode = elastic_code(tr)
    use_tip = 1.0 if tr.tip_weight > 0 else 0.0
    group_level = tr.com_strength > 0 or tr.spread > 0
    for g in np.unique(guide_of):
        m = np.flatnonzero(guide_of == g)
        n = m.size
        # (g) roots pinned at the head-carried rest shape
        new = pos + ghost_rest[m, :2] @ R.T
        v[m, :2] = (new - x[m, :2]) / dt
        x[m, :2] = new
        com_w = tr.com_weight if n > 1 else 0.0
        for j in range(2, n_nodes):
            # (a) the guide point of each node and its displacement d = u dt over the substep
            sg, tt = seg[m, j], t[m, j][:, None]
            p = (1 - tt) * gx[g, sg] + tt * gx[g, sg + 1]
            d = p - ((1 - tt) * gx_old[g, sg] + tt * gx_old[g, sg + 1])
            xo = x[m, j].copy()
            centre = xo.mean(axis=0)
            xp = np.empty_like(xo)
            for k in range(n):
                # (b) equations (4) and (5)
                w_el = elastic_weight(*d[k], *v[m[k], j], mode)
                w_com = com_weight(np.linalg.norm(xo[k] - centre), inv_len[m[k]], com_w)
                xp[k] = weighted_position(*xo[k], *d[k], w_el, use_tip * w_tip[m[k], j],
                                          w_com, tr.max_weight)[:3]
            # (c) pull toward the target: guide point + Q rest offset
            q = p + np.einsum('sab,sb->sa', frames[g, sg], off[m, j])
            xp = xp + tr.offset_strength * (q - xp)
            if group_level:
                # (d) centre of mass toward the targets' centre of mass, (e) spread, eqs. (2)-(3)
                mean = xp.mean(axis=0)
                delta = tr.com_strength * (q.mean(axis=0) - mean)
                f = 1.0
                if tr.spread > 0 and n > 1:
                    var = group_variance(np.ascontiguousarray(xp.T)[None], 0, 0, n, tuple(mean))
                    f = spread_factor(var, var_target[g][j], tr.spread)
                c = mean + delta
                xp = c + f * (xp + delta - c)
            if tr.length_restore:
                # (f) Follow-The-Leader: rest length from the (final) previous node
                prev = x[m, j - 1]
                dv = xp - prev
                nd = np.linalg.norm(dv, axis=1, keepdims=True)
                fallback = (ghost_rest[m, j] - ghost_rest[m, j - 1]) @ R.T
                xp = np.where(nd > 1e-300, prev + dv * ghost_len[m, j - 1][:, None] /
                              np.where(nd > 1e-300, nd, 1.0), prev + fallback)
            if collider is not None:
                xp = _collide_nodes(xp, xo, x[m, j - 1], ghost_len[m, j - 1],
                                    ghost_rest[m, j] - ghost_rest[m, j - 1], head, collider,
                                    tr.length_restore)
            v[m, j] = (xp - xo) / dt
            x[m, j] = xp
    return x, v


def _collide_nodes(p, start, prev, seg_len, rest_seg, head, collider, restore):
    """(h) for the nodes ``p`` (n, 3) of one node index: pushed out of the collider with
    friction (:func:`~hair_tracking.colliders.contact.ellipsoid_contact`), then with length
    restoration the collision-aware FTL step (:func:`.ftl.restore_node`)."""
    R = head.rotation
    c = head.position + R @ collider.center
    a = collider.radii + collider.margin
    out = p.copy()
    for k in range(p.shape[0]):
        contact = (tuple(R.reshape(-1)), *c, *a, collider.friction, collider.refine)
        moved, y0, y1, y2 = ellipsoid_contact(*p[k], *start[k], contact)
        if moved and restore:
            y0, y1, y2 = restore_node((y0, y1, y2), tuple(prev[k]), seg_len[k],
                                      tuple(rest_seg[k]), R, (*c, *a, collider.refine), 0)
        out[k] = (y0, y1, y2)
    return out
