"""The node with a body (body.*) and collider slots (colliders.*): a TF torso frame moved into
long hair pushes it out without adding energy, the bust is shown on hair/colliders, a frame
that never arrives or stops arriving is said in /diagnostics (the bust keeps its last pose),
and a collider set live on a TF frame subscribes /tf.

The node runs in-process on its own domain (test_node.py's Harness: 20-34), discovery limited
to localhost (conftest.py); every wait is bounded.
"""
from types import SimpleNamespace

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticStatus
from rclpy.parameter import Parameter
from visualization_msgs.msg import Marker, MarkerArray

from hair_tracking.colliders import kernels
from hair_tracking.core.scene import Scene, SceneError
from msg_adapters.pose import pose_stamped_msg, transform_stamped_msg

from test_node import grid_times, Harness, yaw_quat

#: Long strands that hang below the shoulders, a bust on the TF frame torso_1.
BODY = {'groom.length': 0.5, 'groom.droop': 0.9, 'groom.guide_nodes': 12,
        'groom.ghost_nodes': 12, 'body.bust': True, 'body.frame': 'torso_1'}


@pytest.fixture
def harness():
    made = []

    def make(**overrides):
        values = dict(BODY)
        values.update(overrides)
        h = Harness(values)
        made.append(h)
        return h
    yield make
    for h in made:
        h.close()


def torso(h, t, x):
    """The torso frame ``x`` metres in front of its place under the head (world)."""
    tr = transform_stamped_msg(t, [x, 0.0, -0.2], yaw_quat(0.0), 'world', 'torso_1')
    h.node.frames.on_tf(SimpleNamespace(transforms=[tr]))


def test_a_shoulder_moving_into_the_hair_pushes_it_out_without_adding_energy(harness):
    h = harness()
    pub = h.pose_publisher()
    times = grid_times(h, 100)
    dt_frame = (times[1] - times[0]) * 1e-9
    body_speed = 0.01 / dt_frame                       # 1 cm a frame while it moves
    sim = h.node.sim

    def frame(k, t, x):
        torso(h, t, x)
        h.send(pub, pose_stamped_msg(t, [0.0, 0.0, 0.0], yaw_quat(0.0), 'world'))
        return float(np.linalg.norm(sim.guides.v, axis=2).max())
    # the bust parked 30 cm in front of the hair while the hair settles
    before = max(frame(k, t, 0.3) for k, t in enumerate(times[:40]) if k >= 30)
    contacts = sim.guide_solver.stats['contacts_total']
    fastest, depth_g, depth_s = 0.0, 0.0, 0.0
    for k, t in enumerate(times[40:70]):                # then 1 cm a frame into the hair
        fastest = max(fastest, frame(k, t, 0.29 - 0.01 * k))
        body = sim.guide_solver.body
        bare = body.posed_bare(sim.head)
        f = sim.frame()
        deep = np.zeros(f.guides.shape[0])
        kernels.deepest(f.guides, sim.guides.inv_mass, True, bare, deep)
        depth_g = max(depth_g, float(deep.max()))
        ghosts = np.ascontiguousarray(f.ghosts, dtype=np.float64)
        deep = np.zeros(ghosts.shape[0])
        kernels.deepest(ghosts, np.zeros((0, 0)), False, bare, deep)
        depth_s = max(depth_s, float(deep.max()))
    assert np.allclose(sim.colliders.torso(sim.head)[1], [0.0, 0.0, -0.2])
    assert sim.guide_solver.stats['contacts_total'] > contacts     # the hair was pushed
    margin = sim.guide_solver.body.margin
    assert depth_g <= margin and depth_s <= margin + 1e-5
    # no node faster than it swung before, plus the body's speed and the push-out bound
    assert fastest < before + body_speed + sim.scene.body.max_push_speed
    # the body stopped: the hair comes to rest on it
    rest = [frame(k, t, 0.0) for k, t in enumerate(times[70:])]
    assert rest[-1] < max(rest[:5]) and rest[-1] < 0.3


def test_the_bust_is_shown_on_hair_colliders(harness):
    h = harness(**{'body.frame': ''})
    got = []
    h.probe.create_subscription(MarkerArray, 'hair/colliders', got.append, 10)
    h.spin_until(lambda: h.node.publishing.colliders_pub.get_subscription_count() > 0,
                 what='hair/colliders match')
    pub = h.pose_publisher()
    t = grid_times(h, 1)[0]
    h.send(pub, pose_stamped_msg(t, [0.0, 0.0, 1.5], yaw_quat(0.3), 'world'))
    h.spin_until(lambda: bool(got), what='collider markers')
    markers = got[-1].markers
    assert len(markers) == 15                                   # five capsules, three each
    assert [m.type for m in markers[:3]] == [Marker.CYLINDER, Marker.SPHERE, Marker.SPHERE]
    assert {m.header.frame_id for m in markers} == {'world'}
    trunk = markers[12]
    assert trunk.pose.position.z < 1.5 - 0.3                   # below the head


def test_a_frame_that_never_arrives_or_stops_is_said_in_diagnostics(harness):
    h = harness()
    pub = h.pose_publisher()
    t0, t1 = grid_times(h, 2)
    h.send(pub, pose_stamped_msg(t0, [0.0, 0.0, 0.0], yaw_quat(0.0), 'world'))
    d = h.node.diagnostics()
    assert d.level == DiagnosticStatus.WARN and "body.frame 'torso_1' not received" in d.message
    torso(h, t1, 0.1)
    h.send(pub, pose_stamped_msg(t1, [0.0, 0.0, 0.0], yaw_quat(0.0), 'world'))
    assert np.allclose(h.node.sim.colliders.torso(h.node.sim.head)[1], [0.1, 0.0, -0.2])
    d = h.node.diagnostics()
    assert 'body.frame' not in d.message
    assert float({kv.key: kv.value for kv in d.values}['body_frame_age_s']) >= 0.0
    seen, static = h.node.frames.seen['torso_1']
    h.node.frames.seen['torso_1'] = (seen - 10**11, static)               # 100 s ago
    d = h.node.diagnostics()
    assert d.level == DiagnosticStatus.WARN and "body.frame 'torso_1' stale" in d.message
    # the bust keeps its last pose
    t2 = t1 + (t1 - t0)
    h.send(pub, pose_stamped_msg(t2, [0.0, 0.0, 0.0], yaw_quat(0.5), 'world'))
    assert np.allclose(h.node.sim.colliders.torso(h.node.sim.head)[1], [0.1, 0.0, -0.2])


def test_a_bad_body_is_refused_in_one_line_naming_the_field():
    for field, value in (('body__height', -1.7), ('body__margin', -0.01),
                         ('body__friction', 2.0)):
        with pytest.raises(SceneError) as e:
            Scene().with_changes(**{field: value})
        message = str(e.value)
        assert field.replace('__', '.') in message and '\n' not in message


def test_a_collider_on_a_tf_frame_set_live_subscribes_tf_and_is_said_in_diagnostics():
    """A collider slot set live on a TF frame: /tf is subscribed then (the node started without
    it), the slot is off and /diagnostics says so until the frame arrives, then rides on it
    and keeps its last pose when it stops arriving."""
    h = Harness({'groom.length': 0.3, 'groom.guide_nodes': 8, 'groom.ghost_nodes': 8})
    try:
        node = h.node
        assert not node.frames.subscribed
        pub = h.pose_publisher()
        t0, t1, t2 = grid_times(h, 3)
        h.send(pub, pose_stamped_msg(t0, [0.0, 0.0, 0.0], yaw_quat(0.0), 'world'))
        refused = node.set_parameters([Parameter('colliders.extra_1.radius', value=-0.05)])[0]
        assert not refused.successful and 'colliders.extra_1.radius' in refused.reason
        done = node.set_parameters([Parameter('colliders.extra_1.shape', value='sphere'),
                                    Parameter('colliders.extra_1.frame', value='hand_1'),
                                    Parameter('colliders.extra_1.radius', value=0.04)])
        assert all(r.successful for r in done)
        h.send(pub, pose_stamped_msg(t1, [0.0, 0.0, 0.0], yaw_quat(0.0), 'world'))
        assert node.frames.subscribed and node.sim.collider_frames() == ('hand_1',)
        assert node.sim.colliders_waiting() == ['extra_1 (hand_1)']
        d = node.diagnostics()
        assert d.level == DiagnosticStatus.WARN
        assert "colliders.extra_1: TF frame 'hand_1' not received" in d.message
        # the hand arrives, 12 cm behind the head centre: inside the hair at the back
        tr = transform_stamped_msg(t2, [-0.12, 0.0, -0.05], yaw_quat(0.0), 'world', 'hand_1')
        node.frames.on_tf(SimpleNamespace(transforms=[tr]))
        h.send(pub, pose_stamped_msg(t2, [0.0, 0.0, 0.0], yaw_quat(0.0), 'world'))
        sim = node.sim
        assert sim.colliders_waiting() == []
        sh = sim.guide_solver.body.posed_bare(sim.head)
        assert np.allclose(sh[0, 1:4], [-0.12, 0.0, -0.05])
        assert 'colliders.extra_1' not in node.diagnostics().message
        seen, static = node.frames.seen['hand_1']
        node.frames.seen['hand_1'] = (seen - 10**11, static)      # 100 s ago
        d = node.diagnostics()
        assert d.level == DiagnosticStatus.WARN
        assert "colliders.extra_1: TF frame 'hand_1' stale" in d.message
    finally:
        h.close()
