"""GhostTracker behaviour: exact copying, pinned roots, centre-of-mass tracking, boundedness."""
import numpy as np
import pytest

from hair_tracking.core.model import HeadPose, StrandSet
from hair_tracking.core.scene import Scene
from hair_tracking.core.transforms import quat_from_axis_angle, quat_multiply, quat_to_matrix
from hair_tracking.ghosts.interface import TrackStep
from hair_tracking.ghosts.tracker import GhostTracker

DT = 1.0 / 240.0
WEIGHTS_OFF = dict(elastic_weight=False, tip_weight=0.0, com_weight=0.0, spread=0.0,
                   length_restore=False)


def follow(tracker, guide_x_old, head, dt=DT):
    """One tracking substep after the tracker's guides moved from ``guide_x_old``."""
    tracker.step(TrackStep(dt, 1, guide_x_old, tracker.guides.x, head))


def scene_with(**tracking):
    return Scene().with_changes(**{f'tracking__{k}': v for k, v in tracking.items()})


def pose(position=(0.0, 0.0, 0.0), axis=(0.0, 0.0, 1.0), angle=0.0, q=None):
    if q is None:
        q = quat_from_axis_angle(axis, angle)
    return HeadPose(np.asarray(position, dtype=float), q, quat_to_matrix(q))


def hanging_strand(root, nodes, length=0.2, curl=0.0):
    """One rest strand (nodes, 3) from ``root`` down along -z, optionally curving along +x."""
    s = np.linspace(0.0, length, nodes)
    return np.stack([root[0] + curl * s ** 2, root[1] + 0.0 * s, root[2] - s], axis=1)


def comb(guide_roots, ghosts_per_guide, nodes=16, ghost_nodes=None, radius=0.008, seed=0):
    """Guides hanging from ``guide_roots`` and ghosts placed around each guide."""
    rng = np.random.default_rng(seed)
    ghost_nodes = ghost_nodes or nodes
    guides = np.array([hanging_strand(r, nodes, curl=0.5) for r in guide_roots])
    ghosts = []
    for r in guide_roots:
        for _ in range(ghosts_per_guide):
            off = rng.uniform(-radius, radius, size=3) * np.array([1.0, 1.0, 0.0])
            ghosts.append(hanging_strand(np.asarray(r) + off, ghost_nodes, curl=0.5))
    return StrandSet.from_rest(guides), StrandSet.from_rest(np.array(ghosts))


def oscillating_head(step, amp_angle=0.6, amp_shift=0.06):
    t = step * DT
    q1 = quat_from_axis_angle([0, 0, 1], amp_angle * np.sin(2 * np.pi * 1.5 * t))
    q2 = quat_from_axis_angle([1, 0, 0], 0.5 * amp_angle * np.sin(2 * np.pi * 0.7 * t + 1.0))
    shift = amp_shift * np.array([np.sin(2 * np.pi * 2.0 * t), np.cos(2 * np.pi * 1.1 * t), 0.0])
    return pose(shift, q=quat_multiply(q1, q2))


def wave(guides, step, amp=0.03):
    """A travelling bend of the guides on top of the head motion (world frame)."""
    m = guides.nodes
    ramp = (np.arange(m) / (m - 1)) ** 2
    phase = 2 * np.pi * 2.3 * step * DT - np.arange(m) * 0.4
    out = np.zeros(guides.x.shape)
    out[:, :, 1] = amp * ramp * np.sin(phase)
    out[:, :, 0] = 0.5 * amp * ramp * np.cos(phase)
    return out


# ------------------------------------------------------------------ velocity transfer
def test_single_ghost_copies_translated_guide_when_weights_off():
    """Translation-only head, rigid guide: ghost = guide + root offset, exactly."""
    guide = hanging_strand((0.0, 0.0, 0.0), 12, curl=0.8)
    offset = np.array([0.006, -0.004, 0.001])
    guides = StrandSet.from_rest(guide[None])
    ghosts = StrandSet.from_rest((guide + offset)[None])
    tracker = GhostTracker(ghosts, guides, scene_with(**WEIGHTS_OFF))
    assert tracker.guide_of.tolist() == [0]
    for k in range(300):
        head = pose((0.1 * np.sin(0.05 * k), 0.07 * np.cos(0.031 * k) - 0.07, 0.02 * k / 300))
        old = guides.x.copy()
        guides.x[...] = head.to_world(guides.rest)
        follow(tracker, old, head)
        np.testing.assert_allclose(tracker.positions()[0], guides.x[0] + offset, rtol=0,
                                   atol=1e-12)
    assert np.abs(tracker.positions()[0] - guide - offset).max() > 0.05      # it really moved


def test_pure_velocity_transfer_follows_a_deforming_guide():
    """Feedback off too: the ghost moves exactly by its guide's displacement, node by node."""
    rng = np.random.default_rng(1)
    guide = hanging_strand((0.0, 0.0, 0.0), 10)
    offset = np.array([0.0, 0.01, 0.0])
    guides = StrandSet.from_rest(guide[None])
    ghosts = StrandSet.from_rest((guide + offset)[None])
    tracker = GhostTracker(ghosts, guides, scene_with(offset_strength=0.0, com_strength=0.0,
                                                      **WEIGHTS_OFF))
    for k in range(100):
        head = pose((0.01 * k, 0.0, 0.0))
        old = guides.x.copy()
        guides.x[...] = head.to_world(guides.rest)
        guides.x[:, 2:] += rng.normal(scale=0.01, size=(1, 8, 3))
        follow(tracker, old, head)
        np.testing.assert_allclose(tracker.positions()[0], guides.x[0] + offset, rtol=0,
                                   atol=1e-12)


def test_offsets_turn_with_the_head_only_with_feedback():
    """Copying velocities does not rotate the offsets (the flaw of TressFX follow hairs);
    the offset/centre-of-mass feedback does."""
    guides, _ = comb([(0.0, 0.0, 0.0)], 1)
    offset = np.array([0.02, 0.0, 0.0])
    results = {}
    for name, strengths in {'copy': dict(offset_strength=0.0, com_strength=0.0),
                            'feedback': {}}.items():
        g = StrandSet.from_rest(guides.rest)
        ghosts = StrandSet.from_rest(guides.rest + offset)
        tracker = GhostTracker(ghosts, g, scene_with(**strengths, **WEIGHTS_OFF))
        for k in range(240):
            head = pose(angle=np.pi / 2 * min(1.0, k / 120))
            old = g.x.copy()
            g.x[...] = head.to_world(g.rest)
            follow(tracker, old, head)
        want = head.to_world(ghosts.rest)          # rotated offsets
        results[name] = np.abs(tracker.positions() - want).max()
    assert results['feedback'] < 1e-6
    assert results['copy'] > 0.01


# ------------------------------------------------------------------ roots
@pytest.mark.parametrize('options', [{}, dict(elastic_mode='changed', spread=0.5,
                                              tip_weight=2.0, com_weight=20.0)])
def test_roots_pinned_under_rotation_and_translation(options):
    guides, ghosts = comb([(0.0, 0.0, 0.0), (0.03, 0.01, 0.0), (-0.02, 0.03, 0.01)], 5)
    tracker = GhostTracker(ghosts, guides, scene_with(**options))
    for k in range(200):
        head = oscillating_head(k)
        old = guides.x.copy()
        guides.x[...] = head.to_world(guides.rest) + wave(guides, k)
        follow(tracker, old, head)
        err = np.abs(tracker.positions()[:, :2] - head.to_world(ghosts.rest[:, :2])).max()
        assert err < 1e-9
    assert np.all(np.isfinite(tracker.positions())) and np.all(np.isfinite(tracker.velocities()))


# ------------------------------------------------------------------ centre of mass
def test_group_centre_of_mass_contracts_toward_its_target():
    """One substep with a still guide: the group's centre-of-mass error shrinks by exactly
    (1 - com_strength) (1 - offset_strength); the spread about it only by (1 - offset)."""
    guides, ghosts = comb([(0.0, 0.0, 0.0)], 4)
    k_com, k_off = 0.4, 0.1
    tracker = GhostTracker(ghosts, guides, scene_with(com_strength=k_com, offset_strength=k_off,
                                                      **WEIGHTS_OFF))
    head = pose()
    target = tracker.targets(head)
    rng = np.random.default_rng(5)
    x = np.array(tracker.positions())
    x[:, 2:] += np.array([0.01, -0.02, 0.005]) + rng.normal(scale=0.003, size=(4, 14, 3))
    tracker.set_state(x, tracker.velocities())
    err0 = tracker.positions() - target
    follow(tracker, guides.x.copy(), head)
    err1 = tracker.positions() - target
    com0, com1 = err0[:, 2:].mean(axis=0), err1[:, 2:].mean(axis=0)
    np.testing.assert_allclose(com1, (1 - k_com) * (1 - k_off) * com0, atol=1e-15)
    np.testing.assert_allclose(err1[:, 2:] - com1, (1 - k_off) * (err0[:, 2:] - com0),
                               atol=1e-15)


def test_group_centre_of_mass_tracks_moving_target():
    guides, ghosts = comb([(0.0, 0.0, 0.0), (0.04, 0.0, 0.0)], 6)
    k_com = 0.5
    tracker = GhostTracker(ghosts, guides, scene_with(offset_strength=0.0, com_strength=k_com,
                                                      length_restore=False))
    guides.place_at(oscillating_head(0))
    tracker.reset(oscillating_head(0))
    com_err, guide_step = [], []
    for k in range(900):
        head = oscillating_head(k) if k < 600 else oscillating_head(600)
        old = guides.x.copy()
        guides.x[...] = head.to_world(guides.rest) + wave(guides, min(k, 600))
        follow(tracker, old, head)
        guide_step.append(np.linalg.norm(guides.x - old, axis=2).max())
        if k % 10 == 0 or k == 899:
            target = tracker.targets(head)
            errs = []
            for g in range(tracker.group_guide.size):
                m = tracker.group_members(g)
                errs.append(np.abs((tracker.positions()[m] - target[m]).mean(axis=0)).max())
            com_err.append(max(errs))
    # during motion the weights push the group ahead by at most max_weight * (guide step) per
    # substep and the centre-of-mass pull takes back k_com of the lead: lead <= W d / k_com
    bound = 1.5 * max(guide_step) / k_com
    assert 0.0 < max(com_err[:60]) < bound
    assert com_err[-1] < 1e-9                  # and it converges once the target stops
    # individual ghosts keep some individuality (no offset pull): not all on their targets
    assert np.abs(tracker.positions() - tracker.targets(head)).max() > com_err[-1]


# ------------------------------------------------------------------ energy
@pytest.mark.parametrize('mode', ['kept', 'changed'])
@pytest.mark.parametrize('ftl', [False, True])
def test_ghosts_stay_bounded_with_weights_on(mode, ftl):
    """Many substeps of oscillating motion with large weights: deviations and speeds stay
    bounded and die out when the guides stop (the weights inject no energy)."""
    guides, ghosts = comb([(0.0, 0.0, 0.0), (0.03, 0.0, 0.0), (0.0, 0.03, 0.0)], 6)
    tr = dict(elastic_mode=mode, tip_weight=2.0, com_weight=30.0, max_weight=1.5,
              length_restore=ftl)
    scene = scene_with(**tr)
    tracker = GhostTracker(ghosts, guides, scene)
    guides.place_at(oscillating_head(0))
    tracker.reset(oscillating_head(0))
    steps, still = 2400, 480
    dev, speed, guide_step = [], [], []
    for k in range(steps + still):
        head = oscillating_head(min(k, steps))
        old = guides.x.copy()
        guides.x[...] = head.to_world(guides.rest) + wave(guides, min(k, steps))
        follow(tracker, old, head)
        guide_step.append(np.linalg.norm(guides.x - old, axis=2).max())
        speed.append(np.linalg.norm(tracker.velocities(), axis=2).max())
        if k % 20 == 0 or k == steps + still - 1:
            dev.append(np.linalg.norm(tracker.positions() - tracker.targets(head), axis=2).max())
    dev, speed = np.array(dev), np.array(speed)
    assert np.all(np.isfinite(dev)) and np.all(np.isfinite(speed))
    n = steps // 20
    # no growth: the last third of the motion deviates no more than the middle third
    assert dev[2 * n // 3:n].max() <= 1.1 * dev[n // 3:2 * n // 3].max()
    # speeds: at most (1 + 2 max_weight) the guides' (docs/ghosts.md), plus FTL corrections
    max_guide_speed = max(guide_step) / DT
    assert speed[:steps].max() <= (1 + 2 * 1.5) * max_guide_speed * (1.5 if ftl else 1.0)
    if not ftl:
        # deviation bound of docs/ghosts.md: max_weight * guide step / offset_strength
        assert dev.max() <= 1.5 * max(guide_step) / 0.05 + 1e-9
    # after the guides stop, the ghosts come to rest ...
    assert speed[-1] < 1e-3 * speed[:steps].max()
    if not ftl:
        # ... on their targets (with FTL, where the bent guides are not isometric to the rest
        # shape, at the compromise between the target pull and the rest lengths)
        assert dev[-1] < 1e-3 * dev[:n].max()


# ------------------------------------------------------------------ spread
def test_spread_control_reaches_target_variance():
    guides, ghosts = comb([(0.0, 0.0, 0.0)], 8, radius=0.01)
    tracker = GhostTracker(ghosts, guides, scene_with(**dict(WEIGHTS_OFF, spread=0.5,
                                                             spread_target=2.0)))
    var0 = ((ghosts.rest - ghosts.rest.mean(axis=0)) ** 2).sum(axis=(0, 2))
    head = pose()
    for _ in range(200):
        follow(tracker, guides.x.copy(), head)
    var = ((tracker.positions() - tracker.positions().mean(axis=0)) ** 2).sum(axis=(0, 2))
    np.testing.assert_allclose(var[2:] / var0[2:], 2.0, rtol=1e-3)
    np.testing.assert_allclose(var[:2], var0[:2], rtol=1e-12)        # roots stay pinned


# ------------------------------------------------------------------ layout, options
def test_regroup_keeps_results_and_reports_permutation():
    guides, ghosts = comb([(0.0, 0.0, 0.0), (0.03, 0.0, 0.0), (0.0, 0.03, 0.0)], 4)
    rng = np.random.default_rng(2)
    scramble = rng.permutation(ghosts.count)
    rest = ghosts.rest[scramble]
    a = StrandSet.from_rest(rest)
    b = StrandSet.from_rest(rest)
    ga, gb = StrandSet.from_rest(guides.rest), StrandSet.from_rest(guides.rest)
    ta = GhostTracker(a, ga, Scene())
    tb = GhostTracker(b, gb, Scene(), regroup=False)
    np.testing.assert_array_equal(a.rest, rest[ta.permutation])
    assert np.all(np.diff(ta.guide_of) >= 0)                  # groups contiguous
    np.testing.assert_array_equal(tb.permutation, np.arange(b.count))
    np.testing.assert_array_equal(ta.guide_of, tb.guide_of[ta.permutation])
    for k in range(50):
        head = oscillating_head(k)
        for g, t in ((ga, ta), (gb, tb)):
            old = g.x.copy()
            g.x[...] = head.to_world(g.rest) + wave(g, k)
            follow(t, old, head)
    # bit-identical, deterministic
    np.testing.assert_array_equal(ta.positions(), tb.positions()[ta.permutation])
    np.testing.assert_array_equal(ta.velocities(), tb.velocities()[ta.permutation])
    # a tracker rebuilt on grouped ghosts, started from the state of the first, keeps their
    # order and that state
    a.x[...], a.v[...] = ta.positions(), ta.velocities()
    tc = GhostTracker(a, ga, scene_with(com_strength=0.2))
    np.testing.assert_array_equal(tc.permutation, np.arange(a.count))
    np.testing.assert_array_equal(tc.positions(), tb.positions()[ta.permutation])
    np.testing.assert_array_equal(tc.velocities(), tb.velocities()[ta.permutation])


def test_reset_and_stats():
    guides, ghosts = comb([(0.0, 0.0, 0.0), (0.03, 0.0, 0.0)], 3)
    tracker = GhostTracker(ghosts, guides, scene_with(tip_weight=5.0, max_weight=0.5))
    head = pose((0.1, 0.2, 0.3), angle=0.4)
    old = guides.x.copy()
    guides.x[...] = head.to_world(guides.rest)
    follow(tracker, old, head)
    assert tracker.stats['steps'] == 1
    assert tracker.stats['clamped'] > 0                   # w_tip 5 > max_weight 0.5
    assert tracker.stats['groups'] == 2 and tracker.stats['ghosts'] == 6
    tracker.reset(head)
    np.testing.assert_allclose(tracker.positions(), head.to_world(ghosts.rest), atol=1e-15)
    assert not tracker.velocities().any()


def test_the_head_collider_is_the_tables_head_row_or_none():
    """collide means "with the scene's head collider, if it has one": none given, none run;
    anything but the table's head row (a HeadCollider) is refused."""
    guides, ghosts = comb([(0.0, 0.0, 0.0)], 3)
    tracker = GhostTracker(ghosts, guides, scene_with(collide=True), None)
    follow(tracker, guides.x.copy(), pose())
    assert not tracker.collide and tracker.stats['contacts'] == 0

    class Plane:
        def apply(self, x, x_prev, inv_mass, head):
            return 0

    for other in (object(), Plane()):
        with pytest.raises(ValueError, match='HeadCollider'):
            GhostTracker(ghosts, guides, scene_with(collide=True), other)


@pytest.mark.parametrize('length_restore', [True, False])
def test_fused_ellipsoid_collision_pushes_ghosts_out(length_restore):
    """The project's Collider runs inside the kernel: after a step that drives the ghosts into a
    sphere, no free node is inside it; with length restoration the segments keep their rest
    lengths; velocities stay the displacement over dt; with collision off they stay inside."""
    from hair_tracking.colliders.head import HeadCollider
    guides, ghosts = comb([(0.0, 0.0, 0.0), (0.03, 0.0, 0.0)], 8)
    radius, margin = 0.05, 0.004
    collider = HeadCollider('sphere', (0.02, 0.0, -0.15), (radius,) * 3, margin, 0.3)
    opts = dict(length_restore=length_restore, offset_strength=0.0, com_strength=0.0)
    results = {}
    for collide in (False, True):
        g = StrandSet.from_rest(guides.rest)
        h = StrandSet.from_rest(ghosts.rest)
        tracker = GhostTracker(h, g, scene_with(collide=collide, **opts), collider)
        assert tracker.collide == collide
        old = g.x.copy()
        g.x[:, 2:, 0] += 0.02            # guides swing toward the sphere's centre
        g.x[:, 2:, 2] -= 0.01
        x_prev = tracker.positions().copy()
        follow(tracker, old, pose())
        x = tracker.positions()
        np.testing.assert_allclose(tracker.velocities(), (x - x_prev) / DT, atol=1e-9)
        results[collide] = (h, tracker)
    c = collider.center
    inside_before = np.linalg.norm(results[False][1].positions()[:, 2:] - c, axis=-1).min()
    assert inside_before < radius - 0.01       # without collision the ghosts went in
    h, tracker = results[True]
    assert tracker.stats['contacts'] > 0
    x = tracker.positions()
    depth = np.linalg.norm(x[:, 2:] - c, axis=-1).min()
    assert depth >= radius - 1e-9               # outside the bare sphere
    if length_restore:
        seg = np.linalg.norm(np.diff(x, axis=1), axis=-1)
        np.testing.assert_allclose(seg[:, 1:], h.rest_length[:, 1:], rtol=1e-9)
    else:
        assert depth >= radius + margin - 1e-9  # a plain push ends on the surface + margin


def test_degenerate_strands_give_no_nan():
    guide = hanging_strand((0.0, 0.0, 0.0), 8)
    guide_flat = guide.copy()
    guide_flat[3] = guide_flat[2]                            # zero-length rest segment
    ghost_point = np.zeros((8, 3))                           # zero-length ghost
    ghost_dup = guide.copy() + [0.01, 0, 0]
    ghost_dup[4:] = ghost_dup[4]                             # coincident nodes
    guides = StrandSet.from_rest(np.array([guide, guide_flat]))
    ghosts = StrandSet.from_rest(np.array([ghost_point, ghost_dup, guide + [0, 0.01, 0]]))
    tracker = GhostTracker(ghosts, guides, scene_with(spread=1.0, spread_target=3.0,
                                                      com_weight=50.0, tip_weight=5.0))
    for k in range(60):
        head = oscillating_head(k)
        old = guides.x.copy()
        guides.x[...] = head.to_world(guides.rest)
        guides.x[:, 5] = guides.x[:, 4]                      # collapsed segment now
        guides.x[:, 7] = 2 * guides.x[:, 6] - guides.x[:, 7]  # reversed tip segment
        follow(tracker, old, head)
        assert np.all(np.isfinite(tracker.positions()))
        assert np.all(np.isfinite(tracker.velocities()))


def test_bad_input_is_rejected_with_a_reason():
    guides, ghosts = comb([(0.0, 0.0, 0.0)], 2)
    tracker = GhostTracker(ghosts, guides, Scene())
    with pytest.raises(ValueError, match='dt'):
        follow(tracker, guides.x.copy(), pose(), dt=0.0)
    with pytest.raises(ValueError, match='guide_x_old'):
        follow(tracker, guides.x[:, :3].copy(), pose())
    empty = StrandSet.from_rest(np.zeros((0, 16, 3)))
    with pytest.raises(ValueError, match='at least one guide'):
        GhostTracker(ghosts, empty, Scene())
    bad = StrandSet.from_rest(ghosts.rest.copy())
    bad.rest[0, 3, 1] = np.nan
    with pytest.raises(ValueError, match='NaN'):
        GhostTracker(bad, guides, Scene())


def test_state_in_kernel_layout_is_shown_and_set_through_the_tracker():
    """The tracker keeps the ghost state in its kernel's layout between steps:
    :meth:`positions` after any step shows the current state, a state set between steps
    (:meth:`set_state`) is used by the next step, and a second tracker started from the first
    one's state continues exactly as the first would.  Results do not depend on when the state
    was read."""
    def run(read_between, touch, handover=False):
        guides, ghosts = comb([(0.0, 0.0, 0.0), (0.02, 0.0, 0.0)], 5, seed=3)
        scene = scene_with()
        tracker = GhostTracker(ghosts, guides, scene)
        seen = []
        for k in range(6):
            head = oscillating_head(k)
            old = guides.x.copy()
            guides.x[...] = head.to_world(guides.rest)
            if handover and k == 3:
                ghosts.x[...], ghosts.v[...] = tracker.positions(), tracker.velocities()
                tracker = GhostTracker(ghosts, guides, scene)
            follow(tracker, old, head)
            if read_between:
                seen.append(tracker.positions().copy())
            if touch and k == 2:
                x = np.array(tracker.positions())
                x[:, 2:, 0] += 0.002                  # taken by the next step
                tracker.set_state(x, tracker.velocities())
        return tracker.positions().copy(), tracker.velocities().copy(), seen

    x_read, v_read, seen = run(True, True)
    x_quiet, v_quiet, _ = run(False, True)
    np.testing.assert_array_equal(x_read, x_quiet)
    np.testing.assert_array_equal(v_read, v_quiet)
    np.testing.assert_array_equal(seen[-1], x_read)
    assert not np.array_equal(seen[1], seen[2])       # each read shows the newest state
    x_untouched, _, _ = run(False, False)
    assert np.abs(x_untouched - x_quiet).max() > 1e-4  # the state set was not lost
    x_handover, v_handover, _ = run(False, True, handover=True)
    np.testing.assert_array_equal(x_handover, x_quiet)
    np.testing.assert_array_equal(v_handover, v_quiet)


def test_positions_for_output_keep_the_state_in_the_kernel_layout(monkeypatch):
    """``positions()`` (what the simulator's frames and checks read) shows the current state
    read-only and leaves it with the tracker: the next step does not copy anything in again.
    Output needs only the positions: the velocities are written out when
    ``velocities()`` is read."""
    import hair_tracking.ghosts.tracker as ghosts_module
    copies = []
    real = ghosts_module.copy_blocks

    def counting(*args):
        copies.append(args[6] if args[7] else (args[6], 'x only'))   # into_blocks, with_v
        return real(*args)
    monkeypatch.setattr(ghosts_module, 'copy_blocks', counting)
    guides, ghosts = comb([(0.0, 0.0, 0.0), (0.02, 0.0, 0.0)], 4, seed=5)
    tracker = GhostTracker(ghosts, guides, scene_with())
    assert copies == [True]                 # the start state into the blocks
    v_before = tracker.velocities().copy()
    old = guides.x.copy()
    guides.x[:, 2:, 0] += 0.003
    follow(tracker, old, pose())
    seen = tracker.positions()
    assert copies == [True, (False, 'x only')]
    with pytest.raises(ValueError):
        seen[0, 0, 0] = 1.0                 # read-only
    assert np.array_equal(tracker.positions(), seen) and copies == [True, (False, 'x only')]
    follow(tracker, guides.x.copy(), pose())
    assert copies == [True, (False, 'x only')]   # no copy back in: the tracker kept the state
    v = tracker.velocities()
    assert copies[-1] is False              # x and v written out
    assert np.abs(v - v_before).max() > 0.0
    follow(tracker, guides.x.copy(), pose())
    assert copies == [True, (False, 'x only'), False]   # reads never copy back in
