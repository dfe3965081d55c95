"""Plain-numpy reference steps: the readable statement of the algorithm the numba kernels run.

The kernels (:mod:`.integrate`, :mod:`.pbd_constraints`, :mod:`.ftl`, :mod:`.tracking_kernels`)
are organised for speed: blocks of strands, lane-major layouts, fused loops, inlined scalar
helpers.  The functions here compute the same substeps vectorised over strands with numpy, in the
order of the method (``docs/method.md``), and the tests check the kernels against them (to about
1e-12 m: the kernels use fused multiply-add).  They are slow and meant for reading and testing,
not for running a scene.

Guide solvers (Mueller et al. 2007 "Position Based Dynamics"; Macklin, Mueller & Chentanez 2016
"XPBD"; Mueller, Kim & Chentanez 2012 "Fast Simulation of Inextensible Hair and Fur", FTL):

* :func:`guide_predict` -- roots carried by the head, the rest carried by ``shock`` of the head's
  motion, velocity damped, gravity, explicit Euler prediction;
* :func:`pbd_sweep` / :func:`xpbd_sweep` -- one Gauss-Seidel sweep of distance constraints between
  nodes ``gap`` apart (gap 1: stretching, gap 2: bending as a second-neighbour distance);
* :func:`ftl_pass` -- Follow-The-Leader: every node put at its rest length from its parent;
* :func:`guide_finalize` -- displacement clamp, FTL velocity correction, ``v = (x - x_old) / dt``;
* :func:`pbd_step`, :func:`xpbd_step`, :func:`ftl_step` -- whole substeps composed of these.

Ghost tracking (Park & Kim): :func:`ghost_step`, stages (a)-(h) of
:mod:`.tracking_kernels`, calling the equation functions of :mod:`.weights`, :mod:`.spread`.

Units: positions [m], velocities [m/s], world frame; rest shapes in the head frame; head poses
``p_world = pos + rot p_head``.
"""
import numpy as np

from .collision import push_out
from .ftl import restore_node
from .spread import group_variance, spread_factor
from .transforms import rotation_between
from .weights import com_weight, elastic_code, elastic_weight, tip_weights, weighted_position


# ------------------------------------------------------------------------- guide solvers
def guide_predict(x, v, rest, inv_mass, rot, pos, rot_prev, pos_prev, gravity, damping, dt,
                  shock):
    """Predict stage of every guide solver.  Returns ``(p, x_carried, v_integrated)``: the
    predicted positions, the start positions after the rigid carry by ``shock`` of the head's
    motion (the ``x_old`` of the finalize stage) and the integrated velocities."""
    rot_rel = rot @ rot_prev.T
    moved = (x - pos_prev) @ rot_rel.T + pos
    xc = x + shock * (moved - x)
    vc = v + shock * (v @ rot_rel.T - v)
    free = (inv_mass > 0)[..., None]
    vn = np.where(free, vc * np.exp(-damping * dt) + np.asarray(gravity) * dt, 0.0)
    p = np.where(free, xc + vn * dt, xc)
    p[:, :2] = rest[:, :2] @ rot.T + pos          # roots: nodes 0 and 1 follow the head
    vn[:, :2] = v[:, :2]
    return p, xc, vn


def pbd_sweep(p, rest_dist, inv_mass, gap, k):
    """One PBD sweep, in place on ``p`` (S, N, 3): for ``i = 0 .. N-1-gap`` the constraint
    ``C = |p_j - p_i| - rest_dist[:, i]`` (``j = i + gap``) projected with stiffness ``k``,
    the correction shared by the inverse masses."""
    for i in range(p.shape[1] - gap):
        j = i + gap
        wi, wj = inv_mass[:, i], inv_mass[:, j]
        ws = wi + wj
        d = p[:, j] - p[:, i]
        length = np.linalg.norm(d, axis=1)
        c = length - rest_dist[:, i]
        nrm = d / np.maximum(length, 1e-15)[:, None]
        safe = np.where(ws > 0, ws, 1.0)
        p[:, i] += (k * wi / safe * c)[:, None] * nrm
        p[:, j] -= (k * wj / safe * c)[:, None] * nrm


def xpbd_sweep(p, rest_dist, inv_mass, lam, gap, alpha_tilde):
    """One XPBD sweep, in place on ``p`` and the multipliers ``lam`` (S, N-gap):
    ``dlam = (-C - alpha_tilde lam) / (w_i + w_j + alpha_tilde)``, ``alpha_tilde = alpha / dt^2``
    the time-step scaled compliance."""
    for i in range(p.shape[1] - gap):
        j = i + gap
        wi, wj = inv_mass[:, i], inv_mass[:, j]
        ws = wi + wj
        d = p[:, j] - p[:, i]
        length = np.linalg.norm(d, axis=1)
        c = length - rest_dist[:, i]
        nrm = d / np.maximum(length, 1e-15)[:, None]
        dlam = np.where(ws > 0, (-c - alpha_tilde * lam[:, i]) / (ws + alpha_tilde), 0.0)
        lam[:, i] += dlam
        p[:, i] -= (wi * dlam)[:, None] * nrm
        p[:, j] += (wj * dlam)[:, None] * nrm


def ftl_pass(p, rest, rest_length, rot):
    """Follow-The-Leader pass, in place on ``p``: node ``i >= 2`` put at ``rest_length[:, i-1]``
    from node ``i-1`` along their current direction (a collapsed segment continues along its
    head-carried rest direction, or straight down).  Returns the corrections (S, N, 3)
    ``new - old`` (for the velocity correction of :func:`guide_finalize`)."""
    corr = np.zeros_like(p)
    for i in range(2, p.shape[1]):
        d = p[:, i] - p[:, i - 1]
        length = np.linalg.norm(d, axis=1)
        fallback = (rest[:, i] - rest[:, i - 1]) @ rot.T
        fb_len = np.linalg.norm(fallback, axis=1)
        fallback = np.where((fb_len > 1e-12)[:, None],
                            fallback / np.maximum(fb_len, 1e-300)[:, None], [0.0, 0.0, -1.0])
        u = np.where((length > 1e-12)[:, None], d / np.maximum(length, 1e-300)[:, None], fallback)
        new = p[:, i - 1] + rest_length[:, i - 1][:, None] * u
        corr[:, i] = new - p[:, i]
        p[:, i] = new
    return corr


def guide_finalize(p, x_old, inv_mass, corr, dt, max_disp, s_damp):
    """Finalize stage: free nodes' displacements clamped to ``max_disp`` (0: off), the FTL
    velocity correction ``- s_damp corr[i+1]`` (Mueller, Kim & Chentanez 2012), and
    ``v = displacement / dt``.  Returns ``(x, v, clamped node count)``."""
    p = p.copy()
    free = inv_mass > 0
    disp = p - x_old
    clamped = np.zeros(inv_mass.shape, bool)
    if max_disp > 0:
        mag = np.linalg.norm(disp, axis=2)
        hit = free & (mag > max_disp)
        disp[hit] *= (max_disp / mag[hit])[:, None]
        p[hit] = x_old[hit] + disp[hit]
        clamped |= hit
    if s_damp > 0:
        shifted = np.zeros_like(corr)
        shifted[:, :-1] = corr[:, 1:]
        disp = np.where(free[..., None], disp - s_damp * shifted, disp)
        if max_disp > 0:
            mag = np.linalg.norm(disp, axis=2)
            hit = free & (mag > max_disp)
            disp[hit] *= (max_disp / mag[hit])[:, None]
            clamped |= hit
    return p, disp / dt, int(clamped.sum())


def pbd_step(x, v, rest, inv_mass, rest_length, bend_rest, motion, dt, iterations, stiffness,
             bend_stiffness, max_disp):
    """One PBD substep of all guides: predict, ``iterations`` times a stretch sweep and (if
    ``bend_stiffness > 0``) a bending sweep, finalize.  ``motion``: the keyword arguments of
    :func:`guide_predict` after ``inv_mass`` except ``dt`` (rot, pos, rot_prev, pos_prev,
    gravity, damping, shock).  Returns ``(x, v, clamped)``."""
    p, xc, _ = guide_predict(x, v, rest, inv_mass, dt=dt, **motion)
    for _ in range(iterations):
        pbd_sweep(p, rest_length, inv_mass, 1, stiffness)
        if bend_stiffness > 0.0:
            pbd_sweep(p, bend_rest, inv_mass, 2, bend_stiffness)
    return guide_finalize(p, xc, inv_mass, None, dt, max_disp, 0.0)


def xpbd_step(x, v, rest, inv_mass, rest_length, bend_rest, motion, dt, iterations,
              alpha_stretch, alpha_bend, max_disp):
    """One XPBD substep of all guides (multipliers from zero; a negative ``alpha_bend``: no
    bending).  As :func:`pbd_step`; returns ``(x, v, clamped, lam_stretch, lam_bend)``."""
    p, xc, _ = guide_predict(x, v, rest, inv_mass, dt=dt, **motion)
    lam_s = np.zeros(rest_length.shape)
    lam_b = np.zeros(bend_rest.shape)
    for _ in range(iterations):
        xpbd_sweep(p, rest_length, inv_mass, lam_s, 1, alpha_stretch)
        if alpha_bend >= 0.0:
            xpbd_sweep(p, bend_rest, inv_mass, lam_b, 2, alpha_bend)
    return guide_finalize(p, xc, inv_mass, None, dt, max_disp, 0.0) + (lam_s, lam_b)


def ftl_step(x, v, rest, inv_mass, rest_length, bend_rest, motion, dt, bend_passes,
             bend_stiffness, s_damp, max_disp):
    """One FTL substep of all guides: predict, ``bend_passes`` PBD bending sweeps (if
    ``bend_stiffness > 0``), the FTL pass, finalize with the velocity correction ``s_damp``.
    As :func:`pbd_step`; returns ``(x, v, clamped, corrections)``."""
    p, xc, _ = guide_predict(x, v, rest, inv_mass, dt=dt, **motion)
    if bend_stiffness > 0.0:
        for _ in range(bend_passes):
            pbd_sweep(p, bend_rest, inv_mass, 2, bend_stiffness)
    corr = ftl_pass(p, rest, rest_length, motion['rot'])
    return guide_finalize(p, xc, inv_mass, corr, dt, max_disp, s_damp) + (corr,)


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
    node with ``collider`` (a :class:`.collision.Collider`).

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
                    var = group_variance(np.ascontiguousarray(xp.T), 0, n, *mean)
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
    friction (:func:`.collision.push_out`), then with length restoration the collision-aware FTL
    step (:func:`.ftl.restore_node`)."""
    R = head.rotation
    c = head.position + R @ collider.center
    a = collider.radii + collider.margin
    out = p.copy()
    for k in range(p.shape[0]):
        moved, y0, y1, y2 = push_out(*p[k], *start[k], R, *c, *a, collider.friction,
                                     collider.refine)
        if moved and restore:
            y0, y1, y2 = restore_node(y0, y1, y2, *prev[k], seg_len[k], *rest_seg[k], R, *c,
                                      *a, collider.refine, 0)
        out[k] = (y0, y1, y2)
    return out
