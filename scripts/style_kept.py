#!/usr/bin/env python3
"""Is the groomed style kept?  Settled shape against the groom file's, for straight, wavy and
curly grooms, on a still head and after the bundled walk, at several
``solver.shape_stiffness``.

    python scripts/style_kept.py [--strands 64] [--nodes 48] [--stiffness 0 1000 4000]
                                 [--md docs/results/style.md] [--json F]

Each style is the tests' synthetic groom (test/groom_files.py, :data:`STYLES`) written as a
USC-HairSalon ``.data`` file and imported with the defaults; every strand a guide of ``--nodes``
nodes (resampled from the file: the figures are against that rest shape), simulated by the
default scene's solver (FTL, dt 1/240 s, the head collider).  For each stiffness the hair is
settled until no node moves faster than 2 mm/s (the simulator's settle), measured, driven
through the bundled walk (CMU 131_01, 8.3 s), settled again at its last pose and measured
again: the RMS node distance from the groomed shape carried by the head over the strand
length [% L], and the mean end-to-end distance over the arc length of the strands (a curl's
ratio: 1 straight, lower curled) against the groom's.

Then the output strands as the default scene shows them: ``--guides`` of the strands simulated,
every strand a ghost of ``groom.ghost_nodes`` (16) nodes, shown at ``--detail`` points
(``groom.detail_nodes``: the file's shape carried by the ghosts), measured the same way against
the file's strands at those points, beside the ghosts' own ratio.
"""
import argparse
import os
import sys
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)
sys.path.insert(0, os.path.join(ROOT, 'test'))          # the tests' groom file writers

from hair_tracking.executable import use_numba_cache  # noqa: E402
use_numba_cache()      # before numba loads: the cache make install fills
import numpy as np  # noqa: E402

import groom_files  # noqa: E402
from hair_tracking.core.scene import Scene  # noqa: E402
from hair_tracking.evaluation.provenance import command_line  # noqa: E402
from hair_tracking.evaluation.provenance import provenance, write_reports  # noqa: E402
from hair_tracking.motion.pose_table import load_bundled_walk  # noqa: E402
from hair_tracking.simulator import HairSimulator  # noqa: E402
from settle_shape import rms_percent  # noqa: E402  (scripts/, the folder of this script)

STYLES = ('straight', 'wavy', 'curly')


def shape_figures(x, rest, lengths):
    """``(RMS distance [% L], mean end-to-end / arc length of x, of rest)``."""
    ratio = np.linalg.norm(x[:, -1] - x[:, 0], axis=1) / lengths
    ratio_rest = np.linalg.norm(rest[:, -1] - rest[:, 0], axis=1) / lengths
    return rms_percent(x, rest, lengths), float(ratio.mean()), float(ratio_rest.mean())


def measure(sim):
    """:func:`shape_figures` of the simulator's guides now, in the head frame."""
    return shape_figures(sim.frame(head_frame=True).guides, sim.guides.rest,
                         sim.guides.strand_length)


def run_output(path, stiffness, guides, detail):
    """The output strands (``groom.detail_nodes`` ``detail``) of the default scene still and
    after the walk: ``((RMS [% L], ratio, groom's ratio, the ghosts' ratio), (...), stretch)``
    in the head frame, against the strands at rest."""
    scene = Scene().with_changes(
        groom__file=path, groom__guides=guides, groom__detail_nodes=detail,
        solver__shape_stiffness=stiffness, solver__settle_speed=0.002,
        solver__max_substeps=10_000)
    sim = HairSimulator(scene)
    rest = sim.detail.carry(sim.ghosts.rest, np.eye(3))
    lengths = np.linalg.norm(np.diff(rest, axis=1), axis=2).sum(axis=1)

    def measured():
        frame = sim.frame(head_frame=True)
        g = frame.ghosts
        ghost_ratio = np.linalg.norm(g[:, -1] - g[:, 0], axis=1) / sim.ghosts.strand_length
        return shape_figures(frame.curves, rest, lengths) + (float(ghost_ratio.mean()),)

    still = measured()
    walk_bundled(sim)
    return still, measured(), float(sim.max_stretch())


def walk_bundled(sim):
    """The bundled walk, then a settle at its last pose."""
    walk = load_bundled_walk()
    for t, p, q in zip(walk.t_ns, walk.position, walk.quaternion):
        sim.push_pose(int(t), p, q)
        sim.advance_to(int(t))
    sim.settle()


def run(path, stiffness, strands, nodes):
    scene = Scene().with_changes(
        groom__file=path, groom__guides=strands, groom__ghosts_per_guide=0,
        groom__guide_nodes=nodes, groom__ghost_nodes=nodes, tracking__mode='paper',
        solver__shape_stiffness=stiffness, solver__settle_speed=0.002,
        solver__max_substeps=10_000)
    sim = HairSimulator(scene)
    still = measure(sim)
    walk_bundled(sim)
    return still, measure(sim), float(sim.max_stretch())


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--strands', type=int, default=64)
    ap.add_argument('--nodes', type=int, default=48)
    ap.add_argument('--stiffness', type=float, nargs='+', default=[0.0, 1000.0, 4000.0],
                    help='solver.shape_stiffness values [1/s^2]')
    ap.add_argument('--guides', type=int, default=16,
                    help='guides of the output strands\' scene')
    ap.add_argument('--detail', type=int, default=60, help='groom.detail_nodes of the output')
    ap.add_argument('--md', help='write the table here, with a header')
    ap.add_argument('--json', help='write the figures here')
    args = ap.parse_args(argv)
    rows, out_rows = [], []
    with tempfile.TemporaryDirectory() as tmp:
        for style in STYLES:
            path = os.path.join(tmp, f'{style}.data')
            groom_files.write_data(path, groom_files.to_file_frame(groom_files.synthetic_groom(
                args.strands, 60, seed=1, style=style)))
            for k in args.stiffness:
                still, walked, stretch = run(path, k, args.strands, args.nodes)
                rows.append(dict(style=style, stiffness=k, still_rms=still[0],
                                 still_ratio=still[1], groom_ratio=still[2],
                                 walk_rms=walked[0], walk_ratio=walked[1], stretch=stretch))
                print(f'{style:8s} k {k:7g}: still {still[0]:5.2f} % L, ratio {still[1]:.3f} '
                      f'(groom {still[2]:.3f}); after the walk {walked[0]:5.2f} % L, ratio '
                      f'{walked[1]:.3f}; stretch {stretch:.1e}', flush=True)
            for k in args.stiffness:
                still, walked, stretch = run_output(path, k, args.guides, args.detail)
                out_rows.append(dict(style=style, stiffness=k, still_rms=still[0],
                                     still_ratio=still[1], groom_ratio=still[2],
                                     ghost_ratio=still[3], walk_rms=walked[0],
                                     walk_ratio=walked[1], walk_ghost_ratio=walked[3],
                                     stretch=stretch))
                print(f'{style:8s} k {k:7g} output at {args.detail} points: still '
                      f'{still[0]:5.2f} % L, ratio {still[1]:.3f} (groom {still[2]:.3f}, '
                      f'ghosts {still[3]:.3f}); after the walk {walked[0]:5.2f} % L, ratio '
                      f'{walked[1]:.3f} (ghosts {walked[3]:.3f})', flush=True)
    record = provenance(command_line('python scripts/style_kept.py', argv or sys.argv[1:]))
    lines = [
        f'{args.strands} strands of each synthetic style, every one an FTL guide of '
        f'{args.nodes} nodes; settled until still, then after the bundled walk and settled '
        'again.  RMS node distance from the groomed shape over the strand length; ratio: '
        'mean end-to-end distance over arc length.',
        '',
        '| style | solver.shape_stiffness [1/s^2] | still: from the groom [% L] | still: '
        'ratio (groom) | after the walk: from the groom [% L] | after the walk: ratio | '
        'max stretch |', '|---|---:|---:|---:|---:|---:|---:|']
    lines += [f'| {r["style"]} | {r["stiffness"]:g} | {r["still_rms"]:.2f} | '
              f'{r["still_ratio"]:.3f} ({r["groom_ratio"]:.3f}) | {r["walk_rms"]:.2f} | '
              f'{r["walk_ratio"]:.3f} | {r["stretch"]:.1e} |' for r in rows]
    lines += [
        '', '## The output strands', '',
        f'The default scene ({args.guides} of the strands simulated, every strand a ghost '
        f'of 16 nodes) showing groom.detail_nodes {args.detail} points a strand (the '
        'file\'s shape carried by the ghosts), against the strands at rest at those '
        'points; the ghosts\' ratio is that of their 16 nodes.', '',
        '| style | solver.shape_stiffness [1/s^2] | still: from the groom [% L] | still: '
        'ratio (groom; ghosts) | after the walk: from the groom [% L] | after the walk: '
        'ratio (ghosts) |', '|---|---:|---:|---:|---:|---:|']
    lines += [f'| {r["style"]} | {r["stiffness"]:g} | {r["still_rms"]:.2f} | '
              f'{r["still_ratio"]:.3f} ({r["groom_ratio"]:.3f}; {r["ghost_ratio"]:.3f}) | '
              f'{r["walk_rms"]:.2f} | {r["walk_ratio"]:.3f} ({r["walk_ghost_ratio"]:.3f}) |'
              for r in out_rows]
    write_reports(record, args.json, {'rows': rows, 'output': out_rows}, args.md,
                  'Is the groomed style kept?', lines)
    return 0


if __name__ == '__main__':
    sys.exit(main())
