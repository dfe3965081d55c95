#!/usr/bin/env python3
"""Write a synthetic groom file to try ``groom.file`` and ``hair_sim_groom`` with (no groom
dataset may be redistributed, so the package ships none).

    python scripts/make_groom_file.py OUT.{hair,data,bin,ply,npz} [--strands 3000]
                                      [--vertices 60] [--seed 1]
                                      [--style mixed|straight|wavy|curly]

The groom is the tests' synthetic one (test/groom_files.py: a fringe, longer hair down the back
and sides, a third of the strands curled), written as a DCC tool would hold it: centimetres,
y up, the head 1.6 m above the origin; the format follows the extension.
"""
import argparse
import os
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, 'test'))          # the tests' groom file writers

import groom_files  # noqa: E402


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('output', help='the file to write; its extension picks the format: '
                                   + ', '.join(groom_files.WRITERS))
    ap.add_argument('--strands', type=int, default=3000)
    ap.add_argument('--vertices', type=int, default=60)
    ap.add_argument('--seed', type=int, default=1)
    ap.add_argument('--style', choices=tuple(groom_files.STYLES), default='mixed',
                    help='straight, wavy or curly strands, or mixed: a third curled (default)')
    args = ap.parse_args(argv)
    ext = os.path.splitext(args.output)[1].lower()
    if ext not in groom_files.WRITERS:
        ap.error(f'unknown extension {ext!r}: one of {", ".join(groom_files.WRITERS)}')
    strands = groom_files.synthetic_groom(args.strands, args.vertices, seed=args.seed,
                                          style=args.style)
    os.makedirs(os.path.dirname(os.path.abspath(args.output)), exist_ok=True)
    groom_files.WRITERS[ext](args.output, groom_files.to_file_frame(strands))
    print(f'wrote {args.output}: {args.strands} strands of about {args.vertices} vertices')
    return 0


if __name__ == '__main__':
    sys.exit(main())
