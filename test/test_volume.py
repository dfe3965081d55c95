"""volume.enabled: the guides push apart where they are denser than at rest and move together,
through a grid fixed to the head (hair_tracking.guides.volume)."""
import os

import numba
import numpy as np
import pytest

from hair_tracking.core.metrics import hair_layer
from hair_tracking.core.model import StrandSet
from hair_tracking.core.scene import Scene
from hair_tracking.ghosts.correspondence import near_other_strands
from hair_tracking.guides.volume import MAX_CELLS, VolumeGrid
from hair_tracking.people.crowd import Crowd
from hair_tracking.simulator import HairSimulator

pytestmark = pytest.mark.usefixtures('one_numba_thread')

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
LONG_HAIR = Scene.from_yaml(os.path.join(ROOT, 'config', 'scene_long_hair.yaml')).with_changes(
    groom__ghosts_per_guide=4)


def layer(sim):
    """The hair layer on the top of the head (:func:`~hair_tracking.core.metrics.hair_layer`
    of the output strands): ``(spread, median)`` [m]."""
    c = sim.scene.collider
    return hair_layer(sim.frame(head_frame=True).strands, c.center, c.radii)[:2]


def test_off_builds_no_stage_and_on_the_grid_keeps_its_size_whatever_the_motion():
    sim = HairSimulator(Scene())
    assert sim.guide_solver.volume is None
    sim = HairSimulator(Scene().with_changes(volume__enabled=True))
    grid = sim.guide_solver.volume
    cells, shape = grid.cells, grid.grid.shape
    for k, (p, turn) in enumerate([([0.0, 0.0, 0.0], 0.0), ([0.3, 0.0, 0.0], 2.0),
                                   ([5.0, -3.0, 1.0], 3.0)]):        # moves, turns, a teleport
        t = 10**9 + k * 50_000_000
        sim.push_pose(t, p, [0.0, 0.0, np.sin(turn / 2), np.cos(turn / 2)])
        sim.advance_to(t)
    assert grid.cells == cells and grid.grid.shape == shape and cells <= MAX_CELLS
    assert not grid.grid.any()                       # the touched cells were cleared


def test_long_hair_on_a_still_head_has_volume_and_comes_to_rest():
    """The done-when of the volume stage: with it, the layer of long hair on the top of a still
    head is at least 1.5 times as thick as without; lengths, the collider's margin and rest
    are kept; fewer nodes lie within 2 mm of another strand."""
    still = dict(solver__settle_speed=0.002, solver__max_substeps=10_000)
    flat = HairSimulator(LONG_HAIR.with_changes(**still))
    full = HairSimulator(LONG_HAIR.with_changes(volume__enabled=True, **still))
    (thin, _), (thick, median) = layer(flat), layer(full)
    assert thick >= 1.5 * thin, (thick, thin)
    assert full.settled_s < 29.0                     # came to rest before the settle's cap
    assert full.guide_solver.stats['max_stretch'] < 1e-9       # FTL's lengths, exact
    assert full.max_stretch() <= 0.01
    assert full.penetration() <= LONG_HAIR.collider.margin
    assert median > layer(flat)[1]
    # and the strands run through one another less (docs/volume.md: 37 % -> 12 % at 2 mm)
    near = [near_other_strands(sim.frame(head_frame=True).strands, 0.002) for sim in (flat, full)]
    assert near[1] < 0.5 * near[0], near


def strands_around(count=9, nodes=6, spread=0.03):
    """``count`` straight strands hanging from a row of roots ``spread`` apart (head frame)."""
    rest = np.zeros((count, nodes, 3))
    rest[:, :, 0] = (np.arange(count) - count // 2)[:, None] * spread
    rest[:, :, 1] = 0.2
    rest[:, :, 2] = 0.1 - np.linspace(0.0, 0.1, nodes)[None, :]
    return StrandSet.from_rest(rest)


def test_the_stage_changes_velocities_only_and_pushes_dense_hair_apart():
    st = strands_around()
    grid = VolumeGrid(st.rest, st.inv_mass,
                      Scene().with_changes(volume__pressure=50.0, volume__friction=0.0).volume)
    x = st.rest.copy()
    x[:, :, 0] *= 0.1                               # squeezed together: ten times the density
    v = np.zeros_like(x)
    x0 = x.copy()
    grid.apply(x, v, np.eye(3), np.zeros(3), 1 / 240)
    assert np.array_equal(x, x0)
    free = st.inv_mass > 0
    assert np.all(v[~free] == 0.0)
    side = np.sign(x[:, :, 0])[free]
    outward = (v[:, :, 0][free] * side)[side != 0]
    assert outward.min() > 0.0                     # every side node pushed away from the middle
    # turned with the head: the same push, turned
    c, s = np.cos(0.7), np.sin(0.7)
    rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    pos = np.array([1.0, 2.0, 0.5])
    w = np.zeros_like(x)
    grid.apply(x0 @ rot.T + pos, w, rot, pos, 1 / 240)
    np.testing.assert_allclose(w, v @ rot.T, atol=1e-12)


def test_friction_moves_velocities_together_and_keeps_their_sum():
    st = strands_around(spread=0.004)
    grid = VolumeGrid(st.rest, st.inv_mass,
                      Scene().with_changes(volume__pressure=0.0, volume__friction=200.0).volume)
    rng = np.random.default_rng(3)
    v = rng.normal(size=st.rest.shape) * (st.inv_mass > 0)[..., None]
    before = v.copy()
    grid.apply(st.rest.copy(), v, np.eye(3), np.zeros(3), 1 / 240)
    np.testing.assert_allclose(v.sum(axis=(0, 1)), before.sum(axis=(0, 1)), atol=1e-9)
    assert v[st.inv_mass > 0].var(axis=0).sum() < 0.7 * before[st.inv_mass > 0].var(axis=0).sum()


def test_a_grid_finer_than_the_bound_takes_a_larger_cell():
    long = HairSimulator(LONG_HAIR.with_changes(volume__enabled=True, volume__cell_size=0.002,
                                                solver__settle_time=0.0))
    grid = long.guide_solver.volume
    assert grid.cells <= MAX_CELLS and grid.h > 0.002


def test_people_each_have_their_own_volume():
    """Several heads: the guide solver takes one call a person with the stage on (it couples
    a person's strands after every substep), and each person's hair keeps its lengths."""
    scene = Scene().with_changes(volume__enabled=True, groom__guides=16,
                                 groom__ghosts_per_guide=2, solver__settle_time=0.0)
    crowd = Crowd(scene, places=3)
    assert not crowd.batched
    for k in range(12):
        t = 10**9 + k * 16_666_667
        for i, name in enumerate(('a', 'b', 'c')):
            pose = (t, [0.5 * i, 0.02 * np.sin(k), 0.0], [0.0, 0.0, 0.0, 1.0])
            (crowd.add if k == 0 else crowd.push_pose)(name, *pose)
        crowd.advance_to(t)
    for name in ('a', 'b', 'c'):
        sim = crowd.people[name]
        assert sim.guide_solver.volume is not None
        assert sim.guide_solver.stats['max_stretch'] < 1e-9


def test_many_people_with_volume_stay_bounded_through_a_fast_shake():
    """Eight people with the stage on, each shaking at 50 rad/s (8 Hz) beside the others: every
    strand stays finite, FTL's lengths exact, and the nodes no faster than the motion can make
    them (the shake's 50 rad/s at the tips' reach, twice over)."""
    from hair_tracking.evaluation import synthetic_motion as sm
    scene = Scene().with_changes(volume__enabled=True, groom__guides=24,
                                 groom__ghosts_per_guide=2, solver__settle_time=0.0)
    motion = sm.shake(50.0, 8.0, duration_s=0.5)
    names = [f'p{i}' for i in range(8)]
    crowd = Crowd(scene, places=len(names))
    x_prev = None
    for k, t in enumerate(motion.t_ns):
        for i, name in enumerate(names):
            pos = motion.position[k] + [0.6 * i, 0.0, 0.0]
            (crowd.add if k == 0 else crowd.push_pose)(name, int(t), pos, motion.quaternion[k])
        crowd.advance_to(int(t))
        if k == 0:            # the farthest rest node from the head's centre
            rest = crowd.people[names[0]].guide_solver.strands.rest
            reach = float(np.linalg.norm(rest, axis=2).max())
        x = np.stack([crowd.people[n].guide_solver.strands.x for n in names])
        assert np.isfinite(x).all()
        if x_prev is not None:
            dt = (motion.t_ns[k] - motion.t_ns[k - 1]) * 1e-9
            assert np.linalg.norm(x - x_prev, axis=-1).max() / dt < 2 * 50.0 * reach
        x_prev = x
    for name in names:
        sim = crowd.people[name]
        assert sim.guide_solver.volume is not None
        assert sim.guide_solver.stats['max_stretch'] < 1e-9
        assert sim.max_stretch() <= 0.01


def test_the_stage_runs_on_a_fixed_period_however_the_solver_is_called():
    """Eight substeps in one call or one at a time: the same hair (the stage runs every
    PERIOD_S of substeps, counted across calls)."""
    from hair_tracking.core.head_track import head_pose
    scene = Scene().with_changes(volume__enabled=True, groom__guides=12,
                                 groom__ghosts_per_guide=0, solver__settle_time=0.0)
    a, b = HairSimulator(scene), HairSimulator(scene)
    dt = scene.solver.dt
    poses = [head_pose([0.01 * k, 0.0, 0.0], [0.0, 0.0, np.sin(0.05 * k), np.cos(0.05 * k)])
             for k in range(9)]
    a.guide_solver.advance(dt, poses[0], poses[1:])
    for k in range(8):
        b.guide_solver.step(dt, poses[k], poses[k + 1])
    assert a.guide_solver.volume.period(dt) == 4
    np.testing.assert_allclose(a.guides.x, b.guides.x, atol=1e-12)
    np.testing.assert_allclose(a.guides.v, b.guides.v, atol=1e-9)


@pytest.mark.skipif(numba.config.NUMBA_NUM_THREADS < 2, reason='needs two numba threads')
def test_the_threaded_stage_gives_the_same_sums_on_any_thread_count_and_leaves_the_grid_empty():
    """The splat's lanes sum in a fixed order: the parallel kernels give the same velocities on
    one thread and on every thread, the serial variants the same to rounding; every grid is
    empty after a run."""
    st = strands_around(count=40, nodes=12, spread=0.004)
    spec = Scene().with_changes(volume__pressure=50.0, volume__friction=20.0).volume
    rng = np.random.default_rng(5)
    x = st.rest + rng.normal(scale=0.003, size=st.rest.shape) * (st.inv_mass > 0)[..., None]
    v0 = rng.normal(size=x.shape) * (st.inv_mass > 0)[..., None]
    out = {}
    threads = numba.get_num_threads()
    try:
        for parallel, count in ((False, 1), (True, 1), (True, numba.config.NUMBA_NUM_THREADS)):
            numba.set_num_threads(count)
            grid = VolumeGrid(st.rest, st.inv_mass, spec, parallel)
            v = v0.copy()
            grid.apply(x, v, np.eye(3), np.zeros(3), 1 / 60)
            assert not grid.grids.any()                 # cleared for the next run
            out[parallel, count] = v
    finally:
        numba.set_num_threads(threads)
    assert not np.array_equal(out[False, 1], v0)
    np.testing.assert_array_equal(out[True, 1], out[True, numba.config.NUMBA_NUM_THREADS])
    np.testing.assert_allclose(out[False, 1], out[True, 1], rtol=0, atol=1e-12)


def test_near_other_strands_counts_the_nodes_with_another_strand_close_by():
    x = np.zeros((3, 5, 3))
    x[:, :, 2] = np.arange(5)[None, :] * 0.02                 # 2 cm segments
    x[1, :, 0] = 0.001                                        # 1 mm beside strand 0
    x[2, :, 0] = 0.05                                         # 5 cm away
    assert near_other_strands(x, 0.002) == pytest.approx(10 / 15)
    assert near_other_strands(x, 0.0005) == 0.0
    x[2, 2] = (0.0, 0.0015, 0.04)                             # one node of 2 runs into 0
    assert near_other_strands(x, 0.002) == pytest.approx(11 / 15)
    x[2, 2] = (0.05, 0.0, 0.04)
    x[1, :, 2] = np.arange(5) * 0.0005 + 0.0012              # 0.5 mm segments above node 0
    x[1, :, 0] = 0.0                                          # of strand 0: two within 2 mm
    assert near_other_strands(x, 0.002) == pytest.approx(3 / 15)
    # a strand folded on itself puts many of its own nodes nearer than the other strand's
    z = np.zeros((2, 8, 3))
    z[0, :, 1] = 0.0005 * (np.arange(8) // 2)                # folds 0.5 mm apart
    z[0, :, 2] = 0.02 * (np.arange(8) % 2)
    z[1, :, 0], z[1, :, 2] = 0.05, np.arange(8) * 0.02
    z[1, 0] = (0.0018, 0.0, 0.0)                             # 1.8 mm from node 0 of strand 0
    d = np.linalg.norm(z[0][:, None] - z[1][None], axis=2) <= 0.002
    assert near_other_strands(z, 0.002) == pytest.approx(
        (d.any(axis=1).sum() + d.any(axis=0).sum()) / 16)
    assert near_other_strands(z, 0.002) > 1 / 16
    with pytest.raises(ValueError, match='radius'):
        near_other_strands(x, 0.0)
