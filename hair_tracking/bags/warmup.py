"""Compile a scene's kernels and message encoders ahead of time; ``hair_sim_warmup``.

numba compiles a kernel the first time it is called and keeps the machine code on disk
(``cache=True``), in a folder keyed by a hash of the package's sources
(:func:`hair_tracking.executable.numba_cache_dir`).  Without a filled cache the first start of
the node after an install or an edit spends its time compiling; ``make install`` runs
``hair_sim_warmup``, and so can a ROS user after ``colcon build``::

    ros2 run hair_tracking hair_sim_warmup                  # the default scene
    ros2 run hair_tracking hair_sim_warmup --scene long_hair --scene stiff_extreme
    ros2 run hair_tracking hair_sim_warmup --all-presets

:func:`warm_up` is what the node runs before it subscribes (a tiny copy of the scene through
every call the node makes, kernels and message encoders); the command runs it for each scene it
is given and prints where the cache is and how long each scene took.  Neither needs rclpy.
"""
import argparse
import glob
import os
import sys
import time
from typing import List, Optional

import numpy as np

from hair_tracking import executable
from hair_tracking.core.scene import Scene
from hair_tracking.core.param_table import MARKER_STYLES


def warm_up(scene: Scene, parallel=None) -> float:
    """Compile (or load from numba's on-disk cache) the kernels and encoders ``scene`` uses.

    Runs a tiny copy of the scene (same solver, collider, tracking and output options, few
    strands) through every call the node makes (:mod:`hair_tracking.ros.node`), so the first
    real frames are not late (``parallel``: the kernel variants of a simulator of ``scene``
    already built, :func:`hair_tracking.simulator.warm_up`).  Returns the seconds it took.
    """
    from msg_adapters.marker_cdr import strands_to_marker_array_cdr
    from msg_adapters.pointcloud import CloudBuffer, pack_rgb_u32

    from hair_tracking.simulator import warm_up as warm_up_simulator

    start = time.perf_counter()
    sim = warm_up_simulator(scene, parallel)
    for head_frame in (False, True):
        f = sim.frame(head_frame=head_frame, copy=False)
        for guides, strands in ((False, f.strands), (True, f.guides)):
            n_strands, n_points, write = sim.record_writer(guides, head_frame)
            CloudBuffer().encode(n_strands, n_points, write, frame_id='warmup', stamp_ns=1,
                                 packed_rgb=pack_rgb_u32(np.ones((n_strands, 4))))
            for style in MARKER_STYLES:
                strands_to_marker_array_cdr(strands, frame_id='warmup', style=style,
                                            delete_all_first=True)
    return time.perf_counter() - start


def preset_names() -> List[str]:
    """The scene presets shipped in config/ (``scene_<name>.yaml``)."""
    from hair_tracking.resources import config_dir
    return sorted(os.path.basename(p)[len('scene_'):-len('.yaml')]
                  for p in glob.glob(os.path.join(config_dir(), 'scene_*.yaml')))


def main(argv: Optional[List[str]] = None) -> int:
    """``hair_sim_warmup``: 0 when every scene is compiled (or a stop was asked for), 2 for a
    scene that cannot be read."""
    ap = argparse.ArgumentParser(
        prog='hair_sim_warmup',
        description="Compile every numba kernel a scene uses into numba's on-disk cache, so "
                    'the next hair_sim_node, hair_sim_bag run or hair_sim_demo starts in '
                    'seconds. Run it once after installing or editing the package.')
    ap.add_argument('--scene', action='append', default=[], metavar='NAME_OR_FILE',
                    help='a scene preset (e.g. long_hair) or scene YAML file; repeatable '
                         '(default: the default scene)')
    ap.add_argument('--all-presets', action='store_true',
                    help='also every scene preset in config/')
    args = ap.parse_args(argv)
    with executable.started() as stop:
        try:
            with stop.interruptible():       # compiling: plain Python and numba
                return _warm_up_scenes(args)
        except KeyboardInterrupt:
            print(f'hair_sim_warmup: stopped ({stop.signal_name or "interrupted"})',
                  file=sys.stderr)
            return 0


def _warm_up_scenes(args) -> int:
    from hair_tracking.bags.io import BagError
    from hair_tracking.bags.offline import load_settings

    names = list(args.scene) or ([] if args.all_presets else [''])
    if args.all_presets:
        names += [''] + preset_names()
    print(f'numba cache: {os.environ["NUMBA_CACHE_DIR"]}')
    total = time.perf_counter()
    for name in names:
        try:
            scene = load_settings(scene=name).scene if name else Scene()
        except BagError as e:
            print(f'hair_sim_warmup: error: {e}', file=sys.stderr)
            return 2
        secs = warm_up(scene)
        print(f'{name or "default scene"}: kernels and encoders ready in {secs:.1f} s',
              flush=True)
    print(f'groom files (import and groom.detail_nodes): ready in {warm_up_import():.1f} s',
          flush=True)
    print(f'done in {time.perf_counter() - total:.1f} s')
    return 0


def warm_up_import() -> float:
    """Compile (or load) the kernels of a groom file's import and of ``groom.detail_nodes`` on
    a tiny file of the procedural groom's strands, so the first ``groom.file`` does not wait
    for numba.  Returns the seconds it took."""
    import tempfile
    from dataclasses import replace
    from hair_tracking.core.groom import make_groom
    from hair_tracking.ghosts.detail import Detail
    from hair_tracking.grooms.build import build_groom
    from hair_tracking.grooms.writers import write_data

    t0 = time.perf_counter()
    spec = Scene().with_changes(groom__guides=4, groom__ghosts_per_guide=2).groom
    rest = make_groom(spec).ghost_rest
    with tempfile.TemporaryDirectory() as folder:
        path = os.path.join(folder, 'tiny.data')
        write_data(path, rest.reshape(-1, 3), np.full(rest.shape[0], rest.shape[1]))
        groom = build_groom(replace(spec, file=path, guides=2, detail_nodes=2 * spec.ghost_nodes),
                            cache=False)
    Detail(groom.ghost_rest, groom.detail_rest).carry(groom.ghost_rest, np.eye(3))
    return time.perf_counter() - t0


if __name__ == '__main__':
    sys.exit(main())
