#!/usr/bin/env python3
"""Loading an imported groom, and the default frame on it against a procedural groom of the
same counts.

    python scripts/bench_groom.py [--strands 10000] [--vertices 100] [--repeats 5]
                                  [--frames 120] [--threads N] [--json F]

Writes a USC-HairSalon ``.data`` file of ``--strands`` strands of about ``--vertices``
vertices (scripts/make_groom_file.py: the tests' synthetic groom, in centimetres, y up) into a
temporary folder, then:

* **load**: the median (wall clock and CPU time) of ``--repeats`` reads of the file alone
  (:func:`~hair_tracking.grooms.formats.read_strands`), of imports onto the head
  (:func:`~hair_tracking.grooms.build.import_groom`: read, resample, fit) and of whole grooms
  (:func:`~hair_tracking.grooms.build.build_groom`: the import and the guides' choice);
* **frame**: the default scene (blend tracker, FTL guides, one guide per 16 strands, 16 nodes)
  on the imported groom and on a procedural groom of the same strand and node counts, each
  following the bundled walk at 60 Hz as scripts/bench_frame.py does (push_pose, advance_to,
  the cloud's bytes), ``--repeats`` times, the two side by side a frame at a time (each first in
  turn), so that load on a shared machine falls on both alike; the median over all frames of
  each frame's CPU time on the imported groom over the same frame's on the procedural one
  (``paired_ratio_cpu``, with its quartiles), the median over the runs of each run's median
  frame (wall clock and CPU time) and their ratio, the same for the frame's two parts (CPU
  time: the guide substeps, ``advance_to``; the ghosts with the cloud's bytes) and the guides'
  head contacts a substep; then the same without the head collider (``collider.shape: none``),
  where the two grooms differ only in their shapes' lengths.
"""
import argparse
import json
import os
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)
sys.path.insert(0, os.path.join(ROOT, 'scripts'))

from hair_tracking.executable import use_numba_cache  # noqa: E402
use_numba_cache()      # before numba loads: the cache make install fills
import numba  # noqa: E402
import numpy as np  # noqa: E402

from bench_frame import FrameClock, WARM_FRAMES  # noqa: E402
import make_groom_file  # noqa: E402
from hair_tracking.core.scene import Scene  # noqa: E402
from hair_tracking.evaluation.provenance import command_line, provenance  # noqa: E402
from hair_tracking.grooms.build import build_groom, import_groom  # noqa: E402
from hair_tracking.grooms.formats import read_strands  # noqa: E402
from hair_tracking.simulator import HairSimulator, warm_up  # noqa: E402

#: The parts of a frame timed on their own (:meth:`bench_frame.FrameClock.frame`): the guide
#: substeps and the ghosts with the cloud's bytes.
PARTS = ('guides', 'ghosts_cloud')


def median_seconds(fn, repeats):
    """Medians of the wall-clock and the CPU seconds (this process) of ``repeats`` calls (on a
    shared machine the CPU time is what the work itself costs)."""
    wall, cpu = [], []
    for _ in range(repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        fn()
        wall.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    return float(np.median(wall)), float(np.median(cpu))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--strands', type=int, default=10_000)
    ap.add_argument('--vertices', type=int, default=100)
    ap.add_argument('--repeats', type=int, default=5)
    ap.add_argument('--frames', type=int, default=120)
    ap.add_argument('--threads', type=int, default=numba.config.NUMBA_NUM_THREADS)
    ap.add_argument('--json')
    args = ap.parse_args(argv)
    numba.set_num_threads(args.threads)
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, 'groom.data')
        make_groom_file.main([path, '--strands', str(args.strands), '--vertices',
                              str(args.vertices)])
        size_mb = os.path.getsize(path) / 1e6
        guides = max(1, args.strands // 16)
        imported = Scene().with_changes(groom__file=path, groom__guides=guides)
        procedural = Scene().with_changes(groom__guides=guides, groom__ghosts_per_guide=16)
        load = {}
        for name, fn in (('read_s', lambda: read_strands(path)),
                         ('import_s', lambda: import_groom(imported.groom)),
                         ('build_s', lambda: build_groom(imported.groom, cache=False))):
            load[name], load[name.replace('_s', '_cpu_s')] = median_seconds(fn, args.repeats)
            print(f'{name[:-2]:7s} {args.strands} x {args.vertices} ({size_mb:.1f} MB): median '
                  f'{load[name]:.3f} s wall, {load[name.replace("_s", "_cpu_s")]:.3f} s CPU',
                  flush=True)
        frame = {}
        for collider in ('ellipsoid', 'none'):
            scenes = {'procedural': procedural.with_changes(collider__shape=collider),
                      'imported': imported.with_changes(collider__shape=collider)}
            for scene in scenes.values():
                warm_up(scene)
            wall = {name: [] for name in scenes}
            cpu = {name: [] for name in scenes}
            part_cpu = {part: {name: [] for name in scenes} for part in PARTS}
            pair_ratio = []
            contacts = {}
            for r in range(args.repeats):
                clocks = {name: FrameClock(HairSimulator(scene))
                          for name, scene in scenes.items()}
                names = list(clocks)
                n_frames = min(args.frames + WARM_FRAMES, min(len(c) for c in clocks.values()))
                times = {name: [] for name in names}
                for k in range(n_frames):
                    for name in (names if k % 2 else names[::-1]):    # each first in turn
                        t = clocks[name].frame(k)
                        if k >= WARM_FRAMES:
                            times[name].append(t)
                for name in names:
                    wall[name].append(float(np.median([t['frame'] for t in times[name]])))
                    cpu[name].append(float(np.median([t['frame_cpu'] for t in times[name]])))
                    for part in PARTS:
                        part_cpu[part][name].append(
                            float(np.median([t[part + '_cpu'] for t in times[name]])))
                    stats = clocks[name].sim.guide_solver.stats
                    contacts[name] = stats['contacts_total'] / max(1, stats['substeps'])
                pair_ratio += [a['frame_cpu'] / b['frame_cpu']
                               for a, b in zip(times['imported'], times['procedural'])]
                print(f'collider {collider}, run {r + 1}: median frame CPU imported '
                      f'{cpu["imported"][-1]:.3f} ms, procedural {cpu["procedural"][-1]:.3f} ms; '
                      f'frame by frame imported / procedural median '
                      f'{np.median(pair_ratio[-len(times["imported"]):]):.3f}', flush=True)
            row = {'wall_ms': {n: float(np.median(v)) for n, v in wall.items()},
                   'cpu_ms': {n: float(np.median(v)) for n, v in cpu.items()},
                   'runs_wall_ms': wall, 'runs_cpu_ms': cpu,
                   'guide_contacts_per_substep': contacts}
            row['ratio_wall'] = row['wall_ms']['imported'] / row['wall_ms']['procedural']
            row['ratio_cpu'] = row['cpu_ms']['imported'] / row['cpu_ms']['procedural']
            row['paired_ratio_cpu'] = float(np.median(pair_ratio))
            row['paired_ratio_cpu_quartiles'] = [float(q) for q in
                                                 np.percentile(pair_ratio, [25, 75])]
            for part in PARTS:
                med = {n: float(np.median(v)) for n, v in part_cpu[part].items()}
                row[part + '_cpu_ms'] = med
                row[part + '_ratio_cpu'] = med['imported'] / med['procedural']
            frame[collider] = row
            print(f'collider {collider}: imported / procedural frame: frame by frame '
                  f'{row["paired_ratio_cpu"]:.3f} (quartiles '
                  f'{row["paired_ratio_cpu_quartiles"][0]:.3f}-'
                  f'{row["paired_ratio_cpu_quartiles"][1]:.3f}); {row["ratio_cpu"]:.3f} '
                  f'(CPU medians {row["cpu_ms"]["imported"]:.3f} / '
                  f'{row["cpu_ms"]["procedural"]:.3f} ms), {row["ratio_wall"]:.3f} (wall); '
                  f'guides {row["guides_ratio_cpu"]:.3f}, ghosts + cloud '
                  f'{row["ghosts_cloud_ratio_cpu"]:.3f} (CPU); '
                  f'guide head contacts a substep {contacts["imported"]:.0f} / '
                  f'{contacts["procedural"]:.0f}', flush=True)
    if args.json:
        record = provenance(command_line('python scripts/bench_groom.py', argv or sys.argv[1:]),
                            args.threads)
        out = {'provenance': record, 'strands': args.strands, 'vertices': args.vertices,
               'file_mb': size_mb, 'frames': args.frames, 'load': load, 'frame': frame}
        with open(args.json, 'w', encoding='utf-8') as f:
            json.dump(out, f, indent=2)
    return 0


if __name__ == '__main__':
    sys.exit(main())
