"""Every scene preset in config/ holds the package's own criteria, and ``default`` is the
defaults.

The presets are found by glob, so a new ``config/scene_<name>.yaml`` is tested without a change
here.  Each one must

* start with no root inside its collider: the attached nodes of every guide and ghost (their
  rest shapes, head frame) are measured with the collider's own
  :meth:`~hair_tracking.colliders.head.Collider.penetration`, and the hair the simulator
  starts with (settled) has no node deeper in it than the collider margin;
* pass the stability matrix's criteria (:func:`hair_tracking.evaluation.stability.run_case`:
  finite, guide and ghost stretch within ``STRETCH_BOUND`` / ``GHOST_STRETCH_BOUND``, roots
  attached, penetration within the margin, bounded energy, no energy gained over a still tail)
  on 2.5 s of the bundled walk, the part with the bend down (1.5-4 s), then a still head.

The walk runs with at most :data:`GHOSTS_PER_GUIDE` ghosts per guide, to keep the test at a few
seconds a preset.  The guides, which the solver settings act on, are the preset's own (count,
nodes, length, solver, collider); each ghost is placed from the guides and its own rest shape
(the blend and turn trackers; the paper's tracker from its guide's group), so its stretch and
penetration are figures of that strand, which a sample of the ghosts tests as a full head
would.
"""
import glob
import os

import numpy as np
import pytest

from hair_tracking.bags import io as bag_io
from hair_tracking.bags.offline import load_settings, run_bag, RunOptions
from hair_tracking.core.head_track import IDENTITY
from hair_tracking.core.scene import Scene
from hair_tracking.evaluation import stability
from hair_tracking.evaluation import synthetic_motion as sm
from hair_tracking.motion.pose_table import load_bundled_walk
from hair_tracking.ros.parameters import load_base_scene
from hair_tracking.simulator import HairSimulator

from recordings import write_walk_bag

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PRESETS = sorted(glob.glob(os.path.join(ROOT, 'config', 'scene_*.yaml')))
#: Ghosts per guide on the walk (see the module docstring).
GHOSTS_PER_GUIDE = 2
#: A point on the collider's surface, rounded to float64, lies this far inside at most [m].
ROUNDING_M = 1e-12


def _name(path):
    return os.path.basename(path)[len('scene_'):-len('.yaml')]


def test_every_preset_is_found():
    assert {'default', 'long_hair', 'short_hair', 'stiff_extreme'} <= set(map(_name, PRESETS))


@pytest.mark.parametrize('path', PRESETS, ids=_name)
def test_no_root_starts_inside_the_collider(path):
    scene = Scene.from_yaml(path)
    sim = HairSimulator(scene)
    if sim.colliders.head is None:
        pytest.skip('no collider')
    for part, strands in (('guides', sim.guides), ('ghosts', sim.ghosts)):
        if strands is None:
            continue
        attached = np.ascontiguousarray(strands.rest[:, :2])
        depth = sim.colliders.head.penetration(attached, IDENTITY)
        assert depth <= ROUNDING_M, \
            f'{_name(path)}: {part} roots start {depth * 1e3:.2f} mm inside the collider'
    depth = sim.penetration()
    assert depth <= scene.collider.margin, \
        f'{_name(path)}: the settled hair is {depth * 1e3:.2f} mm inside the collider'


@pytest.mark.parametrize('path', PRESETS, ids=_name)
def test_preset_passes_the_stability_criteria_on_the_walk(path):
    scene = Scene.from_yaml(path)
    scene = scene.with_changes(groom__ghosts_per_guide=min(scene.groom.ghosts_per_guide,
                                                           GHOSTS_PER_GUIDE))
    walk = load_bundled_walk()
    case = stability.Case(_name(path), 'preset', scene, lambda: sm.window(walk, 1.5, 2.5),
                          'the bundled walk, 1.5-4 s')
    result = stability.run_case(case)
    assert result.passed, f'{_name(path)}: ' + '; '.join(result.failures)


def test_the_default_preset_gives_the_same_hair_as_no_scene(tmp_path):
    assert load_base_scene('default') == load_base_scene('') == Scene()
    src = write_walk_bag(tmp_path / 'walk.mcap', 0.3)
    clouds = []
    for scene in ('default', None):           # hair_sim_bag run --scene default / no --scene
        out = tmp_path / f'{scene}.mcap'
        run_bag(str(src), str(out), load_settings(scene),
                RunOptions(markers=False, diagnostics=False, head_pose=False))
        clouds.append([(t, bytes(msg.data)) for t, msg in bag_io.cloud_messages(out)])
    assert clouds[0] and clouds[0] == clouds[1]


def test_the_stiff_preset_is_stiff_on_the_walk():
    """scene_stiff_extreme (XPBD, rigid, 10 g): every guide and ghost segment within 1 % of its
    rest length over the first 2 s of the bundled walk (checked at every pose)."""
    scene = Scene.from_yaml(os.path.join(ROOT, 'config', 'scene_stiff_extreme.yaml'))
    sim = HairSimulator(scene.with_changes(groom__ghosts_per_guide=GHOSTS_PER_GUIDE))
    walk = load_bundled_walk()
    worst, poses = 0.0, 0
    for t, p, q in zip(walk.t_ns, walk.position, walk.quaternion):
        if t - walk.t_ns[0] > 2_000_000_000:
            break
        sim.push_pose(int(t), p, q)
        sim.advance_to(int(t))
        worst = max(worst, sim.max_stretch())
        poses += 1
    assert poses > 100 and worst <= 0.01, worst
