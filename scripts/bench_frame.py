#!/usr/bin/env python3
"""Time of one output frame of the default scene at a large ghost count: the guides' substeps
for one head pose, the ghosts, and the PointCloud2 bytes of every ghost node.

    python scripts/bench_frame.py [--ghosts 100000] [--threads 2] [--frames 240] [--mode turn]
                                  [--volume] [--json F]

The default scene (blend tracker, or the tracker ``--mode``; FTL guides at its dt) with
``--ghosts`` strands of 16 nodes, one guide per 16 strands, follows the bundled walk recording
at 60 Hz (every second pose of the 120 Hz recording); each frame is ``push_pose`` +
``advance_to`` + the cloud written into a :class:`msg_adapters.pointcloud.CloudBuffer` as the
node does (``record_writer``). Kernels are compiled (or loaded) and the first 30 frames run
before timing. Prints the median, p95 and worst frame and the median of each part: the guide
substeps (``advance_to``) and the ghosts with the cloud's bytes (the blend or turn runs when
the cloud reads the ghosts).  ``--volume`` turns the hair-hair stage on (``volume.enabled``)
and also prints the stage's own time a frame (within the guide substeps) and its share of
each frame (median).
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
from hair_tracking.simulator import HairSimulator, warm_up  # noqa: E402
from msg_adapters.pointcloud import CloudBuffer, pack_rgb_u32  # noqa: E402

WARM_FRAMES = 30


class FrameClock:
    """One simulator following the bundled walk at 60 Hz, a frame at a time: :meth:`frame`
    runs frame ``k`` (``push_pose`` + ``advance_to`` + the cloud's bytes) and returns its times
    [ms]: ``frame``, ``guides``, ``ghosts_cloud`` (wall clock) and ``frame_cpu``, ``guides_cpu``,
    ``ghosts_cloud_cpu`` (CPU time of this process: on a shared machine, what the work costs
    whatever else runs)."""

    def __init__(self, sim):
        self.sim = sim
        poses = bag_io.read_head_poses(bag_io.bundled_bag())
        self.poses = poses
        self.idx = np.arange(0, len(poses), 2)
        self.cloud = CloudBuffer()
        self.rgb = pack_rgb_u32(np.ones((sim.ghosts.count, 4)))
        self.volume_ms = 0.0
        grid = sim.guide_solver.volume
        if grid is not None:                # the stage's own time, wherever in a frame it runs
            apply = grid.apply

            def timed(*args):
                t0 = time.perf_counter()
                apply(*args)
                self.volume_ms += (time.perf_counter() - t0) * 1e3
            grid.apply = timed

    def __len__(self):
        return len(self.idx)

    def frame(self, k):
        sim, poses, i = self.sim, self.poses, self.idx[k]
        t = int(poses.t_ns[i])
        self.volume_ms = 0.0
        c0 = time.process_time()
        t0 = time.perf_counter()
        sim.push_pose(t, poses.position[i], poses.quaternion[i])
        sim.advance_to(t)
        t1 = time.perf_counter()
        c1 = time.process_time()
        n_strands, n_points, write = sim.record_writer()
        msg = self.cloud.encode(n_strands, n_points, write, frame_id='world', stamp_ns=t,
                                packed_rgb=self.rgb)
        self.cloud_bytes = int(msg.nbytes)
        t2 = time.perf_counter()
        c2 = time.process_time()
        return {'frame_cpu': (c2 - c0) * 1e3, 'guides_cpu': (c1 - c0) * 1e3,
                'ghosts_cloud_cpu': (c2 - c1) * 1e3, 'guides': (t1 - t0) * 1e3,
                'ghosts_cloud': (t2 - t1) * 1e3, 'frame': (t2 - t0) * 1e3,
                'volume': self.volume_ms}


def frame_times(sim, frames, warm=WARM_FRAMES):
    """Per-frame times [ms] of ``sim`` following the bundled walk at 60 Hz for ``frames``
    frames after ``warm`` untimed ones: lists of :meth:`FrameClock.frame`'s times,
    ``substeps_per_frame`` and ``cloud_bytes`` (the size of one frame's cloud message)."""
    clock = FrameClock(sim)
    n_frames = min(frames + warm, len(clock))
    parts = {'guides': [], 'ghosts_cloud': [], 'frame': [], 'frame_cpu': [], 'guides_cpu': [],
             'ghosts_cloud_cpu': [], 'volume': []}
    for k in range(n_frames):
        times = clock.frame(k)
        if k >= warm:
            for key, value in times.items():
                parts[key].append(value)
    parts['substeps_per_frame'] = sim.counters.substeps / max(1, n_frames)
    parts['cloud_bytes'] = clock.cloud_bytes
    return parts


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--ghosts', type=int, default=100000)
    ap.add_argument('--threads', type=int, default=numba.config.NUMBA_NUM_THREADS)
    ap.add_argument('--frames', type=int, default=240)
    ap.add_argument('--mode', choices=['blend', 'turn', 'paper'], default=Scene().tracking.mode,
                    help='tracking.mode (default: the default scene\'s)')
    ap.add_argument('--volume', action='store_true', help='volume.enabled (the hair-hair stage)')
    ap.add_argument('--json')
    args = ap.parse_args(argv)
    numba.set_num_threads(args.threads)
    scene = Scene().with_changes(groom__guides=max(1, args.ghosts // 16),
                                 groom__ghosts_per_guide=16, tracking__mode=args.mode,
                                 volume__enabled=args.volume)
    warm_up(scene)
    sim = HairSimulator(scene)
    parts = frame_times(sim, args.frames)
    f = np.asarray(parts['frame'])
    row = {'mode': args.mode, 'volume': args.volume, 'ghosts': int(sim.ghosts.count),
           'guides': int(sim.guides.count),
           'threads': args.threads, 'frames': len(f), 'median_ms': float(np.median(f)),
           'p95_ms': float(np.percentile(f, 95)), 'max_ms': float(f.max()),
           'guides_median_ms': statistics.median(parts['guides']),
           'ghosts_cloud_median_ms': statistics.median(parts['ghosts_cloud']),
           'frame_cpu_median_ms': statistics.median(parts['frame_cpu']),
           'substeps_per_frame': parts['substeps_per_frame']}
    if args.volume:
        share = np.asarray(parts['volume']) / f
        row.update(volume_median_ms=statistics.median(parts['volume']),
                   volume_share_median=float(np.median(share)))
    print(f"{args.mode}: {row['ghosts']} ghosts x 16 ({row['guides']} guides), "
          f"{args.threads} thread(s), "
          f"{row['frames']} frames at 60 Hz: median {row['median_ms']:.2f} ms, p95 "
          f"{row['p95_ms']:.2f}, worst {row['max_ms']:.2f}, CPU median "
          f"{row['frame_cpu_median_ms']:.2f} (guide substeps "
          f"{row['guides_median_ms']:.2f}, ghosts + cloud bytes "
          f"{row['ghosts_cloud_median_ms']:.2f})")
    if args.volume:
        print(f"volume stage: median {row['volume_median_ms']:.2f} ms a frame, median share "
              f"of a frame {row['volume_share_median']:.1%}")
    if args.json:
        record = provenance(command_line('python scripts/bench_frame.py', argv), args.threads)
        with open(args.json, 'w', encoding='utf-8') as fh:
            json.dump({'provenance': record, **row}, fh, indent=2)
    return 0


if __name__ == '__main__':
    sys.exit(main())
