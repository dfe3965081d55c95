"""groom.detail_nodes: every strand kept at a finer resolution than its ghost and carried by it,
so curls finer than the ghosts' node spacing reach the output (hair_tracking.ghosts.detail)."""
from dataclasses import replace

import numpy as np
import pytest

import groom_files as gf
from hair_tracking.core.model import HeadPose
from hair_tracking.core.scene import Scene, SceneError
from hair_tracking.core.transforms import matrix_of_quat
from hair_tracking.ghosts.detail import Detail, on_segments, stencil
from hair_tracking.grooms.build import build_groom
from hair_tracking.simulator import HairSimulator

pytestmark = pytest.mark.usefixtures('one_numba_thread')

STRANDS, VERTICES, GHOST_NODES, DETAIL_NODES = 60, 100, 8, 64


@pytest.fixture(scope='module')
def curly(tmp_path_factory):
    """A curly groom (five turns a strand) of 100 vertices a strand, as a file holds it."""
    strands = gf.synthetic_groom(STRANDS, VERTICES, seed=3, ragged=False, style='curly')
    path = tmp_path_factory.mktemp('detail') / 'curly.data'
    gf.write_data(path, gf.to_file_frame(strands))
    return str(path), strands


def curly_scene(path, **changes):
    return Scene().with_changes(groom__file=path, groom__guides=8,
                                groom__ghost_nodes=GHOST_NODES,
                                groom__detail_nodes=DETAIL_NODES, **changes)


def straightness(x):
    """End-to-end distance over arc length of every strand of ``x`` (..., P, 3)."""
    arc = np.linalg.norm(np.diff(x, axis=-2), axis=-1).sum(axis=-1)
    return np.linalg.norm(x[..., -1, :] - x[..., 0, :], axis=-1) / arc


def shake(sim, poses=45):
    for k in range(poses):
        a = 0.7 * np.sin(k * 0.35)
        t = 10**9 + k * 16_666_667
        q = [np.sin(a / 2), 0.0, 0.0, np.cos(a / 2)]
        sim.push_pose(t, [0.03 * np.sin(k * 0.2), 0.0, 0.01 * k], q)
        sim.advance_to(t)


def test_the_stencil_puts_points_evenly_by_node_parameter_and_on_the_nodes():
    seg, frac = stencil(8, 64)
    u = seg + frac
    assert np.allclose(u, np.arange(64) * 7 / 63) and seg.max() == 6 and frac[-1] == 1.0
    assert np.array_equal(seg[::9], [0, 1, 2, 3, 4, 5, 6, 6]) and np.allclose(frac[:-1:9], 0)


def test_the_output_at_rest_is_the_file_and_the_ghosts_alone_lose_the_curls(curly):
    path, strands = curly
    scene = curly_scene(path)
    sim = HairSimulator(scene, settled=False)
    groom = build_groom(scene.groom)
    frame = sim.frame(head_frame=True)
    assert frame.curves.shape == (STRANDS, DETAIL_NODES, 3) and frame.strands is frame.curves
    assert np.abs(frame.curves - groom.detail_rest).max() < 1e-7
    file = np.median(straightness(np.stack(strands)))
    detail = np.median(straightness(frame.curves))
    ghosts = np.median(straightness(frame.ghosts))
    assert abs(detail - file) < 0.02, (detail, file)        # 64 of 100 vertices: the curls
    assert ghosts - file > 0.1, (ghosts, file)              # 8 nodes for 5 turns: aliased


def test_the_detail_is_carried_exactly_by_a_rigid_head(curly):
    scene = curly_scene(curly[0])
    sim = HairSimulator(scene, settled=False)
    q = np.array([0.2, -0.4, 0.3, 0.84])
    q /= np.linalg.norm(q)
    head = HeadPose(np.array([0.3, -0.1, 1.2]), q, matrix_of_quat(*q))
    sim.rest_at(head, settle=False)
    rest = build_groom(scene.groom).detail_rest
    assert np.abs(sim.frame().curves - head.to_world(rest)).max() < 1e-7
    assert np.abs(sim.frame(head_frame=True).curves - rest).max() < 1e-7


@pytest.mark.parametrize('mode', ['blend', 'turn', 'paper'])
def test_the_detail_follows_every_trackers_ghosts_without_tearing(curly, mode):
    """Through a 0.7 rad shake the fine strands stay on their ghosts (in the tracker's row
    order), keep their curls and most of their spacing: the ghosts fold at 8 nodes a strand,
    so the offsets turn with them and the detail is not length-exact (docs/grooms.md); a
straightened curl would be as long as its ghost, a fifth shorter."""
    scene = curly_scene(curly[0], tracking__mode=mode)
    sim = HairSimulator(scene)
    groom = build_groom(scene.groom)
    rows = sim.ghost_tracker.permutation
    rest, ghost_rest = groom.detail_rest[rows], groom.ghost_rest[rows]
    shake(sim)
    c = sim.frame(head_frame=True).curves
    ghosts = sim.frame(head_frame=True).ghosts
    assert np.isfinite(c).all()
    assert np.abs(ghosts - ghost_rest).max() > 0.02                         # they moved
    # the points at the ghosts' nodes are those nodes, up to the groom's offset there
    node_off = np.linalg.norm(rest[:, ::9] - ghost_rest, axis=2).max()
    assert np.linalg.norm(c[:, ::9] - ghosts, axis=2).max() <= node_off + 1e-6
    spacing = np.linalg.norm(np.diff(c, axis=1), axis=2)
    rest_spacing = np.linalg.norm(np.diff(rest, axis=1), axis=2)
    change = np.abs(spacing - rest_spacing) / np.median(rest_spacing, axis=1, keepdims=True)
    assert np.median(change) < 0.1 and np.percentile(change, 90) < 0.3, \
        np.percentile(change, [50, 90])
    arc = spacing.sum(axis=1) / rest_spacing.sum(axis=1)
    assert 0.7 < arc.min() and np.median(arc) > 0.95 and arc.max() < 1.02, \
        (arc.min(), np.median(arc), arc.max())


def test_a_procedural_groom_has_its_detail_points_on_the_ghosts_segments():
    scene = Scene().with_changes(groom__guides=6, groom__ghosts_per_guide=4,
                                 groom__detail_nodes=31, output__curve='catmull_rom')
    sim = HairSimulator(scene)
    shake(sim, 20)
    frame = sim.frame()
    seg, frac = stencil(scene.groom.ghost_nodes, 31)
    assert frame.curves.shape == (24, 31, 3)                # the detail, not output.curve
    np.testing.assert_allclose(frame.curves, on_segments(frame.ghosts, seg, frac), atol=1e-12)


def test_the_clouds_strands_are_the_frames_detail(curly):
    sim = HairSimulator(curly_scene(curly[0]))
    shake(sim, 10)
    rows = np.array([3, 17, 40, 41])
    count, points, write = sim.record_writer(rows=rows)
    assert (count, points) == (4, DETAIL_NODES)
    words = np.zeros(count * points * 4, dtype=np.float32)
    assert write(words, 4) is True
    xyz = words.reshape(count, points, 4)[..., :3]
    np.testing.assert_array_equal(xyz, sim.frame().curves[rows].astype(np.float32))
    count, points, write = sim.record_writer()
    assert (count, points) == (STRANDS, DETAIL_NODES)


def test_one_detail_point_is_refused_and_the_cache_keeps_the_detail(
        curly, tmp_path, monkeypatch):
    with pytest.raises(SceneError, match='groom.detail_nodes.*at least 2'):
        Scene().with_changes(groom__detail_nodes=1)
    with pytest.raises(ValueError, match='at least 2'):
        Detail(np.zeros((1, 4, 3)), points=1)
    from hair_tracking.grooms import cache
    monkeypatch.setattr(cache, 'folder', lambda: str(tmp_path / 'cache'))
    spec = curly_scene(curly[0]).groom
    built, loaded = build_groom(spec), build_groom(spec)
    assert np.array_equal(built.detail_rest, loaded.detail_rest)
    assert build_groom(replace(spec, detail_nodes=0)).detail_rest is None
    assert build_groom(replace(spec, ghosts_per_guide=0)).detail_rest is None
