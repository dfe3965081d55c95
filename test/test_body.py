"""The scene's body (body.*): the bust on the neck frame or a TF frame, the trackers' contact
pass over whole strands, and long hair resting on the shoulders instead of hanging through
them."""
import numpy as np
import pytest

from hair_tracking.colliders import kernels, slide
from hair_tracking.colliders.body import bust as bust_shapes
from hair_tracking.colliders.pose import frames_at, posed
from hair_tracking.colliders.reference import reference_depth
from hair_tracking.colliders.scene_body import make_body, SceneBody
from hair_tracking.colliders.table import ColliderTable
from hair_tracking.colliders.shapes import Shape, shape_table
from hair_tracking.core.metrics import max_stretch
from hair_tracking.core.model import carry_rigidly, HeadPose
from hair_tracking.core.scene import Scene
from hair_tracking.core.transforms import quat_from_axis_angle, quat_to_matrix
from hair_tracking.evaluation.stability import STRETCH_BOUND
from hair_tracking.simulator import HairSimulator


def head(position=(0.0, 0.0, 1.5), axis=(0.0, 0.0, 1.0), angle=0.0):
    q = quat_from_axis_angle(np.asarray(axis, dtype=np.float64), angle)
    return HeadPose(np.asarray(position, dtype=np.float64), q, quat_to_matrix(q))


def test_no_bust_no_body():
    assert make_body(ColliderTable(Scene()), 0.01) is None
    assert HairSimulator(Scene().with_changes(groom__guides=4, groom__ghosts_per_guide=2,
                                              solver__settle_time=0.0)).guide_solver.body is None


def test_the_fallback_bust_turns_with_the_heading_and_not_with_a_nod():
    body = SceneBody(ColliderTable(Scene().with_changes(body__bust=True)), 0.01)
    still = body.posed_bare(head())
    turned = body.posed_bare(head(angle=0.5))
    nodded = body.posed_bare(head(axis=(0.0, 1.0, 0.0), angle=0.3))
    centres = still[:, 1:4]
    # the trunk hangs below the head; the shoulders are level and left/right of it
    assert centres[4, 2] < 1.5 - 0.3 and abs(centres[1, 2] - centres[2, 2]) < 1e-12
    assert centres[1, 1] > 0.1 > -0.1 > centres[2, 1]
    c, s = np.cos(0.5), np.sin(0.5)
    rz = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    pivot = np.array([0.0, 0.0, centres[0, 2]])
    want = (centres - pivot) @ rz.T + pivot
    assert np.allclose(turned[:, 1:4], want, atol=1e-12)
    # a nod moves the pivot with the head but keeps the shoulders level
    assert abs(nodded[1, 3] - nodded[2, 3]) < 1e-12


def test_a_tf_frame_carries_the_bust_and_its_last_pose_is_kept():
    table = ColliderTable(Scene().with_changes(body__bust=True, body__frame='torso_1'))
    body = SceneBody(table, 0.01)
    fallback = body.posed_bare(head())
    table.set_body_frame(np.eye(3), [0.3, 0.0, 1.0])
    moved = body.posed_bare(head())
    local = shape_table(body.shapes, frames=('fixed', 'head', 'torso'))
    want = posed(local, *frames_at(np.eye(3), [0.0, 0.0, 1.5], [(np.eye(3), [0.3, 0.0, 1.0])]))
    assert np.allclose(moved[:, 1:4], want[:, 1:4]) and not np.allclose(moved, fallback)
    assert np.array_equal(body.posed_bare(head(angle=1.0))[:, 1:4], moved[:, 1:4])


@pytest.mark.parametrize('dtype', [np.float64, np.float32])
def test_the_strand_pass_leaves_no_node_inside_and_the_strand_below_follows(dtype):
    capsule = Shape('capsule', frame='fixed', center=(0.0, 0.0, 0.0),
                    rotation=(0.7071067811865476, 0.0, 0.0, 0.7071067811865476), radius=0.05,
                    half_length=0.1)
    sh = posed(shape_table([capsule]), *frames_at(np.eye(3), np.zeros(3)))
    # strands hanging down through the capsule (its axis along y), at x offsets across it (none
    # exactly over the axis: a step straight into the surface has no direction to slide in)
    n = 24
    xs = np.linspace(-0.06, 0.06, 13) + 0.0031
    x = np.zeros((len(xs), n, 3))
    x[:, :, 0] = xs[:, None]
    x[:, :, 2] = 0.2 - 0.02 * np.arange(n)
    rest_length = np.full((len(xs), n - 1), 0.02)
    x = np.ascontiguousarray(x.astype(dtype))
    before = x.copy()
    moved = kernels.slide_push_strands(x, rest_length, sh, 2, 0)
    assert moved > 0
    lev = np.array([[slide.level(*map(float, p), sh, 0) for p in s] for s in x])
    assert lev.min() > -1e-5                                     # float32: rounding only
    # the tips below the capsule moved with the pushed nodes above them (shape kept)
    tips = x[:, -1] - x[:, -2]
    assert np.allclose(tips, before[:, -1] - before[:, -2], atol=1e-5)
    # ... and hang beside it, not under it
    assert np.all(np.abs(x[:, -1, 0]) >= np.abs(before[:, -1, 0]) - 1e-7)
    assert np.all(np.abs(x[:, -1, 0]) > 0.045)
    # every segment keeps its length
    seg = np.linalg.norm(np.diff(x.astype(np.float64), axis=1), axis=2)
    assert np.allclose(seg, 0.02, atol=1e-5)


@pytest.mark.parametrize('dtype', [np.float64, np.float32])
@pytest.mark.parametrize('lead', [0, 1])
def test_the_shared_bound_test_changes_no_node(dtype, lead):
    """Blocks of strands share a box bound test at each node index: the result is that of
    every strand alone (a block of one, whose box is the node itself), bit for bit."""
    body = SceneBody(ColliderTable(Scene().with_changes(body__bust=True)), 0.01,
                     head=Shape('ellipsoid', radii=(0.1, 0.085, 0.11)))
    sh = body.posed(head(), head(), 0.0)
    rng = np.random.default_rng(7)
    n = 20
    roots = rng.normal(size=(200, 1, 3)) * 0.1 + np.array([0.0, 0.0, 1.45])
    steps = rng.normal(size=(200, n, 3)) * 0.008 + np.array([0.0, 0.0, -0.02])
    x = np.ascontiguousarray((roots + np.cumsum(steps, axis=1)).astype(dtype))
    rest_length = np.linalg.norm(np.diff(x.astype(np.float64), axis=1), axis=2)
    together = x.copy()
    moved = kernels.slide_push_strands(together, rest_length, sh, 2, lead)
    alone = x.copy()
    one = sum(kernels.slide_push_strands(alone[s:s + 1], rest_length[s:s + 1], sh, 2, lead)
              for s in range(len(x)))
    assert moved > 100 and one == moved
    assert np.array_equal(together, alone)


def test_a_ghost_node_in_the_crease_of_two_capsules_leaves_both():
    """A node whose sweeps over the shapes, each sliding it out of one capsule into the other,
    end inside the crease where a shoulder runs into the chest: it goes to the closest point
    outside both and back to its rest length from its predecessor (which lies outside)."""
    shapes = [s for s in bust_shapes(1.7, frame='torso', margin=0.004)
              if s.name in ('r_shoulder', 'chest')]
    sh = posed(shape_table(shapes, frames=('fixed', 'head', 'torso')),
               *frames_at(np.eye(3), np.zeros(3), [(np.eye(3), np.zeros(3))]))
    above = np.array([-0.01157711061042735, -0.1395403475036652, -0.04323857629120403])
    x = np.array([[above + [0.0, 0.0, 0.02], above,
                   [-0.00278353167093488, -0.12808622381664028, -0.03822355917954764]]])
    rest_length = np.linalg.norm(np.diff(x, axis=1), axis=2)

    def depth(p):                                     # in both capsules' surface + margin
        return [float(reference_depth(p[None], sh[k])[0]) for k in range(sh.shape[0])]

    assert max(depth(x[0, 1])) == 0.0 and min(depth(x[0, 2])) > 0.0
    assert kernels.slide_push_strands(x, rest_length, sh, 2, 0) == 1
    assert max(depth(x[0, 2])) <= kernels.CREASE_TOLERANCE
    assert np.linalg.norm(x[0, 2] - x[0, 1]) == pytest.approx(rest_length[0, 1], abs=1e-12)


def shoulder_box_points(points, h):
    """Points in the boxes of issue 34 at a 1.65 m person's shoulders (head frame): |y|
    0.09-0.20 m, |x| <= 0.07 m, 0.27-0.42 m below the head centre."""
    q = h.to_head(np.asarray(points, dtype=np.float64).reshape(-1, 3))
    return int(np.count_nonzero((np.abs(q[:, 1]) >= 0.09) & (np.abs(q[:, 1]) <= 0.20)
                                & (np.abs(q[:, 0]) <= 0.07) & (q[:, 2] <= -0.27)
                                & (q[:, 2] >= -0.42)))


def test_long_hair_rests_on_the_shoulders():
    scene = Scene.from_yaml('config/scene_long_hair.yaml').with_changes(
        groom__guides=24, groom__ghosts_per_guide=8, body__bust=True)
    out = {}
    for bust in (False, True):
        sim = HairSimulator(scene.with_changes(body__bust=bust))
        t = 1_000_000_000
        for k in range(30):                       # a still head, half a second
            sim.push_pose(t + k * 16_666_667, [0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0])
            sim.advance_to(t + k * 16_666_667)
        f = sim.frame()
        h = sim.head
        bare = SceneBody(ColliderTable(scene), 0.01).posed_bare(h)
        deep = np.zeros(f.guides.shape[0])
        kernels.deepest(f.guides, sim.guides.inv_mass, True, bare, deep)
        ghosts = np.ascontiguousarray(f.ghosts, dtype=np.float64)
        deep_g = np.zeros(ghosts.shape[0])
        kernels.deepest(ghosts, np.zeros((0, 0)), False, bare, deep_g)
        out[bust] = (deep.max(), deep_g.max(), shoulder_box_points(f.ghosts, h))
    # without the bust the hair hangs through the shoulders; with it none lies inside (the
    # boxes also hold the air around the shoulders, where hair lying on them is)
    assert out[False][1] > 0.01 and out[False][2] > 0
    assert out[True][0] == 0.0 and out[True][1] < 1e-5
    assert out[True][2] < out[False][2] / 3


def test_long_hair_guides_keep_their_lengths_on_the_bust():
    """The FTL guides resting on the bust keep their segment lengths (FTL's stretch bound of
    the stability matrix) and stay out of the bare bust."""
    scene = Scene.from_yaml('config/scene_long_hair.yaml').with_changes(
        groom__guides=24, groom__ghosts_per_guide=2, body__bust=True)
    assert scene.solver.type == 'ftl'
    sim = HairSimulator(scene)
    body = sim.guide_solver.body
    t = 1_000_000_000
    stretch, depth = 0.0, 0.0
    for k in range(40):                           # a still head, two thirds of a second
        sim.push_pose(t + k * 16_666_667, [0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0])
        sim.advance_to(t + k * 16_666_667)
        if k >= 10:
            stretch = max(stretch, max_stretch(sim.guides.x, sim.guides.rest_length))
            depth = max(depth, body.depth(sim.guides.x, sim.head, sim.guides.inv_mass))
    assert sim.guide_solver.stats['contacts_total'] > 0              # it rests on the bust
    assert stretch <= STRETCH_BOUND['ftl']
    assert depth <= body.margin


def test_the_paper_trackers_ghosts_rest_on_the_bust():
    """The paper tracker's ghosts collide with the bust through the contact model's collision
    stage: long hair on a still head, with and without the bust."""
    scene = Scene.from_yaml('config/scene_long_hair.yaml').with_changes(
        groom__guides=24, groom__ghosts_per_guide=4, tracking__mode='paper')
    out = {}
    for bust in (False, True):
        sim = HairSimulator(scene.with_changes(body__bust=bust))
        t = 1_000_000_000
        for k in range(30):                       # a still head, half a second
            sim.push_pose(t + k * 16_666_667, [0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0])
            sim.advance_to(t + k * 16_666_667)
        body = SceneBody(ColliderTable(scene.with_changes(body__bust=True)), 0.01)
        ghosts = np.ascontiguousarray(sim.ghost_tracker.positions(), dtype=np.float64)
        deep = np.zeros(ghosts.shape[0])
        kernels.deepest(ghosts, sim.ghosts.inv_mass, True, body.posed_bare(sim.head), deep)
        v = sim.ghost_tracker.velocities()
        out[bust] = (deep.max(), float(np.abs(v).max()), sim.ghost_tracker.stats['contacts'])
    assert out[False][0] > 0.01                   # without the bust the ghosts hang through it
    assert out[True][0] < 1e-6 and out[True][2] > 0
    assert np.isfinite(out[True][1]) and out[True][1] < 5.0


@pytest.mark.parametrize('mode', ['blend', 'turn', 'paper'])
def test_hair_carried_with_a_tilted_head_starts_out_of_the_bust(mode):
    """The first pose (and a reset) carries the settled hair rigidly with the head, which the
    bust on the neck frame does not follow: tilted 10 degrees, 55 cm hair would hang 5 cm into
    the trunk; it starts out of it, at rest, with every tracker's ghosts."""
    scene = Scene.from_yaml('config/scene_long_hair.yaml').with_changes(
        groom__guides=24, groom__ghosts_per_guide=2, body__bust=True, tracking__mode=mode)
    sim = HairSimulator(scene)
    body = sim.guide_solver.body
    tilted = head(position=(0.4, 0.2, 1.4), axis=(0.0, 1.0, 0.0), angle=np.radians(10.0))
    carried = carry_rigidly(sim.guides.x, sim.head, tilted)
    assert body.depth(np.ascontiguousarray(carried), tilted, sim.guides.inv_mass) > 0.02
    sim.push_pose(1_000_000_000, tilted.position, tilted.quaternion)
    assert np.allclose(sim.head.rotation, tilted.rotation)
    assert body.depth(sim.guides.x, sim.head, sim.guides.inv_mass) == 0.0
    assert body.depth(sim.ghost_tracker.positions(), sim.head) < 1e-5
    assert max_stretch(sim.guides.x, sim.guides.rest_length) <= STRETCH_BOUND['ftl']
    assert not sim.guides.v.any()
