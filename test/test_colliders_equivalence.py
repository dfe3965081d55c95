"""The guide solver and the ghost trackers run the contact model (hair_tracking.colliders) on
the head collider placed by their own plumbing (the head pose's tuples, the world quadric of the
stateless trackers); these tests feed the same collider to the model's table-driven functions
(hair_tracking.colliders.kernels and the per-kind functions on a posed table) and compare.

numba inlines an ``inline='always'`` function into its caller, whose flags then apply, and LLVM
fuses multiply-adds per straight run of code: the wrappers below are compiled as the kernels
that run them are (``FASTMATH`` for the guide solver and the blend and turn trackers,
``TRACK_FASTMATH`` for the paper tracker), a switch on the shape's kind kept outside the loops.
Which multiply-adds LLVM fuses is the compiler's choice, not the source's, so the old and new
functions are held to agree to rounding (1e-15 m; the paper tracker's reassociating lanes and
the turn tracker to their own bounds), not to identical bits."""
import math

import numpy as np
from numba import njit
import pytest

from hair_tracking.colliders import contact, kernels, margin, pose, reference
from hair_tracking.colliders import slide as stateless_slide
from hair_tracking.colliders.shapes import (CAPSULE, CX, CZ, ELLIPSOID, FRICTION, KIND, M00,
                                            PLANE, Q00, Q01, Q02, Q11, Q12, Q22, REFINE, Shape,
                                            shape_table)
from hair_tracking.core.model import HeadPose, StrandSet
from hair_tracking.core.scene import Scene
from hair_tracking.core.transforms import quat_from_axis_angle, quat_normalize, quat_to_matrix
from hair_tracking.ghosts import stateless, turn
from hair_tracking.ghosts import contacts as ghost_contacts
from hair_tracking.ghosts.kernels import TRACK_FASTMATH
from hair_tracking.colliders import head as collision
from hair_tracking.guides import ftl, integrate
from hair_tracking.core.kernels import FASTMATH
from hair_tracking.guides.solver import make_solver

RADII = (0.095, 0.08, 0.105)


# ----------------------------------------------------------------------------- set-up
def head_shape(radii=RADII, center=(0.01, -0.02, 0.03), margin_=0.004, friction=0.3):
    """The scene's head collider as a shape (a sphere is an ellipsoid of equal radii)."""
    return Shape('ellipsoid', center=center, radii=radii, margin=margin_, friction=friction)


def head_poses(rng):
    """Head poses at the start and at the end of a substep (a few mm and a degree apart)."""
    rot_prev = quat_to_matrix(quat_normalize(rng.normal(size=4)))
    pos_prev = rng.normal(scale=0.2, size=3)
    turn_ = quat_to_matrix(quat_from_axis_angle(rng.normal(size=3), 0.02))
    return rot_prev, pos_prev, turn_ @ rot_prev, pos_prev + rng.normal(scale=0.004, size=3)


def posed_head(shape, rot, pos, rot_prev, pos_prev, measure=False):
    local = shape_table([shape], measure=measure)
    now = pose.frames_at(rot, pos)
    before = pose.frames_at(rot_prev, pos_prev)
    return pose.posed(local, now[0], now[1], before[0], before[1])


def around(rng, center, axes, rot, pos, n):
    """World points around the ellipsoid ``axes`` (head frame ``center``): outside, just
    inside, deep inside, at the centre."""
    u = rng.normal(size=(n, 3))
    u /= np.linalg.norm(u / axes, axis=1)[:, None]
    q = u * rng.choice([1.3, 1.05, 0.999, 0.98, 0.6, 0.2, 0.0], size=n)[:, None]
    q += rng.normal(scale=1e-3, size=q.shape) * (rng.random(n) < 0.5)[:, None]
    return np.ascontiguousarray((q + center) @ rot.T + pos)


# ----------------------------------------------------------------------------- guides
@pytest.mark.parametrize('radii', [RADII, (0.1, 0.1, 0.1), (0.08, 0.11, 0.09)])
@pytest.mark.parametrize('friction', [0.0, 0.3])
def test_the_collision_stage_is_the_guide_solvers(radii, friction):
    """Pose, friction reference carried with the head and projection: the guide solver's
    head_motion, carry_rigid and project_ellipsoid (parallel and serial)."""
    rng = np.random.default_rng(int(radii[1] * 1000) + int(friction * 10))
    shape = head_shape(radii, friction=friction)
    rot_prev, pos_prev, rot, pos = head_poses(rng)
    col = collision.HeadCollider('ellipsoid', shape.center, radii, shape.margin, friction)
    axes = np.asarray(radii) + shape.margin
    x = around(rng, np.asarray(shape.center), axes, rot, pos, 4000).reshape(200, 20, 3)
    start = x + rng.normal(scale=0.003, size=x.shape)
    inv_mass = np.ones((200, 20))
    inv_mass[:, :2] = 0.0
    rel = np.empty((3, 3))
    integrate.head_motion(rot_prev, pos_prev, rot, pos, rel)
    x_ref = np.empty_like(x)
    integrate.carry_rigid_serial(start, rel, pos_prev, pos, x_ref)
    before = x.copy()
    n_old = collision.project_ellipsoid_serial(before, x_ref, inv_mass, rot, pos, col.model)
    parallel = x.copy()
    collision.project_ellipsoid(parallel, x_ref, inv_mass, rot, pos, col.model)
    sh = posed_head(shape, rot, pos, rot_prev, pos_prev)
    after = x.copy()
    n_new = kernels.collide(after, start, inv_mass, sh, -1.0, start.copy())
    assert n_new == n_old > 1000
    np.testing.assert_allclose(after, before, rtol=0, atol=1e-15)
    np.testing.assert_allclose(after, parallel, rtol=0, atol=1e-15)


def test_the_posed_head_is_the_kernels_centre_motion_and_quadric():
    rng = np.random.default_rng(1)

    @njit(fastmath=FASTMATH, error_model='numpy')
    def world_collider(rot, pos, center, axes, out):
        stateless.world_collider(rot, pos, center, axes, out)

    for _ in range(20):
        rot_prev, pos_prev, rot, pos = head_poses(rng)
        shape = head_shape(center=tuple(rng.normal(scale=0.02, size=3)))
        sh = posed_head(shape, rot, pos, rot_prev, pos_prev)
        rel = np.empty((3, 3))
        integrate.head_motion(rot_prev, pos_prev, rot, pos, rel)
        assert np.array_equal(sh[0, M00:M00 + 9], rel.reshape(9))
        centre = collision.world_center(rot, pos, np.asarray(shape.center))
        assert np.array_equal(sh[0, CX:CZ + 1], centre)
        geo = np.empty(9)
        world_collider(rot, pos, np.asarray(shape.center), np.asarray(RADII) + 0.004, geo)
        assert np.array_equal(sh[0, CX:CZ + 1], geo[:3])
        assert np.array_equal(sh[0, [Q00, Q11, Q22, Q01, Q02, Q12]], geo[3:])


def test_the_depth_is_the_head_colliders():
    rng = np.random.default_rng(2)
    for radii in (RADII, (0.1, 0.1, 0.1)):
        rot_prev, pos_prev, rot, pos = head_poses(rng)
        shape = head_shape(radii)
        col = collision.HeadCollider('ellipsoid', shape.center, radii, 0.004, 0.3)
        x = around(rng, np.asarray(shape.center), np.asarray(radii), rot, pos, 3000)
        x = x.reshape(100, 30, 3)
        inv_mass = np.ones((100, 30))
        old = np.empty(100)
        collision.penetration_ellipsoid_serial(x, inv_mass, False, rot, pos, col.center,
                                               col.radii, col._pen_refine, old)
        bare = posed_head(Shape('ellipsoid', center=shape.center, radii=radii), rot, pos, rot,
                          pos, measure=True)
        new = np.empty(100)
        kernels.deepest(x, inv_mass, False, bare, new)
        np.testing.assert_allclose(new, old, rtol=0, atol=1e-15)
        assert old.max() > 0.01


@njit(fastmath=FASTMATH, error_model='numpy')
def _restore_old(p, b, r, e, rot, c, axes, refine, out, flags):
    ix, iy, iz = 1.0 / (axes[0] ** 2), 1.0 / (axes[1] ** 2), 1.0 / (axes[2] ** 2)
    f_ok = ftl.restore_f_ok(axes[0], axes[1], axes[2])
    for i in range(p.shape[0]):
        qx, qy, qz = collision.to_head(p[i, 0], p[i, 1], p[i, 2], rot, c[0], c[1], c[2])
        flags[i] = qx * qx * ix + qy * qy * iy + qz * qz * iz >= f_ok
        out[i, 0], out[i, 1], out[i, 2] = ftl.restore_node(
            (p[i, 0], p[i, 1], p[i, 2]), (b[i, 0], b[i, 1], b[i, 2]), r[i],
            (e[i, 0], e[i, 1], e[i, 2]), rot, (c[0], c[1], c[2], axes[0], axes[1], axes[2],
                                               refine), 0)


@njit(inline='always')
def _placements(px, py, pz, bx, by, bz, r, ex, ey, ez, rot, sh, k, kind):
    """Follow-The-Leader's collision-aware placement against shape ``k`` of kind ``kind`` on
    the contact model."""
    for it in range(ftl.RESTORE_ITERATIONS + 1):
        dx, dy, dz, f = ftl.ftl_direction(px - bx, py - by, pz - bz, r, ex, ey, ez, rot)
        px, py, pz = bx + f * dx, by + f * dy, bz + f * dz
        if it == ftl.RESTORE_ITERATIONS:
            break
        if contact.outside_within(px, py, pz, sh, k, ftl.RESTORE_TOLERANCE):
            break
        if kind == ELLIPSOID:                   # contact.project: the closest point
            moved, px, py, pz = contact.ellipsoid_projection(
                px, py, pz, contact.placed_ellipsoid(sh, k, 0.0))
        else:
            moved, px, py, pz = contact.contact_of(kind, px, py, pz, px, py, pz, sh, k, 0.0)
    return px, py, pz


@njit(inline='always')
def _restore_node(px, py, pz, bx, by, bz, r, ex, ey, ez, rot, sh, k):
    """:func:`_placements` with the kind a constant in each branch (straight code a kind)."""
    kind = int(sh[k, KIND])
    if kind == ELLIPSOID:
        return _placements(px, py, pz, bx, by, bz, r, ex, ey, ez, rot, sh, k, ELLIPSOID)
    if kind == PLANE:
        return _placements(px, py, pz, bx, by, bz, r, ex, ey, ez, rot, sh, k, PLANE)
    return _placements(px, py, pz, bx, by, bz, r, ex, ey, ez, rot, sh, k, CAPSULE)


@njit(fastmath=FASTMATH, error_model='numpy')
def _restore_new(p, b, r, e, rot, sh, out, flags):
    for i in range(p.shape[0]):
        flags[i] = contact.outside_within(p[i, 0], p[i, 1], p[i, 2], sh, 0,
                                          ftl.RESTORE_TOLERANCE)
        out[i, 0], out[i, 1], out[i, 2] = _restore_node(
            p[i, 0], p[i, 1], p[i, 2], b[i, 0], b[i, 1], b[i, 2], r[i], e[i, 0], e[i, 1],
            e[i, 2], rot, sh, 0)


@pytest.mark.parametrize('radii', [RADII, (0.1, 0.1, 0.1)])
def test_follow_the_leaders_restore_runs_on_the_contact_model(radii):
    rng = np.random.default_rng(3)
    rot_prev, pos_prev, rot, pos = head_poses(rng)
    shape = head_shape(radii)
    axes = np.asarray(radii) + shape.margin
    p = around(rng, np.asarray(shape.center), axes, rot, pos, 2000)
    b = around(rng, np.asarray(shape.center), axes * 1.15, rot, pos, 2000)
    r = rng.uniform(0.005, 0.03, size=2000)
    e = rng.normal(scale=0.01, size=(2000, 3))
    b[::50] = p[::50]                                   # collapsed segments
    refine = 0 if len(set(radii)) == 1 else 2
    c = collision.world_center(rot, pos, np.asarray(shape.center))
    old, old_flags = np.empty_like(p), np.zeros(2000, dtype=np.bool_)
    _restore_old(p, b, r, e, rot, np.asarray(c), axes, refine, old, old_flags)
    sh = posed_head(shape, rot, pos, rot_prev, pos_prev)
    new, new_flags = np.empty_like(p), np.zeros(2000, dtype=np.bool_)
    _restore_new(p, b, r, e, rot, sh, new, new_flags)
    assert np.array_equal(new_flags, old_flags) and 100 < old_flags.sum() < 1900
    np.testing.assert_allclose(new, old, rtol=0, atol=1e-15)


# ----------------------------------------------------------------------------- paper tracker
@njit(fastmath=TRACK_FASTMATH, error_model='numpy')
def _lanes(X0, P, W, n, R, c, axes, friction, refine):
    """The paper tracker's contact stage at node 0 of a block of ``n`` lanes, without FTL."""
    contact = ((R[0, 0], R[0, 1], R[0, 2], R[1, 0], R[1, 1], R[1, 2], R[2, 0], R[2, 1], R[2, 2]),
               c[0], c[1], c[2], axes[0], axes[1], axes[2], friction, refine)
    return ghost_contacts.collide_lanes(X0, P, W, 0, (n, 0), (np.arange(n), np.ones((1, n)),
                                                              np.zeros((n, 3, 3))),
                                        False, contact, R)


@njit(fastmath=TRACK_FASTMATH, error_model='numpy')
def _scalar_new(x, r, sh, out):
    for i in range(x.shape[0]):
        moved, out[i, 0], out[i, 1], out[i, 2] = contact.contact_ellipsoid(
            x[i, 0], x[i, 1], x[i, 2], r[i, 0], r[i, 1], r[i, 2], sh, 0, sh[0, FRICTION])


@pytest.mark.parametrize('radii', [RADII, (0.08, 0.1, 0.11), (0.1, 0.1, 0.1)])
@pytest.mark.parametrize('friction', [0.0, 0.3])
def test_the_paper_trackers_contact_stage_runs_on_the_contact_model(radii, friction):
    rng = np.random.default_rng(4)
    R = quat_to_matrix(quat_from_axis_angle([0.3, 1.0, 0.2], 0.7))
    c = np.array([0.01, -0.02, 0.03])
    shape = head_shape(radii, center=(0.0, 0.0, 0.0), margin_=0.0, friction=friction)
    axes = np.asarray(radii)
    n = 300
    p = around(rng, np.zeros(3), axes, R, c, n)
    start = p + rng.normal(scale=0.003, size=p.shape)
    refine = 0 if len(set(radii)) == 1 else 2
    sh = posed_head(shape, R, c, R, c)
    want = np.empty_like(p)
    for lane_refine in (refine, 4):       # 4: more than the lane pass unrolls, node by node
        sh[0, REFINE] = lane_refine
        _scalar_new(p, start, sh, want)
        lanes = np.ascontiguousarray(p.T)[None].copy()
        m = _lanes(np.ascontiguousarray(start.T)[None], lanes,
                   np.zeros((ghost_contacts.CONTACT_ROWS, n)), n, R, c, axes, friction,
                   lane_refine)
        assert m > n // 3 and not np.array_equal(lanes[0].T, p)
        # under reassociation the last bit follows how LLVM vectorises the whole loop
        assert np.allclose(lanes[0].T, want, rtol=0, atol=1e-15)


# ----------------------------------------------------------------------------- stateless
@njit(fastmath=FASTMATH, error_model='numpy')
def _slide_push_any(N, Pp, L, sh, restore, out):
    for i in range(N.shape[0]):
        nx, ny, nz = N[i, 0], N[i, 1], N[i, 2]
        if stateless_slide.level(nx, ny, nz, sh, 0) < 0.0:
            nx, ny, nz = stateless_slide.slide_push(nx, ny, nz, Pp[i, 0], Pp[i, 1], Pp[i, 2],
                                                    L[i], restore, sh, 0)
        out[i, 0], out[i, 1], out[i, 2] = nx, ny, nz


def stateless_case(rng, radii, n=5000):
    rot_prev, pos_prev, rot, pos = head_poses(rng)
    shape = head_shape(radii)
    axes = np.asarray(radii) + shape.margin
    sh = posed_head(shape, rot, pos, rot, pos)
    u = rng.normal(size=(n, 3))
    u /= np.linalg.norm(u / axes, axis=1)[:, None]
    q = u * rng.uniform(0.5, 1.1, size=(n, 1))
    prev = u * rng.uniform(1.0, 1.2, size=(n, 1)) + rng.normal(scale=0.01, size=(n, 3))
    prev[::50] = q[::50]                                 # a step of no length
    c = np.asarray(shape.center)
    N = np.ascontiguousarray((q + c) @ rot.T + pos)
    Pp = np.ascontiguousarray((prev + c) @ rot.T + pos)
    return sh, N, Pp, HeadPose(pos, np.zeros(4), rot), axes


@pytest.mark.parametrize('radii', [RADII, (0.1, 0.1, 0.1)])
@pytest.mark.parametrize('restore', [True, False])
def test_the_blend_trackers_reference_is_the_contact_models(radii, restore):
    """The stateless trackers' plain-numpy contact (for their tests) against the compiled
    slide and push through the switch on the kind."""
    rng = np.random.default_rng(5)
    sh, N, Pp, head, axes = stateless_case(rng, radii)
    L = np.linalg.norm(N - Pp, axis=1) * rng.uniform(0.9, 1.1, size=len(N))
    got = np.empty_like(N)
    _slide_push_any(N, Pp, L, sh, restore, got)
    assert not np.array_equal(got, N)
    for i in range(0, len(N), 37):
        want = stateless.reference_contact(N[i], Pp[i], L[i], head, axes,
                                           np.asarray(head_shape(radii).center), restore)
        assert np.allclose(got[i], want, rtol=0, atol=1e-14)


def test_the_turn_trackers_contact_agrees_with_the_contact_model():
    """The turn tracker's slide puts the node back at the step's length with ``|d'|^2 =
    |d|^2 - (d.g)^2 / g.g`` (cancellation when the step points nearly along the normal); the
    contact model measures ``|d'|`` from the slid step itself: they agree to 1e-12 m."""
    rng = np.random.default_rng(6)
    for radii in (RADII, (0.1, 0.1, 0.1)):
        sh, N, Pp, head, axes = stateless_case(rng, radii)
        lanes = len(N)
        w = np.zeros((2, 2, 3, lanes))
        w[0, 0], w[0, 1] = Pp.T, N.T
        kind = np.full((1, lanes), turn.GHOST, dtype=np.int8)
        geo = np.full(12, 1e3)
        geo[:3] = sh[0, CX:CZ + 1]
        geo[3:9] = sh[0, [Q00, Q11, Q22, Q01, Q02, Q12]]
        moved = turn._contact_pass(w, kind, 0, 0, geo)
        new = np.empty_like(N)
        _slide_push_any(N, Pp, np.linalg.norm(N - Pp, axis=1), sh, True, new)
        assert moved > 1000
        assert np.allclose(w[0, 1].T, new, rtol=0, atol=1e-12)


# ----------------------------------------------------------------------------- margins
def test_the_fitted_margin_is_the_guide_solvers_and_the_trackers():
    rng = np.random.default_rng(7)
    for margin_, length in ((0.004, 0.25), (0.02, 0.25), (0.004, 0.004)):
        scene = Scene().with_changes(collider__margin=margin_)
        rest = np.zeros((5, 8, 3))
        rest[:, :, 2] = 0.106 + np.arange(8) * length / 8 + rng.uniform(0, 0.01, size=(5, 1))
        rest[:, :2, 2] = (0.09, 0.1)
        strands = StrandSet.from_rest(rest)
        solver = make_solver(strands, scene)
        shape = Shape('ellipsoid', center=scene.collider.center, radii=scene.collider.radii,
                      margin=margin_)
        free = strands.inv_mass > 0
        fitted = margin.fit_margin(shape, rest[free], strands.rest_length)
        assert fitted == solver.margin
        col = collision.head_collider(scene.collider)        # the simulator's: scene margin
        axes = col.fitted(strands.rest, strands.inv_mass, strands.rest_length).axes
        tracker = margin.fit_margin(shape, rest[:, 2:], strands.rest_length)
        assert np.array_equal(axes, np.asarray(scene.collider.radii) + tracker)
    q = rng.normal(scale=0.1, size=(500, 3))
    assert math.isfinite(float(margin.outside_distance(q, RADII).max()))


def _refined(x, ref, placed):
    """The contact's refined projection and friction about the surface normal, without the
    fast path (what contact.ellipsoid_contact does for a deeper node)."""
    rot, cx, cy, cz, ax, ay, az, mu, refine = placed
    q = contact.local_of(*x, rot, cx, cy, cz)
    y = contact.surface_point(*q, ax, ay, az, refine)
    if mu > 0.0:
        p = contact.local_of(*ref, rot, cx, cy, cz)
        y = contact.ellipsoid_friction(*y, *p, 1.0 / ax ** 2, 1.0 / ay ** 2, 1.0 / az ** 2, mu)
    return contact.world_of(*y, rot, cx, cy, cz)


@pytest.mark.parametrize('radii', [RADII, (0.1, 0.1, 0.1)])
@pytest.mark.parametrize('friction', [0.0, 0.3])
def test_the_contacts_fast_path_is_its_refined_projection_to_a_few_micrometres(radii, friction):
    """contact.ellipsoid_contact (every solver's and tracker's): for nodes with F(q) above
    SHALLOW_LEVEL (up to about half a per cent of the semi-axes deep) its fast path, a Newton
    step and friction about the gradient, lands within a few micrometres of the refined
    projection and friction about the surface normal (2.4 um at most here), on the surface to
    10 um / a; deeper nodes take the refined projection; outside nodes stay.  The plain-numpy
    reference states both paths."""
    rng = np.random.default_rng(7 + int(friction * 10))
    rot = quat_to_matrix(quat_normalize(rng.normal(size=4)))
    pos = rng.normal(scale=0.2, size=3)
    center = np.array([0.01, -0.02, 0.03])
    axes = np.asarray(radii) + 0.004
    placed = collision.placed((center, np.asarray(radii), 0.004, friction, 2), rot, pos)
    row = posed_head(Shape('ellipsoid', center=center, radii=radii, margin=0.004,
                           friction=friction), rot, pos, rot, pos)[0]
    seen = {'shallow': 0, 'deep': 0, 'out': 0}
    for k in range(600):
        u = rng.normal(size=3)
        u /= np.linalg.norm(u / axes)
        level = rng.choice([1.02, 0.9999, 0.999, 0.995, 0.9905, 0.9, 0.5])
        q = u * math.sqrt(level)          # F(q) = level
        x = rot @ (q + center) + pos
        ref = x + rng.normal(scale=0.002, size=3)
        new = contact.ellipsoid_contact(*x, *ref, placed)
        moved, expected = reference.reference_push_out(x, ref, row)
        assert new[0] == moved[0]
        np.testing.assert_allclose(new[1:], expected[0], rtol=0, atol=1e-12)
        if not new[0]:
            seen['out'] += 1
            assert new[1:] == tuple(x)
            continue
        refined = _refined(x, ref, placed)
        if level > contact.SHALLOW_LEVEL:
            seen['shallow'] += 1
            assert 0.0 < np.linalg.norm(np.subtract(new[1:], refined)) < 5e-6
            y = rot.T @ (np.array(new[1:]) - pos) - center
            if friction == 0.0:
                assert abs(np.sum((y / axes) ** 2) - 1.0) < 1e-5 / axes.min()
        else:
            seen['deep'] += 1
            np.testing.assert_allclose(new[1:], refined, rtol=0, atol=1e-15)
    assert min(seen.values()) > 50
