"""Head collider: numpy references, geometry of the projection, depth, friction, and that the
collision kernel runs only when the scene has a collider."""
from types import SimpleNamespace

import numpy as np
import pytest

from hair_tracking.colliders import contact
from hair_tracking.colliders import head as collision
from hair_tracking.colliders import shapes

from hair_tracking.core.model import HeadPose, StrandSet
from hair_tracking.core.scene import ColliderSpec, Scene
from hair_tracking.core.transforms import quat_from_axis_angle, quat_normalize, quat_to_matrix
from hair_tracking.guides import integrate
from hair_tracking.colliders.head import HeadCollider, head_collider
from hair_tracking.guides.solver import make_solver

RADII = np.array([0.095, 0.08, 0.105])


def pose(position, quaternion):
    q = quat_normalize(quaternion)
    return HeadPose(np.asarray(position, dtype=np.float64), q, quat_to_matrix(q))


def random_pose(rng):
    return pose(rng.normal(size=3) * 0.2, rng.normal(size=4))


# ------------------------------------------------------------------------- numpy references
def ref_surface_point(q, a, refine):
    f = np.sum((q / a) ** 2, axis=1)
    y = q / np.sqrt(f)[:, None]
    for _ in range(refine):
        n = y / a ** 2
        aa = np.sum(n ** 2 / a ** 2, axis=1)
        bb = np.sum(q * n / a ** 2, axis=1)
        t = (-bb + np.sqrt(bb ** 2 - aa * (f - 1.0))) / aa
        y = q + t[:, None] * n
    return y


def ref_project(x, x_prev, inv_mass, head, center, radii, margin, friction, refine):
    x = x.copy()
    a = radii + margin
    cw = head.rotation @ center + head.position
    q = (x - cw) @ head.rotation                      # R^T (x - c)
    inside = (inv_mass > 0) & (np.sum((q / a) ** 2, axis=-1) < 1.0)
    qi = q[inside]
    y = ref_surface_point(qi, a, refine)
    if friction > 0:
        qp = (x_prev[inside] - cw) @ head.rotation
        n = y / a ** 2
        n /= np.linalg.norm(n, axis=1)[:, None]
        m = y - qp
        y = y - friction * (m - np.sum(m * n, axis=1)[:, None] * n)
    x[inside] = y @ head.rotation.T + cw
    return x, int(inside.sum())


def ref_penetration(x, head, center, radii, refine):
    cw = head.rotation @ center + head.position
    q = ((x - cw) @ head.rotation).reshape(-1, 3)
    inside = np.sum((q / radii) ** 2, axis=1) < 1.0
    if not np.any(inside):
        return 0.0
    y = ref_surface_point(q[inside], radii, refine)
    return float(np.max(np.linalg.norm(y - q[inside], axis=1)))


def inflated_f(x, head, center, radii):
    q = (x - (head.rotation @ center + head.position)) @ head.rotation
    return np.sum((q / radii) ** 2, axis=-1)


def cloud(rng, head, center, scale, s=9, n=11):
    """Points around the collider, many inside, in the world frame."""
    q = rng.normal(size=(s, n, 3))
    q *= (rng.uniform(0.3, 1.3, size=(s, n)) / np.linalg.norm(q, axis=2))[..., None]
    return np.ascontiguousarray((q * scale + center) @ head.rotation.T + head.position)


# ------------------------------------------------------------------------------------ tests
@pytest.mark.parametrize('shape', ['sphere', 'ellipsoid'])
@pytest.mark.parametrize('friction', [0.0, 0.6])
def test_apply_matches_reference(shape, friction):
    rng = np.random.default_rng(1)
    spec = ColliderSpec(shape=shape, center=(0.01, -0.02, 0.015), radius=0.1,
                        radii=tuple(RADII), margin=0.004, friction=friction)
    col = head_collider(spec)
    head = random_pose(rng)
    x = cloud(rng, head, col.center, col.radii)
    x_prev = x + rng.normal(size=x.shape) * 0.01
    inv_mass = np.ones(x.shape[:2])
    inv_mass[:, :2] = 0.0
    expected, n_ref = ref_project(x, x_prev, inv_mass, head, col.center, col.radii, col.margin,
                                  col.friction, col.refine)
    got = x.copy()
    n = col.apply(got, x_prev, inv_mass, head)
    assert n == n_ref and n > 20
    assert np.allclose(got, expected, rtol=0, atol=1e-12)
    # contract: every free node ends outside surface + margin; roots and outside nodes untouched
    f = inflated_f(got, head, col.center, col.radii + col.margin)
    assert np.all(f[:, 2:] >= 1.0 - 1e-9)
    assert np.array_equal(got[:, :2], x[:, :2])
    outside = inflated_f(x, head, col.center, col.radii + col.margin) >= 1.0
    assert np.array_equal(got[outside], x[outside])


def test_sphere_projection_is_radial_to_radius_plus_margin():
    rng = np.random.default_rng(2)
    col = head_collider(ColliderSpec(shape='sphere', radius=0.1, margin=0.005, friction=0.0,
                                     center=(0.0, 0.0, 0.02)))
    assert np.all(col.radii == 0.1) and col.refine == 0
    head = random_pose(rng)
    x = cloud(rng, head, col.center, 0.1)
    inv_mass = np.ones(x.shape[:2])
    before = x.copy()
    col.apply(x, x, inv_mass, head)
    c = head.rotation @ col.center + head.position
    dist = np.linalg.norm(x - c, axis=2)
    was_in = np.linalg.norm(before - c, axis=2) < 0.105
    assert np.all(dist >= 0.105 - 1e-12)
    assert np.allclose(dist[was_in], 0.105, atol=1e-12)
    u_before = (before - c) / np.linalg.norm(before - c, axis=2)[..., None]
    u_after = (x - c) / dist[..., None]
    assert np.allclose(u_before, u_after, atol=1e-12)


def test_ellipsoid_projection_is_near_closest_point():
    """Points built at a known depth below a known surface point along its normal (that surface
    point is the true closest point: the depths stay below the smallest radius of curvature,
    0.061 m). The projection lands exactly on the surface and near the true closest point:
    measured max error 5e-6 m at 5 mm depth, 4e-5 m at 1 cm with 2 refinements."""
    rng = np.random.default_rng(3)
    a = RADII
    u = rng.normal(size=(300, 3))
    u /= np.linalg.norm(u, axis=1)[:, None]
    on = u / np.sqrt(np.sum((u / a) ** 2, axis=1))[:, None]
    normal = on / a ** 2
    normal /= np.linalg.norm(normal, axis=1)[:, None]
    for depth, refine, tol in ((0.01, shapes.ELLIPSOID_REFINEMENTS, 1e-4),
                               (0.03, shapes.PENETRATION_REFINEMENTS, 1e-4)):
        q = on - normal * rng.uniform(0.0002, depth, size=(300, 1))
        y = np.array([contact.surface_point(*qi, *a, refine) for qi in q])
        assert np.allclose(np.sum((y / a) ** 2, axis=1), 1.0, atol=1e-12)
        assert np.max(np.linalg.norm(y - on, axis=1)) < tol
        # the radial projection alone is much worse: the refinement does something
        radial = q / np.sqrt(np.sum((q / a) ** 2, axis=1))[:, None]
        assert np.max(np.linalg.norm(radial - on, axis=1)) > 10 * tol


def test_centre_point_goes_out_along_shortest_axis():
    y = contact.surface_point(0.0, 0.0, 0.0, *RADII, 2)
    assert np.allclose(y, (0.0, RADII[1], 0.0))


def test_penetration_measures_depth():
    rng = np.random.default_rng(4)
    head = random_pose(rng)
    sphere = HeadCollider('sphere', (0.0, 0.0, 0.0), (0.1, 0.1, 0.1), 0.004, 0.3)
    depths = np.array([0.0, 0.003, 0.0125, 0.007])
    dirs = rng.normal(size=(4, 3))
    dirs /= np.linalg.norm(dirs, axis=1)[:, None]
    pts_head = dirs * (0.1 - depths)[:, None]
    pts_head[0] *= 1.5                                       # one point outside
    x = np.ascontiguousarray(head.to_world(pts_head).reshape(2, 2, 3))
    assert sphere.penetration(x, head) == pytest.approx(0.0125, abs=1e-12)
    assert sphere.penetration(x + 10.0, head) == 0.0
    mass = np.ones((2, 2))
    mass[1, 0] = 0.0                                         # the deepest point is a root
    assert sphere.penetration(x, head, mass) == pytest.approx(0.007, abs=1e-12)
    # ellipsoid: along an axis the closest point is the vertex (depth < radius of curvature)
    ell = HeadCollider('ellipsoid', (0.01, 0.0, 0.0), RADII, 0.004, 0.3)
    q = np.array([[[0.01 + RADII[0] - 0.01, 0.0, 0.0], [0.01, 0.0, RADII[2] - 0.02]]])
    xw = np.ascontiguousarray(head.to_world(q))
    assert ell.penetration(xw, head) == pytest.approx(0.02, abs=1e-9)
    # and it agrees with the numpy reference on random points
    x = cloud(rng, head, ell.center, RADII)
    assert ell.penetration(x, head) == pytest.approx(
        ref_penetration(x, head, ell.center, RADII, shapes.PENETRATION_REFINEMENTS),
        abs=1e-12)


def test_friction_reduces_tangential_displacement():
    head = pose([0.1, 0.2, 0.3], quat_from_axis_angle([1, 1, 0], 0.7))
    r, m = 0.1, 0.004
    x_prev_head = np.array([[[0.0, 0.0, r + m]]])                 # resting on the top
    x_head = np.array([[[0.03, 0.0, r - 0.01]]])                  # slid and sank inside
    inv_mass = np.ones((1, 1))
    out = {}
    for fr in (0.0, 0.5, 1.0):
        col = HeadCollider('sphere', (0, 0, 0), (r, r, r), m, fr)
        x = np.ascontiguousarray(head.to_world(x_head))
        col.apply(x, np.ascontiguousarray(head.to_world(x_prev_head)), inv_mass, head)
        out[fr] = head.to_head(x)[0, 0]
    y0 = out[0.0]
    n = y0 / np.linalg.norm(y0)
    d0 = y0 - x_prev_head[0, 0]
    t0 = d0 - d0.dot(n) * n
    for fr in (0.5, 1.0):
        d = out[fr] - x_prev_head[0, 0]
        assert np.allclose(d - d.dot(n) * n, (1.0 - fr) * t0, atol=1e-12)
        assert d.dot(n) == pytest.approx(d0.dot(n), abs=1e-12)
        assert np.linalg.norm(out[fr]) >= r + m - 1e-12        # still outside


def test_head_collider_and_errors():
    assert head_collider(ColliderSpec(shape='none')) is None
    ell = head_collider(ColliderSpec(shape='ellipsoid', radii=(0.1, 0.09, 0.12)))
    assert np.allclose(ell.radii, (0.1, 0.09, 0.12)) and ell.refine > 0
    with pytest.raises(ValueError, match='collider.shape'):
        head_collider(SimpleNamespace(shape='capsule'))
    with pytest.raises(ValueError, match='radii'):
        HeadCollider('ellipsoid', (0, 0, 0), (0.1, 0.0, 0.1), 0.0, 0.0)
    head = pose([0, 0, 0], [0, 0, 0, 1])
    x = np.zeros((2, 3, 3))
    with pytest.raises(ValueError, match='x:'):
        ell.apply(x.astype(np.float32), x, np.ones((2, 3)), head)
    with pytest.raises(ValueError, match='inv_mass'):
        ell.apply(x, x, np.ones((3, 2)), head)
    with pytest.raises(ValueError, match='x_prev'):
        ell.apply(x, np.zeros((2, 3)), np.ones((2, 3)), head)


# ----------------------------------------------------- the kernel runs only when it is needed
def hanging_strands(s=6, n=8, radius=0.1):
    """Roots on the upper half of a sphere, strands pointing out along the normal."""
    rng = np.random.default_rng(5)
    u = rng.normal(size=(s, 3))
    u[:, 2] = np.abs(u[:, 2]) + 0.3
    u /= np.linalg.norm(u, axis=1)[:, None]
    rest = u[:, None, :] * (radius + 0.02 * np.arange(n))[None, :, None]
    return StrandSet.from_rest(rest)


def counting_spy(monkeypatch, module, name):
    """Calls of the kernel ``module.name`` or of its serial variant (small problems)."""
    calls = []
    for variant in (name, name + '_serial'):
        real = getattr(module, variant)

        def spy(*args, real=real):
            calls.append(1)
            return real(*args)

        monkeypatch.setattr(module, variant, spy)
    return calls


@pytest.mark.parametrize('kind', ['pbd', 'ftl'])
def test_no_collider_never_calls_collision_kernel(monkeypatch, kind):
    proj = counting_spy(monkeypatch, collision, 'project_ellipsoid')
    fin = counting_spy(monkeypatch, integrate, 'finalize')
    carry = counting_spy(monkeypatch, integrate, 'carry_rigid')
    scene = Scene().with_changes(collider__shape='none', solver__type=kind)
    g = make_solver(hanging_strands(), scene)
    assert g.collider is None
    head = pose([0, 0, 0], [0, 0, 0, 1])
    g.reset(head)
    for _ in range(5):
        g.step(scene.solver.dt, head, head)
    assert proj == [] and fin == [] and carry == []
    assert g.stats['contacts_total'] == 0


@pytest.mark.parametrize('shape', ['sphere', 'ellipsoid'])
def test_collider_scene_calls_kernel_and_keeps_hair_outside(monkeypatch, shape):
    proj = counting_spy(monkeypatch, collision, 'project_ellipsoid')
    fin = counting_spy(monkeypatch, integrate, 'finalize')
    scene = Scene().with_changes(collider__shape=shape, collider__radius=0.1,
                                 collider__radii=[0.1, 0.1, 0.1] if shape == 'sphere'
                                 else [0.1, 0.09, 0.11],
                                 solver__type='xpbd', solver__iterations=8)
    strands = hanging_strands()
    g = make_solver(strands, scene)
    assert isinstance(g.collider, HeadCollider)
    dt = scene.solver.dt
    steps = 240
    h_prev = pose([0, 0, 0], [0, 0, 0, 1])
    g.reset(h_prev)
    for k in range(1, steps + 1):
        t = k * dt
        head = pose([0.02 * np.sin(6 * t), 0, 0], quat_from_axis_angle([0, 0, 1], 0.6 * t))
        g.step(dt, h_prev, head)
        h_prev = head
    assert len(proj) == steps and len(fin) == steps
    st = g.stats
    assert st['contacts_total'] > 0            # gravity pulled strands onto the head
    free = strands.inv_mass > 0
    f = inflated_f(strands.x, h_prev, g.collider.center, g.collider.radii + g.collider.margin)
    assert np.all(f[free] >= 1.0 - 1e-9)
    assert g.collider.penetration(strands.x, h_prev, strands.inv_mass) == 0.0
