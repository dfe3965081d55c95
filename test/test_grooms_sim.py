"""An imported groom in the simulator: every tracker runs it, its rest shape does not explode at
start, a groom file that cannot be read is refused and the hair kept, and the blend and turn
trackers pass the stability matrix's core cases on it."""
from dataclasses import replace

import numpy as np
import pytest

import groom_files as gf
from hair_tracking.core.params import ParamError
from hair_tracking.core.scene import Scene
from hair_tracking.evaluation import stability
from hair_tracking.grooms.polylines import GroomFileError
from hair_tracking.output.settings import apply_changes, make_settings
from hair_tracking.simulator import HairSimulator

pytestmark = pytest.mark.usefixtures('one_numba_thread')

#: The stability matrix's groups that do not depend on the procedural groom's shape or on the
#: PBD iteration count: time steps, head speed, teleports, gravity, invalid poses.
CORE_GROUPS = ('time step', 'head speed', 'teleport', 'gravity', 'invalid poses')


@pytest.fixture(scope='module')
def groom_file(tmp_path_factory):
    path = tmp_path_factory.mktemp('groom') / 'styled.hair'
    gf.write_hair(path, gf.to_file_frame(gf.synthetic_groom(120, 24, seed=5)))
    return str(path)


def shake(sim, poses=40, t0=10**9, amplitude=0.6):
    for k in range(poses):
        a = amplitude * np.sin(k * 0.35)
        t = t0 + k * 16_666_667
        q = [0.0, 0.0, np.sin(a / 2), np.cos(a / 2)]
        sim.push_pose(t, [0.03 * np.sin(k * 0.2), 0.0, 0.0], q)
        sim.advance_to(t)
    return t


@pytest.mark.parametrize('mode', ['paper', 'blend', 'turn'])
def test_every_tracker_runs_an_imported_groom(groom_file, mode):
    scene = Scene().with_changes(groom__file=groom_file, groom__guides=12, tracking__mode=mode)
    sim = HairSimulator(scene)
    assert sim.ghosts.count == 120 and sim.guides.count == 12
    assert 'styled.hair' in sim.groom_note and '12 guides' in sim.groom_note
    if mode != 'paper':          # the guides are imported strands, chosen by root and shape
        assert np.array_equal(sim.ghosts.rest[sim.guide_index], sim.guides.rest)
    shake(sim)
    frame = sim.frame()
    assert np.isfinite(frame.ghosts).all()
    assert sim.max_stretch() < 1e-5
    assert sim.penetration() <= scene.collider.margin
    want = sim.head.to_world(sim.ghosts.rest[:, :2])
    assert np.abs(frame.ghosts[:, :2] - want).max() < 1e-5      # roots carried by the head


def test_the_imported_hair_starts_at_rest_near_its_groomed_shape(groom_file):
    """No explosion at start: the settle leaves the hair outside the head, close to the shape
    it was groomed in and nearly still (what is left of the sag is measured in
    docs/grooms.md)."""
    scene = Scene().with_changes(groom__file=groom_file, tracking__mode='paper',
                                 groom__ghosts_per_guide=0, groom__guides=120,
                                 solver__settle_time=2.0)
    sim = HairSimulator(scene)
    x0 = sim.frame(head_frame=True).guides
    rest, lengths = sim.guides.rest, sim.guides.strand_length
    moved = np.linalg.norm(x0 - rest, axis=2).max(axis=1) / lengths
    assert np.median(moved) < 0.6 and sim.penetration() < 1e-9
    sim.push_pose(10**9, [0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0])
    sim.advance_to(10**9 + 250_000_000)
    later = sim.frame(head_frame=True).guides
    assert np.linalg.norm(later - x0, axis=2).max() < 0.05 * lengths.max()


def test_a_groom_file_that_cannot_be_read_changes_nothing(groom_file, tmp_path):
    scene = Scene().with_changes(groom__file=groom_file, groom__guides=12)
    sim = HairSimulator(scene)
    shake(sim, poses=5)
    before = sim.frame().ghosts
    data = open(groom_file, 'rb').read()
    (tmp_path / 'cut.hair').write_bytes(data[:len(data) // 2])
    bad = scene.with_changes(groom__file=str(tmp_path / 'cut.hair'))
    with pytest.raises(GroomFileError, match='byte'):
        sim.update_scene(bad)
    assert sim.scene is scene and np.array_equal(sim.frame().ghosts, before)
    shake(sim, poses=3, t0=2 * 10**9)                   # and it goes on
    assert np.isfinite(sim.frame().ghosts).all()


def test_a_change_to_a_bad_groom_file_is_refused_with_one_line(groom_file, tmp_path):
    settings = make_settings({'groom.guides': 12})
    (tmp_path / 'bad.data').write_bytes(np.int32(5).tobytes() + b'\x00' * 6)
    with pytest.raises(ParamError) as e:
        apply_changes(settings, {'groom.file': str(tmp_path / 'bad.data')})
    text = str(e.value)
    assert text.startswith('groom.file: ') and 'bad.data: byte' in text and '\n' not in text
    with pytest.raises(ParamError, match='file not found'):
        apply_changes(settings, {'groom.file': str(tmp_path / 'none.hair')})
    new, rebuild = apply_changes(settings, {'groom.file': groom_file})
    assert rebuild and new.scene.groom.file == groom_file
    same, rebuild = apply_changes(new, {'publish_rate_hz': 20.0})   # no groom change: no read
    assert not rebuild


CORE = [c for c in stability.matrix(quick=True) if c.group in CORE_GROUPS]


@pytest.mark.parametrize('mode', ['blend', 'turn'])
@pytest.mark.parametrize('case', CORE, ids=[c.name for c in CORE])
def test_the_stability_matrix_core_cases_pass_on_an_imported_groom(groom_file, mode, case):
    scene = case.scene.with_changes(groom__file=groom_file, tracking__mode=mode)
    r = stability.run_case(replace(case, scene=scene))
    assert r.passed, f'{case.name} ({mode}): {r.failures} (worst {r.worst})'
    assert r.counters['substeps'] > 0


def test_the_imported_hair_comes_to_rest_with_the_head_still(groom_file):
    """Waved and curled strands (strongly bent: second-neighbour rest distances down to a
    fraction of their two segments) come to rest with the head still: after the settle and
    a few seconds more, no node moves 0.1 mm in 0.1 s (FTL's Jacobi bending sweep; with a
    Gauss-Seidel sweep some of them turn on for ever, docs/grooms.md "The rest shape")."""
    scene = Scene().with_changes(groom__file=groom_file, tracking__mode='paper',
                                 groom__ghosts_per_guide=0, groom__guides=24,
                                 solver__settle_time=10.0)
    sim = HairSimulator(scene)
    rest, seg = sim.guides.rest, sim.guides.rest_length
    ratio = np.linalg.norm(rest[:, 2:] - rest[:, :-2], axis=2) / (seg[:, :-1] + seg[:, 1:])
    assert ratio.min() < 0.6                     # the groom has strongly bent strands
    t0 = 10**9
    for k in range(31):                          # 3 s more with the head still
        sim.push_pose(t0 + k * 100_000_000, [0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0])
        sim.advance_to(t0 + k * 100_000_000)
    before = sim.frame(head_frame=True).guides
    sim.push_pose(t0 + 3_100_000_000, [0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0])
    sim.advance_to(t0 + 3_100_000_000)
    moved = np.linalg.norm(sim.frame(head_frame=True).guides - before, axis=2)
    assert moved.max() < 1e-4
