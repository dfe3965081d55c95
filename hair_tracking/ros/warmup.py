"""``hair_sim_warmup``: fill numba's on-disk cache with every kernel a scene uses.

numba compiles a kernel the first time it is called and keeps the machine code on disk
(``cache=True``), in a folder keyed by a hash of the package's sources
(:func:`hair_tracking.numba_cache_dir`).  Without a filled cache the first start of the node after
an install or an edit spends its time compiling; ``make install`` runs this command, and so can a
ROS user after ``colcon build``::

    ros2 run hair_tracking hair_sim_warmup                  # the default scene
    ros2 run hair_tracking hair_sim_warmup --scene long_hair --scene stiff_extreme
    ros2 run hair_tracking hair_sim_warmup --all-presets

It runs the node's own warm-up (:func:`hair_tracking.ros.node.warm_up`: a tiny copy of each scene
through every call the node makes, kernels and message encoders) and prints where the cache is
and how long each scene took.
"""
import argparse
import glob
import os
import sys
import time
from typing import List, Optional


def preset_names() -> List[str]:
    """The scene presets shipped in config/ (``scene_<name>.yaml``)."""
    from hair_tracking.resources import config_dir
    return sorted(os.path.basename(p)[len('scene_'):-len('.yaml')]
                  for p in glob.glob(os.path.join(config_dir(), 'scene_*.yaml')))


def main(argv: Optional[List[str]] = None) -> int:
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

    import hair_tracking
    from hair_tracking.core.scene import Scene, SceneError
    from hair_tracking.ros.node import load_base_scene, warm_up

    names = list(args.scene) or ([] if args.all_presets else [''])
    if args.all_presets:
        names += [''] + preset_names()
    print(f'numba cache: {os.environ.get("NUMBA_CACHE_DIR") or hair_tracking.numba_cache_dir()}')
    total = time.perf_counter()
    for name in names:
        try:
            scene = load_base_scene(name) if name else Scene()
        except SceneError as e:
            print(f'hair_sim_warmup: error: {e}', file=sys.stderr)
            return 2
        secs = warm_up(scene)
        print(f'{name or "default scene"}: kernels and encoders ready in {secs:.1f} s',
              flush=True)
    print(f'done in {time.perf_counter() - total:.1f} s')
    return 0


if __name__ == '__main__':
    sys.exit(main())
