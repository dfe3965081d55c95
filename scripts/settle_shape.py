#!/usr/bin/env python3
"""How far the hair settles from its groomed shape, and how much the settled shape depends on
the step size.

    python scripts/settle_shape.py [--groom FILE] [--settle-speed 0.002] [--md F]

Every strand of the groom (the default procedural one, or ``--groom FILE`` imported) is a guide
simulated by FTL (the scene's solver, tracking.mode paper without ghosts) and settled with a
still head at dt 1/60, 1/240 and 1/960 s, twice: for the default ``solver.settle_time`` (0.5 s)
and until still (``solver.settle_speed``).  For each it prints the RMS distance of the settled
nodes from the groomed shape and from the shape settled at dt 1/960 s, both in % of the strand
length (RMS over nodes and strands of distance / strand length), and the time simulated.
"""
import argparse
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from hair_tracking.executable import use_numba_cache  # noqa: E402
use_numba_cache()      # before numba loads: the cache make install fills
import numpy as np  # noqa: E402

from hair_tracking.core.scene import Scene  # noqa: E402
from hair_tracking.evaluation.provenance import command_line  # noqa: E402
from hair_tracking.evaluation.provenance import markdown_lines, provenance  # noqa: E402
from hair_tracking.simulator import HairSimulator  # noqa: E402

DTS = (1 / 60, 1 / 240, 1 / 960)


def rms_percent(a, b, lengths):
    d = np.linalg.norm(a - b, axis=2) / lengths[:, None]
    return 100.0 * float(np.sqrt(np.mean(d * d)))


def settled(scene):
    sim = HairSimulator(scene)
    return sim.frame(head_frame=True).guides, sim.guides.rest, sim.guides.strand_length, \
        sim.settled_s


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--groom', help='a groom file (default: the procedural groom)')
    ap.add_argument('--guides', type=int, default=64, help='strands simulated')
    ap.add_argument('--settle-speed', type=float, default=0.002,
                    help='solver.settle_speed of the settle until still [m/s]')
    ap.add_argument('--md', help='write the table here, with a header')
    args = ap.parse_args(argv)
    base = Scene().with_changes(tracking__mode='paper', groom__ghosts_per_guide=0,
                                groom__guides=args.guides, solver__max_substeps=10_000,
                                groom__file=args.groom or '')
    rows = []
    for label, speed in (('settle_time 0.5 s', 0.0),
                         (f'until still ({args.settle_speed:g} m/s)', args.settle_speed)):
        shapes = {}
        for dt in DTS:
            x, rest, lengths, secs = settled(base.with_changes(
                solver__dt=dt, solver__settle_time=0.5, solver__settle_speed=speed))
            shapes[dt] = (x, rest, lengths, secs)
        ref = shapes[DTS[-1]][0]
        for dt in DTS:
            x, rest, lengths, secs = shapes[dt]
            rows.append((label, f'1/{round(1 / dt)}', secs, rms_percent(x, rest, lengths),
                         rms_percent(x, ref, lengths)))
            print(f'{label:28s} dt {rows[-1][1]:>6s}: settled {secs:5.1f} s, from the groom '
                  f'{rows[-1][3]:6.2f} % L, from dt 1/960 {rows[-1][4]:6.2f} % L', flush=True)
    if args.md:
        record = provenance(command_line('python scripts/settle_shape.py',
                                         argv or sys.argv[1:]))
        lines = [f'# Settled shape against the groomed shape ({args.groom or "procedural groom"})',
                 ''] + markdown_lines(record) + [
                 f'{args.guides} strands, every one an FTL guide; RMS node distance over the '
                 'strand length.',
                 '',
                 '| settle | dt [s] | simulated [s] | from the groom [% L] | '
                 'from dt 1/960 [% L] |', '|---|---:|---:|---:|---:|']
        lines += [f'| {r[0]} | {r[1]} | {r[2]:.1f} | {r[3]:.2f} | {r[4]:.2f} |' for r in rows]
        with open(args.md, 'w', encoding='utf-8') as f:
            f.write('\n'.join(lines) + '\n')
    return 0


if __name__ == '__main__':
    sys.exit(main())
