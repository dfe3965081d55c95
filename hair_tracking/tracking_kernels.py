"""numba kernels of ghost tracking: the guide frames and the fused per-group tracking step.

One call of :func:`track_groups` advances every ghost node one substep.  It runs in parallel
over *groups* (the ghosts of one guide; a group's nodes fit in the L1/L2 cache) and does, in
order (the letters of ``docs/ghosts.md``):

a. velocity transfer: the node moves by the displacement ``u dt`` of its target point on the
   guide (the guide point at the node's arc-length fraction, Park & Kim section 3);
b. weights, equations (4)-(5): ``pos* = pos + u dt (W* + w_tip + w_com)``, sum clamped;
c. offset feedback: pull toward ``guide point + Q rest_offset`` (``Q`` the guide segment frame);
d. centre-of-mass tracking (Park & Kim Fig. 1; Milliez et al. 2018): the group's centre of mass
   at each node index moves toward the centre of mass of its targets;
e. spread control (HairControl, Milliez et al. 2018, eqs. (2)-(3)): offsets from the centre of
   mass scaled toward the target variance;
f. length restoration: one Follow-The-Leader pass (Mueller, Kim & Chentanez 2012);
g. roots (nodes 0 and 1) pinned at the head-carried rest shape;
then ``v = (x_new - x_old) / dt``.  (h, collision with the head, is a separate call on the whole
arrays, see :class:`hair_tracking.ghosts.GhostTracker`.)

Conventions: world frame positions [m] and velocities [m/s]; rest data in the head frame;
``R`` (3, 3) and ``pos`` (3,) the head pose (``p_world = pos + R p_head``).  Ghost state arrays
``x``, ``v`` are in the user's ghost order and reached through ``order``; every per-ghost static
array (``node_row``, ``rest_off``, ``inv_len``) is stored in group order (row ``k`` belongs
to ghost ``order[k]``).  No cross-thread reductions: results are deterministic.
"""
import math

from numba import njit, prange
import numpy as np

from .weights import clamp_weight, com_weight, elastic_weight


@njit(cache=True, inline='always')
def _frame_into(guide_x, tan_rest, gi, s, R, Q):
    """Q (3, 3) = R_min(R t_rest -> t_now) @ R for segment ``s`` of guide ``gi``.

    ``R_min(a -> b) = c I + [a x b]_x + (a x b)(a x b)^T / (1 + c)``, ``c = a . b`` (the smallest
    rotation taking unit ``a`` onto unit ``b``, Rodrigues' formula).  Within 1e-6 of a half turn
    the rotation by pi about an axis perpendicular to ``a`` is used; a degenerate segment (zero
    length now or at rest) gives ``Q = R``.
    """
    ax = R[0, 0] * tan_rest[gi, s, 0] + R[0, 1] * tan_rest[gi, s, 1] + R[0, 2] * tan_rest[gi, s, 2]
    ay = R[1, 0] * tan_rest[gi, s, 0] + R[1, 1] * tan_rest[gi, s, 1] + R[1, 2] * tan_rest[gi, s, 2]
    az = R[2, 0] * tan_rest[gi, s, 0] + R[2, 1] * tan_rest[gi, s, 1] + R[2, 2] * tan_rest[gi, s, 2]
    bx = guide_x[gi, s + 1, 0] - guide_x[gi, s, 0]
    by = guide_x[gi, s + 1, 1] - guide_x[gi, s, 1]
    bz = guide_x[gi, s + 1, 2] - guide_x[gi, s, 2]
    na = ax * ax + ay * ay + az * az
    nb = math.sqrt(bx * bx + by * by + bz * bz)
    if na < 0.25 or not (nb > 1e-300) or not (nb < 1e300):
        for r in range(3):
            for c in range(3):
                Q[r, c] = R[r, c]
        return
    bx /= nb
    by /= nb
    bz /= nb
    c = ax * bx + ay * by + az * bz
    m00 = m01 = m02 = m10 = m11 = m12 = m20 = m21 = m22 = 0.0
    if 1.0 + c < 1e-6:
        # half turn about p perpendicular to a: M = 2 p p^T - I
        if abs(ax) <= abs(ay) and abs(ax) <= abs(az):
            px, py, pz = 0.0, az, -ay          # a x e_x
        elif abs(ay) <= abs(az):
            px, py, pz = -az, 0.0, ax          # a x e_y
        else:
            px, py, pz = ay, -ax, 0.0          # a x e_z
        npn = math.sqrt(px * px + py * py + pz * pz)
        px /= npn
        py /= npn
        pz /= npn
        m00 = 2.0 * px * px - 1.0
        m01 = 2.0 * px * py
        m02 = 2.0 * px * pz
        m10 = m01
        m11 = 2.0 * py * py - 1.0
        m12 = 2.0 * py * pz
        m20 = m02
        m21 = m12
        m22 = 2.0 * pz * pz - 1.0
    else:
        vx = ay * bz - az * by
        vy = az * bx - ax * bz
        vz = ax * by - ay * bx
        k = 1.0 / (1.0 + c)
        m00 = c + k * vx * vx
        m01 = -vz + k * vx * vy
        m02 = vy + k * vx * vz
        m10 = vz + k * vy * vx
        m11 = c + k * vy * vy
        m12 = -vx + k * vy * vz
        m20 = -vy + k * vz * vx
        m21 = vx + k * vz * vy
        m22 = c + k * vz * vz
    for col in range(3):
        r0 = R[0, col]
        r1 = R[1, col]
        r2 = R[2, col]
        Q[0, col] = m00 * r0 + m01 * r1 + m02 * r2
        Q[1, col] = m10 * r0 + m11 * r1 + m12 * r2
        Q[2, col] = m20 * r0 + m21 * r1 + m22 * r2


@njit(cache=True, parallel=True)
def guide_frames_kernel(guide_x, tan_rest, R, out):
    """Frames of every guide segment: ``out[g, s]`` (3, 3) = ``R_min(R t_rest[g, s] -> t_now) R``
    (see :func:`_frame_into`).  ``guide_x`` (G, M, 3) world [m], ``tan_rest`` (G, M-1, 3) unit rest
    tangents in the head frame (zero rows for degenerate segments)."""
    for g in prange(guide_x.shape[0]):
        for s in range(guide_x.shape[1] - 1):
            _frame_into(guide_x, tan_rest, g, s, R, out[g, s])


@njit(cache=True, parallel=True)
def track_groups(x, v, rest, rest_length, order, group_start, group_guide, node_table, node_row,
                 rest_off, inv_len, var_target, guide_x, guide_x_old, tan_rest, R, pos, dt,
                 elastic_mode, use_tip, com_w, max_weight, k_off, k_com, spread, ftl,
                 q_buf, scratch, clamped):
    """One tracking substep of all ghosts, in place on ``x`` and ``v`` (see the module doc).

    Parameters (S ghosts of N nodes, G guides of M nodes, K groups, U distinct node rows):
      x, v (S, N, 3)          ghost positions [m] / velocities [m/s], world, user order
      rest (S, N, 3)          ghost rest shapes, head frame [m] (roots and FTL fallback)
      rest_length (S, N-1)    ghost rest segment lengths [m]
      order (S,)              ghost index of group-order row k
      group_start (K+1,)      rows of group g: group_start[g] .. group_start[g+1]-1
      group_guide (K,)        guide of group g
      node_table (U, N, 2)    per node: guide parameter ``seg + t`` and ``w_tip``
      node_row (S,)           row of node_table of each ghost (group order); ghosts with the
                              same arc-length layout share a row (all of them, for a groom with
                              evenly spaced nodes), which keeps the per-node data in cache
      rest_off (S, N, 3)      target offset from the guide point, head frame [m] (group order)
      inv_len (S,)            1 / ghost length [1/m] (group order)
      var_target (K, N)       target group variance (sum of squares) [m^2] for spread control
      guide_x, guide_x_old    (G, M, 3) guides after / before this substep, world [m]
      tan_rest (G, M-1, 3)    unit rest tangents of the guides, head frame
      R (3, 3), pos (3,)      head pose;  dt [s]
      elastic_mode            weights.ELASTIC_OFF / KEPT / CHANGED
      use_tip, com_w, max_weight, k_off, k_com, spread, ftl   switches and strengths
      q_buf (K, M-1, 3, 3), scratch (S, 6)   work space;  clamped (K,) out: clamped weight sums

    Within a group the loop runs over node index ``j`` (root to tip) outside and over the group's
    ghosts inside: the ghosts at one node index are independent (instruction-level parallelism),
    the group sums of (d) and (e) are complete before they are applied, Follow-The-Leader finds
    node ``j - 1`` already final, and the target point on the guide is computed once for all
    ghosts of the group that share it.
    """
    n_nodes = x.shape[1]
    m_nodes = guide_x.shape[1]
    m_last = m_nodes - 2
    inv_dt = 1.0 / dt
    need_target = k_off > 0.0 or k_com > 0.0
    group_level = k_com > 0.0 or spread > 0.0
    xf = x.reshape(x.size)
    vf = v.reshape(v.size)
    of = rest_off.reshape(rest_off.size)
    tf = node_table.reshape(node_table.size)
    gxf = guide_x.reshape(guide_x.size)
    gof = guide_x_old.reshape(guide_x_old.size)
    qf = q_buf.reshape(q_buf.size)
    sf = scratch.reshape(scratch.size)
    lf = rest_length.reshape(rest_length.size)
    # flat views: one index per (ghost, node) instead of three keeps the inner loops short
    for g in prange(group_guide.shape[0]):
        gi = group_guide[g]
        k0 = group_start[g]
        k1 = group_start[g + 1]
        n = k1 - k0
        n_clamped = 0
        if need_target:     # frames Q of the guide's segments, once per group
            Q = q_buf[g]
            for sg in range(m_last + 1):
                _frame_into(guide_x, tan_rest, gi, sg, R, Q[sg])
        use_com_w = com_w > 0.0 and n > 1
        qb = g * (m_last + 1) * 9
        gb = gi * m_nodes * 3
        # (g) roots pinned to the head-carried rest shape
        for k in range(k0, k1):
            s = order[k]
            for j in range(min(2, n_nodes)):
                for a in range(3):
                    new = pos[a] + R[a, 0] * rest[s, j, 0] + R[a, 1] * rest[s, j, 1] + \
                        R[a, 2] * rest[s, j, 2]
                    v[s, j, a] = (new - x[s, j, a]) * inv_dt
                    x[s, j, a] = new
        for j in range(2, n_nodes):
            # centre of mass at the start of the substep (only w_com needs it)
            c0x = c0y = c0z = 0.0
            if use_com_w:
                for k in range(k0, k1):
                    xb = (order[k] * n_nodes + j) * 3
                    c0x += xf[xb]
                    c0y += xf[xb + 1]
                    c0z += xf[xb + 2]
                c0x /= n
                c0y /= n
                c0z /= n
            xs0 = xs1 = xs2 = qs0 = qs1 = qs2 = 0.0
            ys0 = ys1 = ys2 = y2 = 0.0
            r0 = r1 = r2 = 0.0
            last_gp = -1.0
            px = py = pz = dx = dy = dz = 0.0
            q00 = q01 = q02 = q10 = q11 = q12 = q20 = q21 = q22 = 0.0
            for k in range(k0, k1):
                xb = (order[k] * n_nodes + j) * 3
                tb = (node_row[k] * n_nodes + j) * 2
                # (a) velocity transfer: displacement u dt of the target point on the guide
                # (computed once for consecutive ghosts sharing the point)
                gp = tf[tb]
                if gp != last_gp:
                    last_gp = gp
                    sg = int(gp)
                    if sg > m_last:
                        sg = m_last
                    t = gp - sg
                    u = 1.0 - t
                    a0 = gb + sg * 3
                    px = u * gxf[a0] + t * gxf[a0 + 3]
                    py = u * gxf[a0 + 1] + t * gxf[a0 + 4]
                    pz = u * gxf[a0 + 2] + t * gxf[a0 + 5]
                    dx = px - (u * gof[a0] + t * gof[a0 + 3])
                    dy = py - (u * gof[a0 + 1] + t * gof[a0 + 4])
                    dz = pz - (u * gof[a0 + 2] + t * gof[a0 + 5])
                    if need_target:
                        b = qb + sg * 9
                        q00 = qf[b]
                        q01 = qf[b + 1]
                        q02 = qf[b + 2]
                        q10 = qf[b + 3]
                        q11 = qf[b + 4]
                        q12 = qf[b + 5]
                        q20 = qf[b + 6]
                        q21 = qf[b + 7]
                        q22 = qf[b + 8]
                xo0 = xf[xb]
                xo1 = xf[xb + 1]
                xo2 = xf[xb + 2]
                # (b) weights, equations (4)-(5): pos* = pos + u dt (W* + w_tip + w_com)
                w = elastic_weight(dx, dy, dz, vf[xb], vf[xb + 1], vf[xb + 2], elastic_mode)
                if use_tip:
                    w += tf[tb + 1]
                if use_com_w:
                    ex = xo0 - c0x
                    ey = xo1 - c0y
                    ez = xo2 - c0z
                    w += com_weight(math.sqrt(ex * ex + ey * ey + ez * ez), inv_len[k], com_w)
                if w > max_weight:
                    n_clamped += 1
                w = 1.0 + clamp_weight(w, max_weight)
                x0 = xo0 + dx * w
                x1 = xo1 + dy * w
                x2 = xo2 + dz * w
                # (c) offset feedback toward the target q = guide point + Q rest_offset
                if need_target:
                    ob = (k * n_nodes + j) * 3
                    o0 = of[ob]
                    o1 = of[ob + 1]
                    o2 = of[ob + 2]
                    q0 = px + q00 * o0 + q01 * o1 + q02 * o2
                    q1 = py + q10 * o0 + q11 * o1 + q12 * o2
                    q2 = pz + q20 * o0 + q21 * o1 + q22 * o2
                    if k_off > 0.0:
                        x0 += k_off * (q0 - x0)
                        x1 += k_off * (q1 - x1)
                        x2 += k_off * (q2 - x2)
                    qs0 += q0
                    qs1 += q1
                    qs2 += q2
                if not group_level:
                    _finish_node(xf, vf, lf, rest, R, order[k], n_nodes, j, xb,
                                 x0, x1, x2, xo0, xo1, xo2, ftl, inv_dt)
                    continue
                xs0 += x0
                xs1 += x1
                xs2 += x2
                if spread > 0.0:
                    if k == k0:
                        r0 = x0
                        r1 = x1
                        r2 = x2
                    e0 = x0 - r0
                    e1 = x1 - r1
                    e2 = x2 - r2
                    ys0 += e0
                    ys1 += e1
                    ys2 += e2
                    y2 += e0 * e0 + e1 * e1 + e2 * e2
                sb = k * 6          # old and predicted position, until the group sums are done
                sf[sb] = xo0
                sf[sb + 1] = xo1
                sf[sb + 2] = xo2
                sf[sb + 3] = x0
                sf[sb + 4] = x1
                sf[sb + 5] = x2
            if not group_level:
                continue
            # (d) centre-of-mass tracking: shift toward the centre of mass of the targets
            d0 = d1 = d2 = 0.0
            if k_com > 0.0:
                d0 = k_com * (qs0 - xs0) / n
                d1 = k_com * (qs1 - xs1) / n
                d2 = k_com * (qs2 - xs2) / n
            # (e) spread control: scale about the shifted centre toward the target variance
            f = 1.0
            if spread > 0.0 and n > 1:
                var = y2 - (ys0 * ys0 + ys1 * ys1 + ys2 * ys2) / n
                if var > 1e-30:
                    ratio = math.sqrt(var_target[g, j] / var)
                    if ratio > 2.0:
                        ratio = 2.0
                    elif ratio < 0.5:
                        ratio = 0.5
                    f = 1.0 + spread * (ratio - 1.0)
            c0 = xs0 / n + d0
            c1 = xs1 / n + d1
            c2 = xs2 / n + d2
            # apply (d), (e); (f) Follow-The-Leader; velocities
            for k in range(k0, k1):
                sb = k * 6
                x0 = sf[sb + 3] + d0
                x1 = sf[sb + 4] + d1
                x2 = sf[sb + 5] + d2
                if f != 1.0:
                    x0 = c0 + f * (x0 - c0)
                    x1 = c1 + f * (x1 - c1)
                    x2 = c2 + f * (x2 - c2)
                xb = (order[k] * n_nodes + j) * 3
                _finish_node(xf, vf, lf, rest, R, order[k], n_nodes, j, xb, x0, x1, x2,
                             sf[sb], sf[sb + 1], sf[sb + 2], ftl, inv_dt)
        clamped[g] = n_clamped


@njit(cache=True, inline='always')
def _finish_node(xf, vf, lf, rest, R, s, n_nodes, j, xb, x0, x1, x2, xo0, xo1, xo2, ftl, inv_dt):
    """(f) Follow-The-Leader placement of node j of ghost s after node j-1 (if ``ftl``), then
    store x and v = (x - x_old) / dt.  ``xf``, ``vf``, ``lf``: flat views of x, v, rest_length;
    ``xb`` the flat index of (s, j, 0)."""
    if ftl:
        d0 = x0 - xf[xb - 3]
        d1 = x1 - xf[xb - 2]
        d2 = x2 - xf[xb - 1]
        nd = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        length = lf[s * (n_nodes - 1) + j - 1]
        if nd > 1e-300 and nd < 1e300:
            sc = length / nd
        else:
            # no direction: continue along the head-carried rest segment (already |.| = length)
            r0 = rest[s, j, 0] - rest[s, j - 1, 0]
            r1 = rest[s, j, 1] - rest[s, j - 1, 1]
            r2 = rest[s, j, 2] - rest[s, j - 1, 2]
            d0 = R[0, 0] * r0 + R[0, 1] * r1 + R[0, 2] * r2
            d1 = R[1, 0] * r0 + R[1, 1] * r1 + R[1, 2] * r2
            d2 = R[2, 0] * r0 + R[2, 1] * r1 + R[2, 2] * r2
            sc = 1.0
        x0 = xf[xb - 3] + d0 * sc
        x1 = xf[xb - 2] + d1 * sc
        x2 = xf[xb - 1] + d2 * sc
    vf[xb] = (x0 - xo0) * inv_dt
    vf[xb + 1] = (x1 - xo1) * inv_dt
    vf[xb + 2] = (x2 - xo2) * inv_dt
    xf[xb] = x0
    xf[xb + 1] = x1
    xf[xb + 2] = x2


def guide_frames(guide_x: np.ndarray, tan_rest: np.ndarray, rotation: np.ndarray) -> np.ndarray:
    """(G, M-1, 3, 3) frame of every guide segment (see :func:`_frame_into`)."""
    out = np.empty((guide_x.shape[0], guide_x.shape[1] - 1, 3, 3))
    guide_frames_kernel(np.ascontiguousarray(guide_x, dtype=np.float64),
                        np.ascontiguousarray(tan_rest, dtype=np.float64),
                        np.ascontiguousarray(rotation, dtype=np.float64), out)
    return out
