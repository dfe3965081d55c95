"""Offline demo: the hair on real recorded head motion (CMU 131_01 walk), numbers and a picture.

    python -m hair_tracking.evaluation.demo [--scene long_hair] [--out out/demo]

Runs the simulator frame by frame at the recording's own timestamps, prints the per-frame time
(compile time kept out: the kernels are warmed up first), the worst stretch and head penetration,
and writes ``hair.png`` with the hair at several moments.
"""
import argparse
import os
import sys
import time

import numpy as np

from hair_tracking.core.scene import Scene, SceneError
from hair_tracking.motion.pose_table import load_bundled_walk
from hair_tracking.resources import config_path
from hair_tracking.simulator import HairSimulator, warm_up as warm_up_simulator


def run(scene: Scene, motion, keep_every: int = 0):
    """Simulate ``motion`` frame by frame; returns (per-frame ms, stretch, penetration, snaps)."""
    sim = HairSimulator(scene)
    ms, stretch, depth, snaps = [], [], [], []
    for i, (t, p, q) in enumerate(zip(motion.t_ns, motion.position, motion.quaternion)):
        start = time.perf_counter()
        sim.push_pose(int(t), p, q)
        sim.advance_to(int(t))
        sim.frame(copy=False)
        ms.append((time.perf_counter() - start) * 1e3)
        stretch.append(sim.max_stretch())
        depth.append(sim.penetration())
        if keep_every and i % keep_every == 0:
            f = sim.frame(head_frame=False)
            snaps.append((t * 1e-9, f.head, f.strands.copy()))
    return sim, np.array(ms), np.array(stretch), np.array(depth), snaps


def warm_up(scene: Scene) -> float:
    """Compile (or load from the on-disk cache) every kernel the scene uses; returns seconds."""
    start = time.perf_counter()
    warm_up_simulator(scene)
    return time.perf_counter() - start


def plot(snaps, path: str, scene: Scene, max_strands: int = 400) -> None:
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    n = len(snaps)
    fig, axes = plt.subplots(2, n, figsize=(3.2 * n, 6.4), squeeze=False)
    for j, (t, head, strands) in enumerate(snaps):
        pick = strands[:: max(1, len(strands) // max_strands)]
        local = head.to_head(pick)          # show the hair around the head, head frame
        for row, (a, b, name) in enumerate(((0, 2, 'side (x forward)'), (1, 2, 'back (y left)'))):
            ax = axes[row, j]
            seg = local[:, :, [a, b]]
            for s in seg:
                ax.plot(s[:, 0], s[:, 1], lw=0.4, color='saddlebrown', alpha=0.6)
            radii = np.asarray(scene.collider.radii if scene.collider.shape == 'ellipsoid'
                               else (scene.collider.radius,) * 3)
            th = np.linspace(0, 2 * np.pi, 100)
            ax.plot(radii[a] * np.cos(th), radii[b] * np.sin(th), color='k', lw=1)
            ax.set_aspect('equal')
            ax.set_xlim(-0.5, 0.5)
            ax.set_ylim(-0.6, 0.25)
            ax.set_title(f't = {t:.2f} s, {name}', fontsize=8)
            ax.tick_params(labelsize=6)
    fig.suptitle('hair_tracking on CMU 131_01 walk (head frame)')
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--scene', default='default', help='scene preset name or YAML path')
    ap.add_argument('--out', default='out/demo', help='output folder for hair.png')
    args = ap.parse_args(argv)
    try:
        scene = Scene.from_yaml(config_path(args.scene))
    except (SceneError, FileNotFoundError) as e:
        print(f'error: {e}', file=sys.stderr)
        return 2
    motion = load_bundled_walk()
    os.makedirs(args.out, exist_ok=True)
    compile_s = warm_up(scene)
    frames = len(motion.t_ns)
    keep = max(1, frames // 5)
    sim, ms, stretch, depth, snaps = run(scene, motion, keep_every=keep)
    duration = (motion.t_ns[-1] - motion.t_ns[0]) * 1e-9
    g, s = sim.guides, sim.ghosts
    print(f'scene: {args.scene}: {g.count} guides x {g.nodes} nodes, '
          f'{0 if s is None else s.count} ghosts x {0 if s is None else s.nodes} nodes, '
          f'solver {scene.solver.type}, dt {scene.solver.dt * 1e3:.2f} ms')
    print(f'head motion: CMU 131_01 walk, {frames} frames, {duration:.2f} s')
    print(f'kernel warm-up (compile or cache load): {compile_s:.2f} s')
    print(f'per frame: median {np.median(ms):.3f} ms, p95 {np.percentile(ms, 95):.3f} ms, '
          f'max {ms.max():.3f} ms; real-time factor {duration / (ms.sum() * 1e-3):.1f}x')
    print(f'substeps: {sim.counters.substeps} run, {sim.counters.substeps_dropped} dropped; '
          f'poses rejected {sim.track.counters["rejected"]}, resets {sim.counters.resets}')
    print(f'max stretch: median {np.median(stretch) * 100:.4f} %, '
          f'worst {stretch.max() * 100:.4f} %')
    print(f'head penetration: worst {depth.max() * 1e3:.3f} mm '
          f'(collider margin {scene.collider.margin * 1e3:.1f} mm)')
    png = os.path.join(args.out, 'hair.png')
    plot(snaps, png, scene)
    print(f'picture: {png}')
    bad = not np.all(np.isfinite(sim.frame().strands))
    return 1 if bad else 0


if __name__ == '__main__':
    sys.exit(main())
