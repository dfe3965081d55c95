"""The contact model (hair_tracking.colliders): shapes and their tables, the compiled rules
against their plain-numpy references, the bound test, the push-out velocity bound, friction
against moving colliders, the stateless trackers' slide, the fitted margin and the bust."""
import math

import numpy as np
from numba import njit
import pytest

from hair_tracking.colliders import (body, bounds, contact, crease, kernels, margin, pose,
                                     reference)
from hair_tracking.colliders import slide as stateless_slide
from hair_tracking.colliders.shapes import (A0, BOUND, CAPSULE, capsule_between, CX, CZ,
                                            FIXED_FRAME, frame_names, FRICTION, HEAD_FRAME, KIND,
                                            M00, OX, OZ, PX, PZ, R00, Shape, shape_table, WIDTH)
from hair_tracking.core.transforms import quat_from_axis_angle, quat_normalize, quat_to_matrix

FASTMATH = contact.FASTMATH


# ----------------------------------------------------------------------------- wrappers
@njit(fastmath=FASTMATH, error_model='numpy')
def push_points(x, r, sh, k, with_friction, out):
    moved = np.zeros(x.shape[0], dtype=np.bool_)
    for i in range(x.shape[0]):
        mu = sh[k, FRICTION] if with_friction else 0.0
        m, y0, y1, y2 = contact.contact_of(int(sh[k, KIND]), x[i, 0], x[i, 1], x[i, 2], r[i, 0],
                                           r[i, 1], r[i, 2], sh, k, mu)
        moved[i] = m
        out[i, 0], out[i, 1], out[i, 2] = y0, y1, y2
    return moved


@njit(fastmath=FASTMATH, error_model='numpy')
def point_values(x, sh, k, tol, out):
    """Per point: depth, outside_within(tol), level, near, carried (3), surface normal (3)."""
    for i in range(x.shape[0]):
        x0, x1, x2 = x[i, 0], x[i, 1], x[i, 2]
        out[i, 0] = contact.depth(x0, x1, x2, sh, k)
        out[i, 1] = 1.0 if contact.outside_within(x0, x1, x2, sh, k, tol) else 0.0
        out[i, 2] = stateless_slide.level(x0, x1, x2, sh, k)
        out[i, 3] = 1.0 if bounds.near(x0, x1, x2, sh, k) else 0.0
        out[i, 4], out[i, 5], out[i, 6] = contact.carried(x0, x1, x2, sh, k)
        out[i, 7], out[i, 8], out[i, 9] = contact.surface_normal(x0, x1, x2, sh, k)


@njit(fastmath=FASTMATH, error_model='numpy')
def slide_points(n, p, length, sliding, sh, k, out):
    for i in range(n.shape[0]):
        out[i, 0], out[i, 1], out[i, 2] = stateless_slide.slide_push(
            n[i, 0], n[i, 1], n[i, 2], p[i, 0], p[i, 1], p[i, 2], length[i], sliding, sh, k)


@njit(fastmath=FASTMATH, error_model='numpy')
def bounded_points(s, y, r, nrm, cap, out):
    for i in range(s.shape[0]):
        out[i, 0], out[i, 1], out[i, 2] = contact.bounded_start(
            s[i, 0], s[i, 1], s[i, 2], y[i, 0], y[i, 1], y[i, 2], r[i, 0], r[i, 1], r[i, 2],
            nrm[i, 0], nrm[i, 1], nrm[i, 2], cap)


@njit(error_model='numpy')
def strand_boxes(x, first):
    out = np.empty((x.shape[0], 6))
    for s in range(x.shape[0]):
        out[s, 0], out[s, 1], out[s, 2], out[s, 3], out[s, 4], out[s, 5] = \
            bounds.strand_box(x, s, first)
    return out


@njit(error_model='numpy')
def shape_boxes(sh):
    out = np.empty((sh.shape[0], 6))
    for k in range(sh.shape[0]):
        out[k, 0], out[k, 1], out[k, 2], out[k, 3], out[k, 4], out[k, 5] = \
            bounds.shape_box(sh, k)
    return out


@njit(error_model='numpy')
def points_meet(x, boxes, k):
    out = np.zeros(x.shape[0], dtype=np.bool_)
    for i in range(x.shape[0]):
        out[i] = bounds.boxes_meet(x[i, 0], x[i, 1], x[i, 2], x[i, 0], x[i, 1], x[i, 2],
                                   boxes, k)
    return out


@njit(error_model='numpy')
def box_tests(lo, hi, sh, k):
    out = np.zeros(lo.shape[0], dtype=np.bool_)
    for i in range(lo.shape[0]):
        out[i] = bounds.box_near(lo[i, 0], lo[i, 1], lo[i, 2], hi[i, 0], hi[i, 1], hi[i, 2],
                                 sh, k)
    return out


# ----------------------------------------------------------------------------- scenes
def rotation(rng):
    return quat_to_matrix(quat_normalize(rng.normal(size=4)))


def shapes_of_every_kind(margin_=0.004, friction=0.3):
    turned = tuple(quat_normalize([0.2, -0.1, 0.3, 1.0]))
    return [
        Shape('ellipsoid', center=(0.01, -0.02, 0.03), rotation=turned,
              radii=(0.095, 0.08, 0.105), margin=margin_, friction=friction, name='head'),
        Shape('ellipsoid', radii=(0.1, 0.1, 0.1), margin=margin_, friction=friction),
        Shape('sphere', frame='neck', center=(0.0, 0.02, 0.1), radius=0.06, margin=margin_,
              friction=friction),
        Shape('capsule', frame='neck', center=(0.0, 0.0, -0.05), rotation=turned, radius=0.05,
              half_length=0.12, margin=margin_, friction=friction),
        Shape('plane', frame=FIXED_FRAME, center=(0.0, 0.0, -0.3),
              rotation=tuple(quat_normalize([0.05, 0.0, 0.0, 1.0])), margin=margin_,
              friction=friction),
    ]


def posed_scene(rng, shapes, moving=True):
    """Posed and local tables of ``shapes`` for random frame poses (now, previous)."""
    local = shape_table(shapes)
    frames = len(frame_names(shapes))
    rot = np.stack([np.eye(3)] + [rotation(rng) for _ in range(frames - 1)])
    pos = np.concatenate([np.zeros((1, 3)), rng.normal(scale=0.2, size=(frames - 1, 3))])
    rot_prev, pos_prev = rot.copy(), pos.copy()
    if moving:
        small = quat_to_matrix(quat_from_axis_angle(rng.normal(size=3), 0.02))
        rot_prev = np.einsum('ij,fjk->fik', small, rot)
        pos_prev = pos + rng.normal(scale=0.004, size=pos.shape)
    sh = pose.posed(local, rot, pos, rot_prev, pos_prev)
    return local, sh, (rot, pos, rot_prev, pos_prev)


def points_around(rng, row, n=600):
    """World points near shape ``row``: outside, just inside and outside the surface + margin,
    deep inside, at its centre and (sphere, capsule) on its core segment."""
    kind = int(row[KIND])
    c = row[CX:CZ + 1]
    axes = row[R00:R00 + 9].reshape(3, 3)
    u = rng.normal(size=(n, 3))
    u /= np.linalg.norm(u, axis=1)[:, None]
    scale = rng.choice([1.4, 1.02, 1.0 + 3e-12, 1.0 - 3e-12, 0.98, 0.7, 0.3], size=n)[:, None]
    if kind == 2:                                          # ellipsoid: onto its surface first
        a = row[A0:A0 + 3]
        local = u / np.linalg.norm(u / a, axis=1)[:, None] * scale
        local[::23] = 0.0
    elif kind == 3:                                        # plane: heights over it
        local = rng.uniform(-0.3, 0.3, size=(n, 3))
        local[:, 2] = row[A0] + (scale[:, 0] - 1.0) * 0.05
    else:
        h = row[A0 + 1]
        t = rng.uniform(-1.3 * h - 0.01, 1.3 * h + 0.01, size=n)
        radial = u.copy()
        radial[:, 2] = 0.0
        radial /= np.maximum(np.linalg.norm(radial, axis=1), 1e-12)[:, None]
        local = radial * row[A0] * scale + np.outer(np.clip(t, -h, h), [0, 0, 1])
        outer = np.abs(t) > h                              # the caps: around the end centres
        local[outer] = np.outer(np.sign(t[outer]) * h, [0, 0, 1]) + u[outer] * row[A0] * \
            scale[outer]
        local[::29] = np.outer(rng.uniform(-h, h, size=local[::29].shape[0]), [0, 0, 1])
    return np.ascontiguousarray(local @ axes.T + c)


# ----------------------------------------------------------------------------- shapes
def test_shapes_refuse_unusable_fields_in_one_line():
    cases = [
        (Shape('cube'), "shape 'cube' is not one of sphere, capsule, ellipsoid, plane"),
        (Shape('sphere', radius=-0.1), 'radius must be a positive number of metres'),
        (Shape('capsule', radius=0.1, half_length=float('nan')), 'half_length must be >= 0'),
        (Shape('ellipsoid', radii=(0.1, 0.0, 0.1)), 'radii must be positive metres'),
        (Shape('ellipsoid', radii=(0.1, 0.1)), 'radii must be 3 finite numbers'),
        (Shape('sphere', radius=0.1, margin=-1.0), 'margin must be >= 0 metres'),
        (Shape('sphere', radius=0.1, friction=2.0), 'friction must be in [0, 1]'),
        (Shape('sphere', radius=0.1, rotation=(0, 0, 0, 2)), 'rotation must be a unit quat'),
        (Shape('sphere', radius=0.1, frame=''), 'frame must be a frame name'),
        (Shape('sphere', radius=0.1, center=(0, 0, float('inf')), name='neck'),
         'collider neck: center must be 3 finite numbers'),
    ]
    for shape, words in cases:
        with pytest.raises(ValueError, match=None) as err:
            shape.validate()
        text = str(err.value)
        assert words in text and '\n' not in text, text
    with pytest.raises(ValueError, match="frame 'torso' is not one of fixed, head"):
        shape_table([Shape('sphere', radius=0.1, frame='torso')], frames=('fixed', 'head'))


def test_the_table_lists_frames_and_refinements():
    shapes = shapes_of_every_kind()
    assert frame_names(shapes) == (FIXED_FRAME, HEAD_FRAME, 'neck')
    local = shape_table(shapes)
    assert local[:, 1].tolist() == [1, 1, 2, 2, 0]          # frame indices
    refine = local[:, -1].tolist()
    assert refine == [2, 0, 0, 0, 0]                          # a round ellipsoid: radial only
    assert shape_table(shapes, measure=True)[0, -1] == 6
    c = capsule_between((0.0, 0.1, 0.0), (0.0, 0.3, 0.2), 0.05)
    axis = quat_to_matrix(c.rotation)[:, 2]
    assert np.allclose(axis, np.array([0.0, 0.2, 0.2]) / math.sqrt(0.08))
    assert np.isclose(c.half_length, 0.5 * math.sqrt(0.08)) and c.center == (0.0, 0.2, 0.1)
    down = capsule_between((0.0, 0.0, 0.0), (0.0, 0.0, -1.0), 0.05)
    assert np.allclose(quat_to_matrix(down.rotation)[:, 2], [0.0, 0.0, -1.0])


def test_posing_matches_the_reference_and_detects_jumps():
    rng = np.random.default_rng(1)
    shapes = shapes_of_every_kind()
    local, sh, frames = posed_scene(rng, shapes)
    want = reference.reference_pose(local, *frames)
    assert sh.shape == (len(shapes), WIDTH)
    assert np.allclose(sh, want, rtol=1e-13, atol=1e-12)      # (Q's entries are ~100)
    rot, pos, rot_prev, pos_prev = frames
    jumped = pos_prev.copy()
    jumped[2] += [0.5, 0.0, 0.0]                    # the neck frame moved 0.5 m in a substep
    got = pose.posed(local, rot, pos, rot_prev, jumped, jump=0.05)
    want = reference.reference_pose(local, rot, pos, rot_prev, jumped, jump=0.05)
    assert np.allclose(got, want, rtol=1e-13, atol=1e-12)
    for k in (2, 3):                                # shapes on the neck frame: no motion
        assert np.array_equal(got[k, M00:M00 + 9], np.eye(3).reshape(9))
        assert np.array_equal(got[k, PX:PZ + 1], got[k, OX:OZ + 1])
    for k in (0, 1):                                # the head's moved a few mm: kept
        assert np.array_equal(got[k, M00:M00 + 9], sh[k, M00:M00 + 9])


# ----------------------------------------------------------------------------- contact
@pytest.mark.parametrize('with_friction', [False, True])
def test_push_out_matches_the_reference_for_every_kind(with_friction):
    rng = np.random.default_rng(2 + with_friction)
    local, sh, _ = posed_scene(rng, shapes_of_every_kind(friction=0.4))
    for k in range(sh.shape[0]):
        x = points_around(rng, sh[k])
        start = x + rng.normal(scale=0.01, size=x.shape)
        ref = reference.reference_carried(start, sh[k])
        got = np.empty_like(x)
        moved = push_points(x, ref, sh, k, with_friction, got)
        want_moved, want = reference.reference_push_out(x, ref, sh[k], with_friction)
        # points a rounding error from the surface may be decided either way
        level = reference.reference_level(x, sh[k])
        clear = np.abs(level) > 1e-12
        assert np.array_equal(moved[clear], want_moved[clear]), k
        assert moved.sum() > 100
        assert np.allclose(got[clear], want[clear], rtol=0, atol=1e-12), k
        assert np.array_equal(got[~moved], x[~moved])
        # contract: every pushed node ends on or outside the surface + margin
        values = np.empty((len(x), 10))
        point_values(got, sh, k, 1e-9, values)
        assert np.all(values[:, 1] == 1.0), k


def test_round_shapes_and_planes_project_to_the_closest_point():
    rng = np.random.default_rng(4)
    local, sh, _ = posed_scene(rng, shapes_of_every_kind(friction=0.0))
    for k in (2, 3, 4):
        x = points_around(rng, sh[k])
        y = np.empty_like(x)
        moved = push_points(x, x, sh, k, False, y)
        values = np.empty((len(x), 10))
        point_values(x, sh, k, 0.0, values)
        # moved exactly by the depth, along the surface normal at the landing point
        assert np.allclose(np.linalg.norm(y - x, axis=1), values[:, 0], rtol=0, atol=1e-14)
        normals = np.empty((len(x), 10))
        point_values(y, sh, k, 0.0, normals)
        d = y[moved] - x[moved]
        on_axis = np.linalg.norm(d, axis=1) > 1e-9
        assert np.allclose(np.cross(d[on_axis], normals[moved][on_axis, 7:10]), 0.0,
                           atol=1e-12)


def test_the_ellipsoid_refinement_nears_the_closest_point():
    """Points a known depth below a surface point along its normal: 2 refinements land within
    a few micrometres of that point at a few millimetres' depth."""
    rng = np.random.default_rng(5)
    a = np.array([0.099, 0.084, 0.109])
    local, sh, _ = posed_scene(rng, [Shape('ellipsoid', radii=tuple(a - 0.004), margin=0.004)],
                               moving=False)
    u = rng.normal(size=(300, 3))
    s = u / np.linalg.norm(u / a, axis=1)[:, None]            # on the surface (its axes)
    n = s / a ** 2
    n /= np.linalg.norm(n, axis=1)[:, None]
    axes = sh[0, R00:R00 + 9].reshape(3, 3)
    for depth, tol in ((0.002, 1e-6), (0.01, 1e-4)):
        x = np.ascontiguousarray((s - depth * n) @ axes.T + sh[0, CX:CZ + 1])
        y = np.empty_like(x)
        push_points(x, x, sh, 0, False, y)
        assert np.max(np.linalg.norm(y - (s @ axes.T + sh[0, CX:CZ + 1]), axis=1)) < tol


def test_the_bound_test_never_misses_a_contact():
    rng = np.random.default_rng(6)
    local, sh, _ = posed_scene(rng, shapes_of_every_kind())
    for k in range(sh.shape[0]):
        x = points_around(rng, sh[k], n=4000)
        values = np.empty((len(x), 10))
        point_values(x, sh, k, 0.0, values)
        inside = values[:, 0] > 0.0
        assert inside.sum() > 1000
        assert np.all(values[inside, 3] == 1.0), k              # near() where inside
        assert np.array_equal(values[:, 3] == 1.0, reference.reference_near(x, sh[k]))
        if sh[k, KIND] != 3:                                    # far points pay the bound only
            far = np.linalg.norm(x - sh[k, CX:CZ + 1], axis=1) > sh[k, BOUND]
            assert far.sum() > 10 and np.all(values[far, 3] == 0.0)
        # boxes around a few points each: near when one of its points is inside
        idx = rng.integers(0, len(x), size=(500, 3))
        lo = np.ascontiguousarray(x[idx].min(axis=1))
        hi = np.ascontiguousarray(x[idx].max(axis=1))
        hits = box_tests(lo, hi, sh, k)
        assert np.all(hits[inside[idx].any(axis=1)]), k
        want = [reference.reference_box_near(lo[i], hi[i], sh[k]) for i in range(len(lo))]
        assert hits.tolist() == want


def test_the_box_of_a_strand_holds_every_finite_node_from_first_on():
    rng = np.random.default_rng(13)
    for n in (3, 16, 77):
        x = np.ascontiguousarray(rng.normal(size=(4, n, 3)))
        for first in (0, 2):
            box = strand_boxes(x, first)
            assert np.array_equal(box[:, :3], x[:, first:].min(axis=1))
            assert np.array_equal(box[:, 3:], x[:, first:].max(axis=1))
        y = x.copy()
        y[:, n // 2] = np.nan                            # a node that is not finite
        box = strand_boxes(y, 0)
        keep = np.delete(x, n // 2, axis=1)
        assert np.array_equal(box[:, :3], keep.min(axis=1))
        assert np.array_equal(box[:, 3:], keep.max(axis=1))
    box = strand_boxes(np.full((1, 4, 3), np.nan), 0)[0]     # no finite node: near nothing
    local, sh, _ = posed_scene(rng, shapes_of_every_kind())
    for k in range(sh.shape[0]):
        assert not box_tests(np.array([box[:3]]), np.array([box[3:]]), sh, k)[0]


def test_a_shapes_box_holds_every_point_inside_it():
    rng = np.random.default_rng(17)
    local, sh, _ = posed_scene(rng, shapes_of_every_kind())
    boxes = shape_boxes(sh)
    for k in range(sh.shape[0]):
        x = points_around(rng, sh[k])
        values = np.empty((len(x), 10))
        point_values(x, sh, k, 0.0, values)
        inside = values[:, 0] > 0.0
        meets = points_meet(x, boxes, k)
        assert np.all(meets[inside]), k
        lo, hi = reference.reference_shape_box(sh[k])
        assert np.array_equal(boxes[k, :3], lo) and np.array_equal(boxes[k, 3:], hi)
        if sh[k, KIND] == CAPSULE:                   # tighter than the bounding sphere's box
            assert np.any(boxes[k, 3:] - boxes[k, :3] < 2.0 * sh[k, BOUND] * 0.9)


def test_depth_level_and_normals_match_the_reference():
    rng = np.random.default_rng(7)
    local, sh, _ = posed_scene(rng, shapes_of_every_kind())
    for k in range(sh.shape[0]):
        x = points_around(rng, sh[k])
        values = np.empty((len(x), 10))
        point_values(x, sh, k, 0.002, values)
        assert np.allclose(values[:, 0], reference.reference_depth(x, sh[k]), atol=1e-12)
        assert np.allclose(values[:, 2], reference.reference_level(x, sh[k]), atol=1e-12)
        assert np.allclose(values[:, 4:7], reference.reference_carried(x, sh[k]), atol=1e-15)
        clear = np.abs(values[:, 0] - 0.002) > 1e-12
        within = values[:, 1] == 1.0
        assert np.all(values[within, 0] <= 0.002 + 1e-12)       # depth bounded by the tolerance
        if sh[k, KIND] != 2:                                    # (the ellipsoid's test is safe,
            assert np.array_equal(within[clear], values[clear, 0] <= 0.002)  # not exact)
        _, y = reference.reference_push_out(x, x, sh[k], False)
        normals = np.empty((len(x), 10))
        point_values(y, sh, k, 0.0, normals)
        assert np.allclose(normals[:, 7:10], reference.reference_normal(y, sh[k]), atol=1e-9)


def test_the_kernels_collide_with_every_shape_in_turn():
    rng = np.random.default_rng(8)
    local, sh, _ = posed_scene(rng, shapes_of_every_kind(friction=0.3))
    x = np.concatenate([points_around(rng, sh[k], n=240) for k in range(sh.shape[0])])
    x = np.ascontiguousarray(x.reshape(-1, 12, 3))
    start = x + rng.normal(scale=0.005, size=x.shape)
    inv_mass = np.ones(x.shape[:2])
    inv_mass[:, :2] = 0.0
    got, x_old = x.copy(), start.copy()
    n = kernels.collide(got, start, inv_mass, sh, 0.001, x_old)
    want, want_old = x.copy(), start.copy()
    count = 0
    for s in range(x.shape[0]):
        for i in range(2, x.shape[1]):
            p, o, hit = want[s, i], want_old[s, i], False
            for k in range(sh.shape[0]):
                r = reference.reference_carried(start[s, i][None], sh[k])
                moved, y = reference.reference_push_out(p[None], r, sh[k])
                if moved[0]:
                    nrm = reference.reference_normal(y, sh[k])
                    o = reference.reference_bounded_start(o[None], y, r, nrm, 0.001)[0]
                    p, hit = y[0], True
            want[s, i], want_old[s, i] = p, o
            count += hit
    assert n == count and n > 500
    # a node the sweep leaves inside another shape goes to the closest point outside all
    # (test_a_node_in_a_crease_goes_to_the_closest_point_outside_both_shapes)
    creased = union_depth(want.reshape(-1, 3), sh).reshape(x.shape[:2]) > \
        kernels.CREASE_TOLERANCE
    creased[:, :2] = False                                          # the roots stay
    assert creased.sum() > 10
    assert np.allclose(got[~creased], want[~creased], rtol=0, atol=1e-11)
    assert np.allclose(x_old[~creased], want_old[~creased], rtol=0, atol=1e-11)
    assert union_depth(got[creased], sh).max() <= 1e-6
    assert np.array_equal(got[:, :2], x[:, :2])
    depth = np.empty(x.shape[0])
    kernels.deepest(x, inv_mass, True, sh, depth)
    want_depth = np.max([reference.reference_depth(x.reshape(-1, 3), sh[k]).reshape(x.shape[:2])
                         for k in range(sh.shape[0])], axis=0)
    want_depth[:, :2] = 0.0
    assert np.allclose(depth, want_depth.max(axis=1), rtol=0, atol=1e-12)
    untouched = x.copy()
    assert kernels.collide(untouched, start, inv_mass, sh[:0], -1.0, start.copy()) == 0
    assert np.array_equal(untouched, x)                                         # no shapes


# ----------------------------------------------------------------------------- motion
def pbd_step(x, start, sh, cap, dt, gravity=(0.0, 0.0, 0.0)):
    """One position-based substep of free nodes ``x`` (S, N, 3) at rest at ``start``:
    prediction under gravity, the contact kernel, ``v = (x - x_old) / dt``."""
    inv_mass = np.ones(x.shape[:2])
    pred = np.ascontiguousarray(x + np.asarray(gravity) * dt * dt)
    x_old = start.copy()
    kernels.collide(pred, start, inv_mass, sh, cap, x_old)
    return pred, (pred - x_old) / dt


def hair_in_a_ball(rng, centre, radius, n=400):
    u = rng.normal(size=(n, 3))
    u /= np.linalg.norm(u, axis=1)[:, None]
    return np.ascontiguousarray((centre + u * radius * rng.uniform(0.2, 0.98, size=(n, 1)))
                                .reshape(n, 1, 3))


def test_a_collider_that_appears_inside_resting_hair_adds_at_most_the_bound_of_energy():
    rng = np.random.default_rng(9)
    dt, cap_speed = 1.0 / 240.0, 0.2
    shapes = [Shape('sphere', frame=FIXED_FRAME, radius=0.08, margin=0.004, friction=0.3),
              capsule_between((0.3, 0.0, 0.0), (0.5, 0.0, 0.0), 0.05, frame=FIXED_FRAME)]
    local = shape_table(shapes)
    rot, pos = pose.frames_at(np.eye(3), np.zeros(3))
    sh = pose.posed(local, rot, pos)                        # at rest: no motion
    for k, (centre, r) in enumerate((((0.0, 0.0, 0.0), 0.084), ((0.4, 0.0, 0.0), 0.05))):
        x = hair_in_a_ball(rng, np.array(centre), r)
        y, v = pbd_step(x.copy(), x.copy(), sh, cap_speed * dt, dt)
        energy = 0.5 * np.sum(v ** 2, axis=-1)              # per unit mass
        assert np.all(energy <= 0.5 * cap_speed ** 2 * (1 + 1e-9)), energy.max()
        assert np.allclose(np.linalg.norm(v, axis=-1), cap_speed, rtol=1e-9)
        _, v_free = pbd_step(x.copy(), x.copy(), sh, -1.0, dt)      # no bound
        assert 0.5 * np.max(np.sum(v_free ** 2, axis=-1)) > 100 * 0.5 * cap_speed ** 2


def test_a_collider_that_jumps_onto_hair_pushes_it_out_without_launching_it():
    rng = np.random.default_rng(10)
    dt, cap = 1.0 / 240.0, 0.2 / 240.0
    local = shape_table([Shape('sphere', frame='hand', radius=0.06, friction=0.5)])
    x = hair_in_a_ball(rng, np.array([0.05, 0.0, 0.0]), 0.06)
    now = pose.frames_at(np.eye(3), np.zeros(3), [(np.eye(3), np.array([0.05, 0.0, 0.0]))])
    before = pose.frames_at(np.eye(3), np.zeros(3), [(np.eye(3), np.zeros(3))])
    for jump, fast in ((0.02, False), (math.inf, True)):
        sh = pose.posed(local, now[0], now[1], before[0], before[1], jump=jump)
        y, v = pbd_step(x.copy(), x.copy(), sh, cap, dt)
        speed = np.linalg.norm(v, axis=-1)
        assert np.all(reference.reference_level(y.reshape(-1, 3), sh[0]) >= -1e-12)
        if fast:               # the 5 cm jump taken as velocity: 12 m/s, carried into the hair
            assert speed.max() > 5.0
        else:
            assert speed.max() <= 0.2 * (1 + 1e-9)


def test_a_moving_collider_pushes_hair_at_its_own_speed():
    dt, cap = 1.0 / 240.0, 0.1 / 240.0
    u = -1.5                                                # m/s, toward the node
    local = shape_table([Shape('sphere', frame='hand', radius=0.05)])
    sh = pose.posed(local, *pose.frames_at(np.eye(3), np.zeros(3),
                                           [(np.eye(3), np.array([u * dt, 0.0, 0.0]))]),
                    *pose.frames_at(np.eye(3), np.zeros(3), [(np.eye(3), np.zeros(3))]))
    x = np.array([[[-0.0505, 0.0, 0.0]]])              # 0.5 mm behind the ball, in its way
    y, v = pbd_step(x.copy(), x.copy(), sh, cap, dt)
    assert np.isclose(y[0, 0, 0], u * dt - 0.05, atol=1e-15)       # on the moved surface
    assert np.isclose(v[0, 0, 0], (u * dt + 0.0005) / dt, atol=1e-9)    # carried, not bounded
    assert abs(v[0, 0, 0]) <= abs(u) + 0.1


@pytest.mark.parametrize('mu', [0.0, 0.5, 1.0])
def test_friction_drags_hair_with_the_surface_of_a_moving_collider(mu):
    """A node pressed onto a capsule that slides along its axis and spins about it: friction
    ``mu`` removes that share of the node's slip relative to the surface."""
    dt = 1.0 / 240.0
    slide_v, spin = 0.4, 3.0                                 # m/s along the axis, rad/s
    local = shape_table([Shape('capsule', frame='arm', radius=0.04, half_length=0.2,
                               friction=mu)])
    turn = quat_to_matrix(quat_from_axis_angle([0.0, 0.0, 1.0], spin * dt))
    now = pose.frames_at(np.eye(3), np.zeros(3), [(turn, np.array([0.0, 0.0, slide_v * dt]))])
    before = pose.frames_at(np.eye(3), np.zeros(3), [(np.eye(3), np.zeros(3))])
    sh = pose.posed(local, *now, *before)
    start = np.array([[[0.04, 0.0, 0.0]]])                  # on the surface
    x = start + np.array([-0.001, 0.0, 0.0])                # pressed 1 mm in, no slip of its own
    y, v = pbd_step(x.copy(), start.copy(), sh, -1.0, dt)
    stuck = reference.reference_carried(start.reshape(1, 3), sh[0])[0]
    plain = np.array([0.04, 0.0, 0.0])                      # projection without friction
    n = np.array([1.0, 0.0, 0.0])
    slip_stuck = (stuck - plain) - ((stuck - plain) @ n) * n
    tangential = (y[0, 0] - plain) - ((y[0, 0] - plain) @ n) * n
    assert np.allclose(tangential, mu * slip_stuck, atol=1e-15)
    if mu == 1.0:                                          # sticks: the surface's velocity
        surface_v = np.array([0.0, spin * 0.04, slide_v])
        assert np.allclose(v[0, 0, 1:], surface_v[1:], rtol=1e-3)


def test_bounded_start_matches_its_reference():
    rng = np.random.default_rng(11)
    s, y, r = (rng.normal(scale=0.01, size=(200, 3)) for _ in range(3))
    n = rng.normal(size=(200, 3))
    n /= np.linalg.norm(n, axis=1)[:, None]
    for cap in (-1.0, 0.0, 0.004):
        got = np.empty_like(s)
        bounded_points(s, y, r, n, cap, got)
        assert np.allclose(got, reference.reference_bounded_start(s, y, r, n, cap), atol=1e-16)
        if cap >= 0.0:
            assert np.all(np.sum((y - got) * n, axis=1) - np.sum((r - s) * n, axis=1)
                          <= cap + 1e-15)


# ----------------------------------------------------------------------------- stateless
@pytest.mark.parametrize('sliding', [True, False])
def test_slide_push_matches_the_reference(sliding):
    rng = np.random.default_rng(12 + sliding)
    local, sh, _ = posed_scene(rng, shapes_of_every_kind())
    for k in range(sh.shape[0]):
        nodes = points_around(rng, sh[k])
        prev = points_around(rng, sh[k]) * 1.0 + rng.normal(scale=0.01, size=nodes.shape)
        outside = reference.reference_level(prev, sh[k]) > 0.0
        nodes, prev = np.ascontiguousarray(nodes[outside]), np.ascontiguousarray(prev[outside])
        length = np.linalg.norm(nodes - prev, axis=1) * rng.uniform(0.8, 1.2, len(nodes))
        got = np.empty_like(nodes)
        slide_points(nodes, prev, length, sliding, sh, k, got)
        inside = reference.reference_level(nodes, sh[k]) < 0.0
        want = np.array([reference.reference_slide_push(n, p, L, sh[k], sliding)
                         if i else n for n, p, L, i in zip(nodes, prev, length, inside)])
        got = np.where(inside[:, None], got, nodes)
        assert np.allclose(got, want, rtol=0, atol=1e-12), k
        assert inside.sum() > 50
        assert np.all(reference.reference_level(got, sh[k]) >= -1e-12)
        if sliding:                          # slid nodes keep their distance where outside
            moved = inside & ~np.isclose(np.linalg.norm(got - nodes, axis=1), 0.0)
            kept = np.isclose(np.linalg.norm(got - prev, axis=1), length, rtol=1e-9)
            assert kept[moved].mean() > 0.5


# ----------------------------------------------------------------------------- margin
def test_the_fitted_margin_is_capped_by_clearance_and_half_the_shortest_segment():
    head = Shape('ellipsoid', radii=(0.095, 0.08, 0.105), margin=0.004)
    points = np.array([[0.0, 0.0, 0.107], [0.2, 0.0, 0.0]])      # 2 mm above the top
    assert np.isclose(margin.fit_margin(head, points, [0.01, 0.02]), 0.002)
    assert margin.fit_margin(head, points[1:], [0.01, 0.004]) == 0.002
    assert margin.fit_margin(head, points[1:], [0.0, 0.05]) == 0.004
    assert margin.fit_margin(head, None, [0.05]) == 0.004
    assert margin.fit_margin(head, points[:0], [0.001]) == 0.004          # no free node
    inside = np.array([[0.0, 0.0, 0.0]])
    assert margin.fit_margin(head, inside, [0.05]) == 0.0
    cap = capsule_between((0.0, 0.0, 0.0), (0.0, 0.0, 0.2), 0.05, margin=0.004)
    assert np.isclose(margin.fit_margin(cap, [[0.0, 0.053, 0.1]], [0.05]), 0.003)
    assert np.isclose(margin.fit_margin(cap, [[0.0, 0.0, 0.2515]], [0.05]), 0.0015)
    floor = Shape('plane', frame=FIXED_FRAME, margin=0.004)
    assert np.isclose(margin.fit_margin(floor, [[1.0, 2.0, 0.001]], [0.05]), 0.001)


def test_outside_distance_is_the_distance_to_the_ellipsoid():
    a = np.array([0.095, 0.08, 0.105])
    q = np.array([[0.2, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.09, 0.0]])
    assert np.allclose(margin.outside_distance(q, a), [0.105, 0.0, 0.01], atol=1e-12)


# ----------------------------------------------------------------------------- body
@pytest.mark.parametrize('height', [1.65, 1.8])
def test_the_bust_has_human_description_proportions(height):
    unit = height / 7.5
    b = body.body(height)
    assert np.isclose(b.unit, unit) and np.isclose(b.head_radius, unit / 2)
    assert np.isclose(b.shoulder, 0.8 * unit) and np.isclose(b.neck_length, 0.25 * unit)
    assert np.isclose(b.torso_height, 2.75 * unit) and b.limb_radius == 0.03
    bust = {s.name: s for s in body.bust(height, frame='torso_1', margin=0.002, friction=0.2)}
    assert list(bust) == ['neck', 'l_shoulder', 'r_shoulder', 'chest', 'trunk']
    assert all(s.kind == 'capsule' and s.frame == 'torso_1' and s.margin == 0.002 and
               s.friction == 0.2 for s in bust.values())

    def ends(s):
        axis = quat_to_matrix(s.rotation)[:, 2] * s.half_length
        return np.asarray(s.center) - axis, np.asarray(s.center) + axis

    for side, sign in (('l_shoulder', 1.0), ('r_shoulder', -1.0)):
        a, e = ends(bust[side])                 # out to the shoulder joint, 0.8 unit
        assert np.allclose(e, [0.0, sign * 0.8 * unit, 0.0])
    a, e = ends(bust['neck'])                   # up to the head's pivot
    assert np.allclose(e, [0.0, 0.0, 0.25 * unit])
    a, e = ends(bust['trunk'])                  # the spine, 3/4 of the torso height down
    assert np.allclose(e, [0.0, 0.0, -0.75 * 2.75 * unit])
    assert np.isclose(bust['neck'].radius, unit / 4)
    arms = body.upper_arms(height, '1')
    assert [a.frame for a in arms] == ['l_shoulder_1', 'r_shoulder_1']
    for arm in arms:
        a, e = ends(arm)
        assert arm.radius == 0.03 and np.allclose(a, 0.0)
        assert np.allclose(e, [0.0, 0.0, -1.6 * unit])
    for shape in body.bust(height) + arms:
        shape.validate()
    with pytest.raises(ValueError, match='body.height'):
        body.body(17.0)


def test_the_neck_frame_hangs_under_the_head_upright_and_turned_with_it():
    height = 1.7
    b = body.body(height)
    rot, pos = body.neck_frame(np.eye(3), np.array([0.1, 0.2, 1.6]), height)
    assert np.allclose(rot, np.eye(3))
    assert np.allclose(pos, [0.1, 0.2, 1.6 - b.head_radius - b.neck_length])
    yaw = quat_to_matrix(quat_from_axis_angle([0.0, 0.0, 1.0], 0.7))
    pitch = quat_to_matrix(quat_from_axis_angle([0.0, 1.0, 0.0], 0.4))
    pivot = np.array([0.0, 0.0, 1.5])
    head = yaw @ pitch                                     # nods about the pivot, turned
    centre = pivot + head @ np.array([0.0, 0.0, b.head_radius])
    rot, pos = body.neck_frame(head, centre, height)
    assert np.allclose(rot, yaw, atol=1e-12)               # upright, with the head's heading
    assert np.allclose(pos, pivot - [0.0, 0.0, b.neck_length])


# ----------------------------------------------------------------------------- creases
@njit(fastmath=FASTMATH, error_model='numpy')
def escape_points(x, sh, tol, out):
    moved = np.zeros(x.shape[0], dtype=np.bool_)
    for i in range(x.shape[0]):
        m, y0, y1, y2 = crease.escape(x[i, 0], x[i, 1], x[i, 2], sh, tol)
        moved[i] = m
        out[i, 0], out[i, 1], out[i, 2] = y0, y1, y2
    return moved


def union_depth(y, sh):
    """How deep [m] each point of ``y`` (M, 3) lies inside the shapes of ``sh`` (the deepest
    of them; 0 outside every one)."""
    return np.max([reference.reference_depth(y, sh[k]) for k in range(sh.shape[0])], axis=0)


def test_a_node_in_a_crease_goes_to_the_closest_point_outside_both_shapes():
    """Two overlapping balls: the closest point outside their union, against the closest of a
    dense sample of the union's surface; pushing out of one ball at a time, in sweeps, leaves
    nodes in the crease inside."""
    rng = np.random.default_rng(21)
    balls = [Shape('sphere', frame=FIXED_FRAME, radius=0.1, margin=0.004),
             Shape('sphere', frame=FIXED_FRAME, center=(0.03, 0.0, 0.0), radius=0.1,
                   margin=0.004)]
    sh = pose.posed(shape_table(balls), *pose.frames_at(np.eye(3), np.zeros(3)))
    # nodes near the crease (the circle x = 0.015, radius 0.103), inside the union
    x = np.array([0.015, 0.09, 0.0]) + rng.uniform(-0.02, 0.02, size=(400, 3))
    x = np.ascontiguousarray(x[union_depth(x, sh) > 1e-4])
    y = np.empty_like(x)
    assert escape_points(x, sh, 1e-9, y).all()
    assert union_depth(y, sh).max() <= 1e-9                   # outside both
    u = rng.normal(size=(400_000, 3))
    u /= np.linalg.norm(u, axis=1)[:, None]
    surface = np.concatenate([u * 0.104, u * 0.104 + np.array([0.03, 0.0, 0.0])])
    surface = surface[union_depth(surface, sh) <= 1e-12]
    closest = np.array([np.sqrt(np.min(np.sum((surface - p) ** 2, axis=1))) for p in x])
    got = np.linalg.norm(y - x, axis=1)
    assert np.all(got <= closest + 1e-9) and np.all(got >= closest - 1e-3)
    # shape by shape, each ball pushes the node out along its own radius: farther
    z = x.copy()
    for _ in range(4):
        for k in range(2):
            moved, w = reference.reference_push_out(z, z, sh[k])
            z = np.where(moved[:, None], w, z)
    assert np.max(np.linalg.norm(z - x, axis=1) - closest) > 1e-3


def test_the_collision_stage_leaves_no_node_inside_the_bust():
    """Nodes inside the bust's overlapping capsules (the shoulders run into the neck and the
    chest): the collision stage leaves none inside any of them."""
    rng = np.random.default_rng(22)
    shapes = body.bust(1.7, frame='torso', margin=0.004)
    sh = pose.posed(shape_table(shapes, frames=(FIXED_FRAME, HEAD_FRAME, 'torso')),
                    *pose.frames_at(np.eye(3), np.zeros(3), [(np.eye(3), np.zeros(3))]))
    x = rng.uniform((-0.15, -0.3, -0.3), (0.15, 0.3, 0.1), size=(20_000, 3))
    x = np.ascontiguousarray(x[union_depth(x, sh) > 0.0].reshape(-1, 1, 3))
    got = x.copy()
    kernels.collide(got, x.copy(), np.ones(x.shape[:2]), sh, -1.0, x.copy())
    assert union_depth(got.reshape(-1, 3), sh).max() <= kernels.CREASE_TOLERANCE + 1e-12
    alone = x.reshape(-1, 3)                     # each shape in turn, once, as a sweep does
    for k in range(sh.shape[0]):
        moved, w = reference.reference_push_out(alone, alone, sh[k])
        alone = np.where(moved[:, None], w, alone)
    assert union_depth(alone, sh).max() > 1e-3


def test_the_fitted_margin_measures_only_the_nodes_that_can_matter():
    """fit_margin measures the exact distance only for nodes that may lie nearer than the
    margin so far (a lower bound rules the others out): the same margin as measuring every
    node, for a turned ellipsoid, nodes far, near and inside."""
    rng = np.random.default_rng(11)
    shape = Shape('ellipsoid', center=(0.01, -0.02, 0.03), radii=(0.09, 0.075, 0.11),
                  margin=0.004, rotation=tuple(quat_normalize(rng.normal(size=4))))
    for depth in (0.05, 0.003, 0.0005, -0.001):
        u = rng.normal(size=(5000, 3))
        u /= np.linalg.norm(u, axis=1)[:, None]
        pts = u * (0.12 + rng.uniform(0.0, 0.2, size=(5000, 1)))
        pts[:3] = u[:3] * (np.array(shape.radii) + depth)      # a few near (or inside)
        pts = pts @ quat_to_matrix(np.array(shape.rotation)).T + shape.center
        every = max(0.0, min(0.004, 0.5 * 0.01, float(margin.clearance(pts, shape).min())))
        assert margin.fit_margin(shape, pts, [0.01, 0.02]) == every
