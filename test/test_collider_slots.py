"""The scene's collider slots (colliders.extra_1 .. 4): shapes on the head, the fixed frame or a
TF frame that the guides and every tracker's ghosts are kept out of, a TF frame's collider off
until its first pose, and bad input refused in one line naming the slot's field."""
import numpy as np
import pytest

from hair_tracking.colliders import kernels
from hair_tracking.colliders.scene_body import make_body
from hair_tracking.colliders.table import ColliderTable
from hair_tracking.core.scene import Scene, SceneError
from hair_tracking.simulator import HairSimulator

#: A sphere in the fixed frame behind the head, where the default hair hangs.
BEHIND = dict(colliders__extra_2__shape='sphere', colliders__extra_2__frame='fixed',
              colliders__extra_2__center=[-0.13, 0.0, -0.1],
              colliders__extra_2__radius=0.05)


def settle(sim, frames=30):
    t = 1_000_000_000
    for k in range(frames):                      # a still head, half a second
        sim.push_pose(t + k * 16_666_667, [0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0])
        sim.advance_to(t + k * 16_666_667)


def depths(sim):
    """Deepest guide and ghost node inside the bare slot shapes."""
    bare = sim.guide_solver.body.posed_bare(sim.head)
    f = sim.frame()
    deep = np.zeros(f.guides.shape[0])
    kernels.deepest(f.guides, sim.guides.inv_mass, True, bare, deep)
    ghosts = np.ascontiguousarray(sim.ghost_tracker.positions(), dtype=np.float64)
    deep_g = np.zeros(ghosts.shape[0])
    kernels.deepest(ghosts, sim.ghosts.inv_mass, True, bare, deep_g)
    return float(deep.max()), float(deep_g.max())


def test_no_slot_no_body():
    assert make_body(ColliderTable(Scene()), 0.01) is None


@pytest.mark.parametrize('mode', ['blend', 'turn', 'paper'])
def test_a_fixed_sphere_behind_the_head_keeps_the_hair_out(mode):
    base = Scene().with_changes(groom__guides=24, groom__ghosts_per_guide=4,
                                tracking__mode=mode)
    without = HairSimulator(base)
    settle(without)
    sim = HairSimulator(base.with_changes(**BEHIND))
    assert [s.name for s in sim.guide_solver.body.shapes] == ['extra_2']
    # the hair hangs through the sphere without it
    bare = sim.guide_solver.body.posed_bare(without.head)
    deep = np.zeros(without.guides.count)
    kernels.deepest(without.guides.x, without.guides.inv_mass, True, bare, deep)
    assert deep.max() > 0.01
    settle(sim)
    guides, ghosts = depths(sim)
    margin = sim.guide_solver.body.shapes[0].margin
    assert guides <= margin and ghosts <= margin + 1e-5


def test_a_tf_frame_collider_is_off_until_its_frame_arrives_and_keeps_its_last_pose():
    scene = Scene().with_changes(groom__guides=8, groom__ghosts_per_guide=2,
                                 colliders__extra_1__shape='capsule',
                                 colliders__extra_1__frame='/l_shoulder_1',
                                 colliders__extra_3__shape='ellipsoid',
                                 colliders__extra_3__frame='head',
                                 colliders__extra_3__radii=[0.01, 0.02, 0.03])
    sim = HairSimulator(scene)
    assert sim.collider_frames() == ('l_shoulder_1',)
    assert sim.colliders_waiting() == ['extra_1 (l_shoulder_1)']
    body = sim.guide_solver.body
    assert body.posed(sim.head, sim.head, 0.004).shape[0] == 1        # the ellipsoid alone
    sim.set_collider_frame('l_shoulder_1', np.eye(3), [0.0, 0.2, -0.3])
    sim.set_collider_frame('r_shoulder_1', np.eye(3), [0.0, -0.2, -0.3])   # no slot: ignored
    assert sim.colliders_waiting() == []
    sh = body.posed_bare(sim.head)
    assert sh.shape[0] == 2 and np.allclose(sh[0, 1:4], [0.0, 0.2, -0.3])
    settle(sim, 3)                               # no new pose: the last one is kept
    assert np.allclose(sim.guide_solver.body.posed_bare(sim.head)[0, 1:4], [0.0, 0.2, -0.3])


@pytest.mark.parametrize('field, value, words', [
    ('radius', -0.05, 'colliders.extra_4.radius'),
    ('radii', [0.1, 0.0, 0.1], 'colliders.extra_4.radii'),
    ('half_length', -0.1, 'colliders.extra_4.half_length'),
    ('rotation', [0.0, 0.0, 0.5, 0.5], 'colliders.extra_4.rotation: must be a unit quaternion'),
    ('frame', '', 'colliders.extra_4.frame'),
    ('frame', 'torso', 'colliders.extra_4.frame'),
    ('shape', 'box', 'colliders.extra_4.shape'),
])
def test_a_bad_slot_is_refused_in_one_line_naming_it(field, value, words):
    changes = {'colliders__extra_4__shape': 'sphere', f'colliders__extra_4__{field}': value}
    with pytest.raises(SceneError) as e:
        Scene().with_changes(**changes)
    assert words in str(e.value) and '\n' not in str(e.value)
