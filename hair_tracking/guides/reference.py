"""Plain-numpy reference steps of the guide solvers: the readable statement of the algorithm the
numba kernels run.

The kernels (:mod:`hair_tracking.guides.integrate`, :mod:`hair_tracking.guides.pbd_constraints`,
:mod:`hair_tracking.guides.ftl`) are organised for speed: blocks of strands, lane-major layouts,
fused loops, inlined scalar helpers.  The functions here compute the same substeps vectorised
over strands with numpy, in the order of the method (``docs/method.md``), and the tests check
the kernels against them (to about 1e-12 m: the kernels use fused multiply-add).  They are slow
and meant for reading and testing, not for running a scene.

Guide solvers (Mueller et al. 2007 "Position Based Dynamics"; Macklin, Mueller & Chentanez 2016
"XPBD"; Mueller, Kim & Chentanez 2012 "Fast Simulation of Inextensible Hair and Fur", FTL):

* :func:`guide_predict` -- roots carried by the head, the rest carried by ``shock`` of the head's
  motion, velocity damped, gravity, explicit Euler prediction;
* :func:`pbd_sweep` / :func:`xpbd_sweep` -- one Gauss-Seidel sweep of distance constraints between
  nodes ``gap`` apart (gap 1: stretching, gap 2: bending as a second-neighbour distance);
* :func:`jacobi_bend` -- FTL's bending: a Jacobi sweep of the second-neighbour constraints;
* :func:`ftl_pass` -- Follow-The-Leader: every node put at its rest length from its parent;
* :func:`guide_finalize` -- displacement clamp, FTL velocity correction, ``v = (x - x_old) / dt``;
* :func:`pbd_step`, :func:`xpbd_step`, :func:`ftl_step` -- whole substeps composed of these.

Units: positions [m], velocities [m/s], world frame; rest shapes in the head frame; head poses
``p_world = pos + rot p_head``.
"""
import numpy as np


# ------------------------------------------------------------------------- guide solvers
def guide_predict(x, v, rest, inv_mass, rot, pos, rot_prev, pos_prev, gravity, damping, dt,
                  shock, shape=0.0):
    """Predict stage of every guide solver.  Returns ``(p, x_carried, v_integrated)``: the
    predicted positions, the start positions after the rigid carry by ``shock`` of the head's
    motion (the ``x_old`` of the finalize stage) and the integrated velocities; ``shape``
    [1/s^2] a spring toward the rest shape carried by the head, integrated implicitly."""
    rot_rel = rot @ rot_prev.T
    moved = (x - pos_prev) @ rot_rel.T + pos
    xc = x + shock * (moved - x)
    vc = v + shock * (v @ rot_rel.T - v)
    free = (inv_mass > 0)[..., None]
    vn = vc * np.exp(-damping * dt) + np.asarray(gravity) * dt
    vn = (vn + shape * dt * (_carried_rest(rest, rot, pos) - xc)) / (1.0 + shape * dt * dt)
    vn = np.where(free, vn, 0.0)
    p = np.where(free, xc + vn * dt, xc)
    p[:, :2] = rest[:, :2] @ rot.T + pos          # roots: nodes 0 and 1 follow the head
    vn[:, :2] = v[:, :2]
    return p, xc, vn


def _pair(p, rest_dist, inv_mass, i, j):
    """The distance constraint of nodes ``i`` and ``j`` of every strand: their inverse masses
    and sum, ``C = |p_j - p_i| - rest_dist[:, i]`` and the unit direction from ``i`` to ``j``."""
    wi, wj = inv_mass[:, i], inv_mass[:, j]
    d = p[:, j] - p[:, i]
    length = np.linalg.norm(d, axis=1)
    return wi, wj, wi + wj, length - rest_dist[:, i], d / np.maximum(length, 1e-15)[:, None]


def pbd_sweep(p, rest_dist, inv_mass, gap, k):
    """One PBD sweep, in place on ``p`` (S, N, 3): for ``i = 0 .. N-1-gap`` the constraint
    ``C = |p_j - p_i| - rest_dist[:, i]`` (``j = i + gap``) projected with stiffness ``k``,
    the correction shared by the inverse masses."""
    for i in range(p.shape[1] - gap):
        j = i + gap
        wi, wj, ws, c, nrm = _pair(p, rest_dist, inv_mass, i, j)
        safe = np.where(ws > 0, ws, 1.0)
        p[:, i] += (k * wi / safe * c)[:, None] * nrm
        p[:, j] -= (k * wj / safe * c)[:, None] * nrm


def jacobi_bend(p, rest_dist, inv_mass, k):
    """FTL's bending sweep, in place on ``p``: every constraint ``C = |p_{i+2} - p_i| -
    rest_dist[:, i]`` projected from the positions before the sweep with stiffness ``k / 2``
    (Jacobi), the correction shared by the inverse masses."""
    d = p[:, 2:] - p[:, :-2]
    length = np.linalg.norm(d, axis=2)
    c = length - rest_dist
    nrm = d / np.maximum(length, 1e-15)[..., None]
    wi, wj = inv_mass[:, :-2], inv_mass[:, 2:]
    ws = wi + wj
    safe = np.where(ws > 0, ws, 1.0)
    dp = np.zeros_like(p)
    dp[:, :-2] += (0.5 * k * wi / safe * c)[..., None] * nrm
    dp[:, 2:] -= (0.5 * k * wj / safe * c)[..., None] * nrm
    p += dp


def xpbd_sweep(p, rest_dist, inv_mass, lam, gap, alpha_tilde):
    """One XPBD sweep, in place on ``p`` and the multipliers ``lam`` (S, N-gap):
    ``dlam = (-C - alpha_tilde lam) / (w_i + w_j + alpha_tilde)``, ``alpha_tilde = alpha / dt^2``
    the time-step scaled compliance."""
    for i in range(p.shape[1] - gap):
        j = i + gap
        wi, wj, ws, c, nrm = _pair(p, rest_dist, inv_mass, i, j)
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


def _carried_rest(rest, rot, pos):
    """The rest shape carried by the head pose ``rot``, ``pos``."""
    return rest @ rot.T + pos


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


def ftl_step(x, v, rest, inv_mass, rest_length, bend_rest, motion, dt, inner_steps,
             bend_stiffness, s_damp, max_disp):
    """One FTL substep of all guides in ``inner_steps`` inner steps ``h = dt / inner_steps``:
    predict over ``h`` (the roots a share ``(r + 1) / inner_steps`` of the way from their
    start to where the head puts them, along the straight line), a Jacobi bending sweep (if
    ``bend_stiffness > 0``, :func:`jacobi_bend`) and the FTL pass; every later inner step first
    moves the free nodes on with their velocity over the one before (its FTL correction damped
    as finalize damps it) and gravity.  Finalize over the whole substep with the corrections
    summed, the velocity correction ``s_damp``.  As :func:`pbd_step`; returns ``(x, v, clamped,
    corrections)``."""
    h = dt / inner_steps
    p, xc, _ = guide_predict(x, v, rest, inv_mass, dt=h, **motion)
    corr = np.zeros_like(p)
    step = np.zeros_like(p)
    moving = (inv_mass > 0)[..., None]
    moving[:, :2] = False
    start = xc
    roots = p[:, :2].copy()                       # where the head puts them at the end
    for r in range(inner_steps):
        t = (r + 1) / inner_steps
        p[:, :2] = roots if t >= 1.0 else xc[:, :2] + t * (roots - xc[:, :2])
        if r > 0:
            vel = (p - start) / h
            vel[:, :-1] -= s_damp * step[:, 1:] / h
            start = p.copy()
            vel = vel * np.exp(-motion['damping'] * h) + np.asarray(motion['gravity']) * h
            k = motion.get('shape', 0.0)
            vel = (vel + k * h * (_carried_rest(rest, motion['rot'], motion['pos']) - p)) / \
                (1.0 + k * h * h)
            p = np.where(moving, p + vel * h, p)
        if bend_stiffness > 0.0:
            jacobi_bend(p, bend_rest, inv_mass, bend_stiffness)
        step = ftl_pass(p, rest, rest_length, motion['rot'])
        corr += step
    return guide_finalize(p, xc, inv_mass, corr, dt, max_disp, s_damp) + (corr,)
