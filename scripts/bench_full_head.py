#!/usr/bin/env python3
"""A full head from a groom file: setup, frame time and the cloud's bytes per second at 10 k
and 100 k strands.

    python scripts/bench_full_head.py [--strands 10000 100000] [--vertices 100] [--frames 60]
                                      [--detail-nodes D] [--threads 2] [--json F]

For each strand count a synthetic groom of ``--vertices`` vertices a strand is written as a
USC-HairSalon ``.data`` file (``scripts/make_groom_file.py``, into a temporary folder) and the
default scene with ``groom.file`` set to it is built twice: the first build reads, places and
chooses guides (and stores the result in the groom cache), the second loads it from the
cache.  The second simulator then follows the bundled walk at 60 Hz as
``scripts/bench_frame.py`` times it (push_pose, advance_to, the cloud of every strand).  Prints
the setup times, the median frame and its parts, the cloud's bytes a frame and the bytes a
second at 30 Hz, the same of the cloud as the node sends it with the default settings
(``cloud_max_strands``) and the time to write it, and the process's peak resident memory.
``--detail-nodes`` sets ``groom.detail_nodes``: the output strands are then the file's shape at
that many points, carried by the ghosts (:mod:`hair_tracking.ghosts.detail`).
(``scripts/bench_groom.py`` compares the default frame on an imported groom with the frame on a
procedural groom of the same counts.)
"""
import argparse
import json
import os
import resource
import statistics
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.dirname(HERE))
sys.path.insert(0, HERE)

from hair_tracking.executable import use_numba_cache  # noqa: E402
use_numba_cache()      # before numba loads: the cache make install fills
import numba  # noqa: E402
import numpy as np  # noqa: E402

import bench_frame  # noqa: E402
import make_groom_file  # noqa: E402
from hair_tracking.core.scene import Scene  # noqa: E402
from hair_tracking.evaluation.provenance import command_line, provenance  # noqa: E402
from hair_tracking.output.frame_encoder import FrameEncoder  # noqa: E402
from hair_tracking.output.settings import make_settings  # noqa: E402
from hair_tracking.simulator import HairSimulator, warm_up  # noqa: E402

#: The cloud's rate [Hz] the bytes a second are given at (the node's default output rate).
CLOUD_HZ = 30.0
#: Clouds written as the node writes them (default settings: ``cloud_max_strands``), timed.
NODE_CLOUDS = 10


def one(strands: int, vertices: int, frames: int, folder: str, detail: int = 0) -> dict:
    """The figures of one strand count (module docstring)."""
    path = os.path.join(folder, f'groom_{strands}.data')
    if not os.path.exists(path):
        make_groom_file.main([path, '--strands', str(strands), '--vertices', str(vertices)])
    scene = Scene().with_changes(groom__file=path, groom__detail_nodes=detail)
    t0 = time.perf_counter()
    first = HairSimulator(scene)
    t1 = time.perf_counter()
    del first
    t2 = time.perf_counter()
    sim = HairSimulator(scene)
    t3 = time.perf_counter()
    warm_up(scene, sim.parallel)
    parts = bench_frame.frame_times(sim, frames)
    f = np.asarray(parts['frame'])
    encoder = FrameEncoder(make_settings({}))       # the node's cloud: cloud_max_strands
    node_ms = []
    for _ in range(NODE_CLOUDS):
        c0 = time.perf_counter()
        node_bytes = int(encoder.frame(sim, ['points'], 'world', 1)['points'].data.nbytes)
        node_ms.append((time.perf_counter() - c0) * 1e3)
    return {'strands': strands, 'vertices': vertices, 'ghosts': int(sim.ghosts.count),
            'ghost_nodes': int(sim.ghosts.nodes), 'detail_nodes': detail,
            'guides': int(sim.guides.count),
            'guide_nodes': int(sim.guides.nodes), 'file_bytes': os.path.getsize(path),
            'setup_first_s': t1 - t0, 'setup_cached_s': t3 - t2, 'frames': len(f),
            'frame_median_ms': float(np.median(f)), 'frame_p95_ms': float(np.percentile(f, 95)),
            'guides_median_ms': statistics.median(parts['guides']),
            'ghosts_cloud_median_ms': statistics.median(parts['ghosts_cloud']),
            'cloud_bytes': parts['cloud_bytes'],
            'cloud_mb_per_s': parts['cloud_bytes'] * CLOUD_HZ / 1e6,
            'node_cloud_strands': min(strands, encoder.settings.cloud_max_strands or strands),
            'node_cloud_bytes': node_bytes, 'node_cloud_median_ms': statistics.median(node_ms),
            'node_cloud_mb_per_s': node_bytes * CLOUD_HZ / 1e6}


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--strands', type=int, nargs='+', default=[10000, 100000])
    ap.add_argument('--vertices', type=int, default=100)
    ap.add_argument('--frames', type=int, default=60)
    ap.add_argument('--detail-nodes', type=int, default=0,
                    help='groom.detail_nodes (0: the ghosts are the output)')
    ap.add_argument('--threads', type=int, default=numba.config.NUMBA_NUM_THREADS)
    ap.add_argument('--json')
    args = ap.parse_args(argv)
    numba.set_num_threads(args.threads)
    rows = []
    with tempfile.TemporaryDirectory() as folder:
        for n in args.strands:
            row = one(n, args.vertices, args.frames, folder, args.detail_nodes)
            rows.append(row)
            print(f"{n} strands x {args.vertices} vertices ({row['file_bytes'] / 1e6:.0f} MB): "
                  f"setup {row['setup_first_s']:.1f} s, from the cache "
                  f"{row['setup_cached_s']:.2f} s; simulated {row['guides']} guides x "
                  f"{row['guide_nodes']}, {row['ghosts']} ghosts x {row['ghost_nodes']}"
                  + (f" shown at {args.detail_nodes} points" if args.detail_nodes else '') +
                  f"; "
                  f"frame median {row['frame_median_ms']:.1f} ms (guides "
                  f"{row['guides_median_ms']:.1f}, ghosts + cloud "
                  f"{row['ghosts_cloud_median_ms']:.1f}); cloud {row['cloud_bytes'] / 1e6:.1f} "
                  f"MB a frame, {row['cloud_mb_per_s']:.0f} MB/s at {CLOUD_HZ:g} Hz; the node's "
                  f"cloud (cloud_max_strands: {row['node_cloud_strands']} strands) "
                  f"{row['node_cloud_bytes'] / 1e6:.1f} MB, {row['node_cloud_mb_per_s']:.0f} "
                  f"MB/s, written in {row['node_cloud_median_ms']:.1f} ms", flush=True)
    peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    print(f'peak resident memory {peak_mb:.0f} MB ({args.threads} thread(s))')
    if args.json:
        record = provenance(command_line('python scripts/bench_full_head.py', argv), args.threads)
        with open(args.json, 'w', encoding='utf-8') as fh:
            json.dump({'provenance': record, 'rows': rows, 'peak_rss_mb': peak_mb}, fh,
                      indent=2)
    return 0


if __name__ == '__main__':
    sys.exit(main())
