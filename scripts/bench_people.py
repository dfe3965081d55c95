#!/usr/bin/env python3
"""Time of one output frame with 1, 2, 4 and 8 people, each with their own hair of
``--ghosts`` ghosts, in one crowd (``people.source: hri``'s core, without ROS), against one
person.

    python scripts/bench_people.py [--ghosts 10000] [--people 1 2 4 8] [--threads 2]
                                   [--frames 240] [--json F]

Each person wears the default scene's hair (blend tracker, FTL guides, ``--ghosts`` strands of
16 nodes, one guide per 16 strands) and follows the bundled walk at 60 Hz, person ``i`` from
pose ``37 i`` on and ``0.6 i`` m to the side.  A frame is every person's ``push_pose``, one
:meth:`~hair_tracking.people.crowd.Crowd.advance_to` (all the people's guides in one call), and
every person's cloud written into a :class:`msg_adapters.pointcloud.CloudBuffer` of its own as the
node does.  For comparison the same people as separate simulators, stepped one after another
(``loop``: one guide solver call a person).  Kernels are compiled (or loaded) and the first 30
frames run before timing.  Prints, per people count, the median frame, its guide and cloud
parts, the frame's ratio to one person's and the guide part of the loop.
"""
import argparse
import json
import os
import statistics
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from hair_tracking.executable import use_numba_cache  # noqa: E402
use_numba_cache()      # before numba loads: the cache make install fills
import numba  # noqa: E402
import numpy as np  # noqa: E402

from hair_tracking.bags import io as bag_io  # noqa: E402
from hair_tracking.core.scene import Scene  # noqa: E402
from hair_tracking.evaluation.provenance import command_line, provenance  # noqa: E402
from hair_tracking.people import crowd as crowd_module  # noqa: E402
from hair_tracking.simulator import HairSimulator, warm_up  # noqa: E402
from msg_adapters.pointcloud import CloudBuffer, pack_rgb_u32  # noqa: E402

WARM_FRAMES = 30
SHIFT = 37          # poses between two people's walks
SIDE = 0.6          # metres between two people


def walk():
    """The bundled walk at 60 Hz: ``(t_ns, position, quaternion)`` arrays."""
    poses = bag_io.read_head_poses(bag_io.bundled_bag())
    idx = np.arange(0, len(poses), 2)
    return poses.t_ns[idx], poses.position[idx], poses.quaternion[idx]


def person_pose(poses, k, i):
    t, p, q = poses
    j = (k + SHIFT * i) % len(t)
    return p[j] + [SIDE * i, 0.0, 0.0], q[j]


def crowd_frames(scene, people, frames, poses):
    """Per-frame times [ms] of ``people`` in one crowd: ``{'guides', 'clouds', 'frame'}``."""
    crowd = crowd_module.Crowd(scene, people)
    t_ns = poses[0]
    for i in range(people):
        crowd.add(str(i), int(t_ns[0]), *person_pose(poses, 0, i))
    clouds = [CloudBuffer() for _ in range(people)]
    rgb = pack_rgb_u32(np.ones((crowd.people['0'].ghosts.count, 4)))
    out = {'guides': [], 'clouds': [], 'frame': []}
    for k in range(1, min(frames + WARM_FRAMES, len(t_ns))):
        t = int(t_ns[k])
        t0 = time.perf_counter()
        for i in range(people):
            crowd.push_pose(str(i), t, *person_pose(poses, k, i))
        crowd.advance_to(t)
        t1 = time.perf_counter()
        for i in range(people):
            n_strands, n_points, write = crowd.people[str(i)].record_writer()
            clouds[i].encode(n_strands, n_points, write, frame_id='world', stamp_ns=t,
                             packed_rgb=rgb)
        t2 = time.perf_counter()
        if k > WARM_FRAMES:
            out['guides'].append((t1 - t0) * 1e3)
            out['clouds'].append((t2 - t1) * 1e3)
            out['frame'].append((t2 - t0) * 1e3)
    return out


def loop_guides(scene, people, frames, poses):
    """Per-frame times [ms] of the same people as separate simulators, one after another
    (push_pose and advance_to only)."""
    sims = [HairSimulator(scene) for _ in range(people)]
    t_ns = poses[0]
    out = []
    for k in range(0, min(frames + WARM_FRAMES, len(t_ns))):
        t = int(t_ns[k])
        t0 = time.perf_counter()
        for i, sim in enumerate(sims):
            sim.push_pose(t, *person_pose(poses, k, i))
            sim.advance_to(t)
        if k > WARM_FRAMES:
            out.append((time.perf_counter() - t0) * 1e3)
    return out


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--ghosts', type=int, default=10000)
    ap.add_argument('--people', type=int, nargs='+', default=[1, 2, 4, 8])
    ap.add_argument('--threads', type=int, default=numba.config.NUMBA_NUM_THREADS)
    ap.add_argument('--frames', type=int, default=240)
    ap.add_argument('--json')
    args = ap.parse_args(argv)
    numba.set_num_threads(args.threads)
    scene = Scene().with_changes(groom__guides=max(1, args.ghosts // 16),
                                 groom__ghosts_per_guide=16)
    warm_up(scene)
    poses = walk()
    rows = []
    for n in args.people:
        crowd_module.warm_up(scene, crowd_module.Crowd(scene, n).parallel)
        parts = crowd_frames(scene, n, args.frames, poses)
        loop = loop_guides(scene, n, args.frames, poses)
        row = {'people': n, 'frames': len(parts['frame']),
               'frame_median_ms': statistics.median(parts['frame']),
               'frame_p95_ms': float(np.percentile(parts['frame'], 95)),
               'guides_median_ms': statistics.median(parts['guides']),
               'clouds_median_ms': statistics.median(parts['clouds']),
               'loop_guides_median_ms': statistics.median(loop)}
        rows.append(row)
    one = next((r for r in rows if r['people'] == 1), rows[0])
    for r in rows:
        r['frame_ratio_to_one'] = r['frame_median_ms'] / one['frame_median_ms']
        r['guides_ratio_to_loop'] = r['guides_median_ms'] / r['loop_guides_median_ms']
        print(f"{r['people']} people x {args.ghosts} ghosts, {args.threads} thread(s): frame "
              f"median {r['frame_median_ms']:.2f} ms (p95 {r['frame_p95_ms']:.2f}; "
              f"{r['frame_ratio_to_one']:.2f}x one person): guides "
              f"{r['guides_median_ms']:.2f}, clouds {r['clouds_median_ms']:.2f}; guides one "
              f"simulator a person {r['loop_guides_median_ms']:.2f} "
              f"(batched / loop {r['guides_ratio_to_loop']:.2f})", flush=True)
    if args.json:
        record = provenance(command_line('python scripts/bench_people.py', argv), args.threads)
        with open(args.json, 'w', encoding='utf-8') as fh:
            json.dump({'provenance': record, 'ghosts_per_person': args.ghosts, 'rows': rows},
                      fh, indent=2)
    return 0


if __name__ == '__main__':
    sys.exit(main())
