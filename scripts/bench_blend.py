"""Speed of the ghost trackers: the blend and turn trackers against the paper's tracker, against
the copy bandwidth of this machine measured in the same run.

For each ghost count (16 nodes a strand, one guide per 16 ghosts, the default scene otherwise),
the blend tracker's frame (blend + FTL pass + head contacts), the turn tracker's frame (the
guides' turns, the turned segments, head contacts) and one step of the paper tracker, each with
the read of the positions that a frame makes, are timed in turns, after a warm-up that compiles
them; medians of the rounds. The bandwidth is a numpy copy of a 64 MB float64 array (read +
write counted). The blend kernel reads the float32 rest offsets and lengths (16 B a node) and
writes float32 positions (12 B); the turn kernel reads float32 rest segments (12 B) and float64
roots (3 B a node at 16 nodes) and writes the positions: a kernel's share of the bandwidth is
(bytes a node x nodes / time) / copy bandwidth.

    python scripts/bench_blend.py [--ghosts 10000 100000] [--threads 2] [--json out.json]
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

from hair_tracking.core.scene import Scene  # noqa: E402
from hair_tracking.evaluation.provenance import command_line, provenance  # noqa: E402
from hair_tracking.ghosts.interface import TrackStep  # noqa: E402
from hair_tracking.simulator import HairSimulator  # noqa: E402

BYTES_PER_NODE = {'blend': 16 + 12, 'turn': 12 + 3 + 12}


def copy_bandwidth(rounds=7):
    a = np.ones(8 << 20)
    b = np.empty_like(a)
    times = []
    for _ in range(rounds):
        t = time.perf_counter()
        np.copyto(b, a)
        times.append(time.perf_counter() - t)
    return 2 * a.nbytes / statistics.median(times)


def moved(sim, k):
    q = [0.0, 0.0, np.sin(0.15 * np.sin(0.3 * k)), np.cos(0.15 * np.sin(0.3 * k))]
    t = 1_000_000_000 + k * 16_666_667
    sim.push_pose(t, [0.02 * np.sin(0.2 * k), 0.0, 0.0], q)
    sim.advance_to(t)
    return sim


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--ghosts', type=int, nargs='+', default=[10000, 100000])
    ap.add_argument('--threads', type=int, default=numba.config.NUMBA_NUM_THREADS)
    ap.add_argument('--rounds', type=int, default=15)
    ap.add_argument('--json')
    args = ap.parse_args(argv)
    numba.set_num_threads(args.threads)
    bw = copy_bandwidth()
    print(f'copy bandwidth {bw / 1e9:.1f} GB/s; {args.threads} thread(s)')
    results = []
    for ghosts in args.ghosts:
        guides = max(1, ghosts // 16)
        base = Scene().with_changes(groom__guides=guides, groom__ghosts_per_guide=16,
                                    solver__settle_time=0.0)
        sims = {mode: moved(HairSimulator(base.with_changes(tracking__mode=mode)), 1)
                for mode in ('blend', 'turn', 'paper')}
        for k in range(2, 5):
            for sim in sims.values():
                moved(sim, k)
        times = {name: [] for name in sims}
        for r in range(args.rounds):
            for name, sim in sims.items():
                tr, head = sim.ghost_tracker, sim.head
                gx_old = sim.guides.x.copy()
                t = time.perf_counter()
                tr.step(TrackStep(sim.scene.solver.dt, 1, gx_old, sim.guides.x, head))
                tr.positions()
                times[name].append(time.perf_counter() - t)
        nodes = sims['blend'].ghosts.count * sims['blend'].ghosts.rest.shape[1]
        row = {'ghosts': sims['blend'].ghosts.count, 'nodes': nodes, 'threads': args.threads,
               'copy_bandwidth_GBps': bw / 1e9}
        for name, ts in times.items():
            med = statistics.median(ts)
            row[name] = {'median_ms': med * 1e3, 'min_ms': min(ts) * 1e3,
                         'Mnodes_per_s': nodes / med / 1e6}
        for name, size in BYTES_PER_NODE.items():
            row[name]['bandwidth_share'] = size * nodes / statistics.median(times[name]) / bw
        results.append(row)
        b, t, p = row['blend'], row['turn'], row['paper']
        print(f"{row['ghosts']:>7} ghosts x 16: blend {b['median_ms']:.2f} ms "
              f"({b['Mnodes_per_s']:.0f} M nodes/s, {100 * b['bandwidth_share']:.0f} % of the "
              f"copy bandwidth); turn {t['median_ms']:.2f} ms ({t['Mnodes_per_s']:.0f} M "
              f"nodes/s, {100 * t['bandwidth_share']:.0f} %); paper tracker step "
              f"{p['median_ms']:.2f} ms ({p['Mnodes_per_s']:.0f} M nodes/s)", flush=True)
    if args.json:
        record = provenance(command_line('python scripts/bench_blend.py', argv), args.threads)
        with open(args.json, 'w', encoding='utf-8') as f:
            json.dump({'provenance': record, 'results': results}, f, indent=2)
    return 0


if __name__ == '__main__':
    sys.exit(main())
