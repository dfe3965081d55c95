#!/usr/bin/env python3
"""How much volume the hair has: the layer of long hair on the top of a still head, with and
without the hair-hair stage (``volume.enabled``), and what it costs in a settle.

    python scripts/volume_layer.py [--scene long_hair] [--pressure 30] [--friction 20]
                                   [--cell-size 0.025] [--md docs/results/volume.md] [--json F]

The scene (a preset or YAML file; default ``long_hair``: 55 cm hair on the bust) is built with
the stage off and on (the ``volume.*`` options given), each settled on a still head until no
node moves faster than 2 mm/s (the simulator's settle, at most 30 s).  For each it prints the
hair layer on the top of the head (:func:`hair_tracking.core.metrics.hair_layer` of the output
strands: the 10-90 % spread of the nodes' distances from the head collider within 60 degrees
of the top, and their median), the share of the output nodes with a node of another strand
within 2 mm (:func:`hair_tracking.ghosts.correspondence.near_other_strands`), the largest
stretch of the guides and of the output, the deepest node in the head collider, and the
simulated time the settle took.
"""
import argparse
import os
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from hair_tracking.executable import use_numba_cache  # noqa: E402
use_numba_cache()      # before numba loads: the cache make install fills

from hair_tracking.bags.offline import load_settings  # noqa: E402
from hair_tracking.core.metrics import hair_layer  # noqa: E402
from hair_tracking.ghosts.correspondence import near_other_strands  # noqa: E402
from hair_tracking.evaluation.provenance import command_line  # noqa: E402
from hair_tracking.evaluation.provenance import provenance, write_reports  # noqa: E402
from hair_tracking.simulator import HairSimulator  # noqa: E402


#: [m] two strands closer than this run through each other (:func:`near_other_strands`)
NEAR_M = 0.002


def measure(scene) -> dict:
    """The figures of one scene, settled until still (module docstring)."""
    sim = HairSimulator(scene.with_changes(solver__settle_speed=0.002,
                                           solver__max_substeps=10_000))
    c = scene.collider
    strands = sim.frame(head_frame=True).strands
    spread, median, nodes = hair_layer(strands, c.center, c.radii)
    return dict(volume=scene.volume.enabled, spread_mm=1e3 * spread, median_mm=1e3 * median,
                nodes=nodes, near_2mm=near_other_strands(strands, NEAR_M),
                stretch_guides=float(sim.guide_solver.stats['max_stretch']),
                stretch=float(sim.max_stretch()), depth_mm=1e3 * float(sim.penetration()),
                margin_mm=1e3 * c.margin, settled_s=float(sim.settled_s))


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--scene', default='long_hair', help='preset name or scene YAML')
    ap.add_argument('--pressure', type=float, help='volume.pressure [m/s^2]')
    ap.add_argument('--friction', type=float, help='volume.friction [1/s]')
    ap.add_argument('--cell-size', type=float, help='volume.cell_size [m]')
    ap.add_argument('--md', help='write the table here, with a header')
    ap.add_argument('--json', help='write the figures here')
    args = ap.parse_args(argv)
    base = load_settings(scene=args.scene).scene
    given = {f'volume__{k}': v for k, v in (('pressure', args.pressure),
                                            ('friction', args.friction),
                                            ('cell_size', args.cell_size)) if v is not None}
    rows = []
    for on in (False, True):
        row = measure(base.with_changes(volume__enabled=on, **given))
        rows.append(row)
        print(f"volume {'on ' if on else 'off'}: layer {row['spread_mm']:.1f} mm (10-90 %), "
              f"median {row['median_mm']:.1f} mm over {row['nodes']} nodes; "
              f"{row['near_2mm']:.1%} of the nodes within 2 mm of another strand; stretch guides "
              f"{row['stretch_guides']:.1e}, output {row['stretch']:.1e}; deepest "
              f"{row['depth_mm']:.3f} mm (margin {row['margin_mm']:g}); settled in "
              f"{row['settled_s']:.1f} s", flush=True)
    ratio = rows[1]['spread_mm'] / max(rows[0]['spread_mm'], 1e-12)
    print(f'layer with / without: {ratio:.2f}')
    v = base.with_changes(**given).volume
    record = provenance(command_line('python scripts/volume_layer.py', argv))
    body = [
        f'Scene {args.scene}; volume.pressure {v.pressure:g} m/s^2, volume.friction '
        f'{v.friction:g} 1/s, volume.cell_size {v.cell_size:g} m; settled until no node moves '
        'faster than 2 mm/s.  Layer: the 10-90 % spread of the output nodes\' distances from '
        'the head collider within 60 degrees of the top.  Near another strand: the share of '
        'the output nodes with a node of another strand within 2 mm (strands running through '
        'each other).', '',
        '| volume | layer [mm] | median distance [mm] | nodes | near another strand '
        '| stretch: guides / output | deepest in the collider [mm] | settled in [s] |',
        '|---|---:|---:|---:|---:|---:|---:|---:|']
    body += [f"| {'on' if r['volume'] else 'off'} | {r['spread_mm']:.1f} | "
             f"{r['median_mm']:.1f} | {r['nodes']} | {r['near_2mm']:.1%} | "
             f"{r['stretch_guides']:.1e} / "
             f"{r['stretch']:.1e} | {r['depth_mm']:.3f} (margin {r['margin_mm']:g}) | "
             f"{r['settled_s']:.1f} |" for r in rows]
    body += ['', f'Layer with the stage / without: {ratio:.2f}.']
    write_reports(record, args.json, {'rows': rows, 'ratio': ratio}, args.md,
                  'Hair volume: the layer on a still head', body)
    return 0


if __name__ == '__main__':
    sys.exit(main())
