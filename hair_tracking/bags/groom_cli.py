"""``hair_sim_groom``: look at a groom file before the hair uses it (guide: docs/grooms.md).

Sub-commands::

    info     FILE               strands, vertices, lengths, bounding box, units, up and face
    convert  FILE -o OUT        the strands as .hair, .data, .ply, .npz or USD (as read, or as put
                                on the head)
    preview  FILE -o OUT.png    a picture of the groom on the head, front and side

Every command reads the file as ``groom.file`` does (formats and options: docs/grooms.md); the
groom options (``--units``, ``--up-axis``, ``--face-axis``, ``--fit``, ``--rotation``,
``--offset``, ``--max-strands``) are the ``groom.*`` parameters of the same names, and
``--scene`` takes the others (the scalp, the node counts) from a scene file.

Exit codes (those of ``hair_sim_bag``, whose :func:`~hair_tracking.bags.cli.run_command` runs
the commands): 0 success, or stopped by SIGINT (Ctrl-C) or SIGTERM (nothing written then: an
output is written under a temporary name and renamed when whole), 1 an unexpected error, 2 bad
command line, 3 the file is missing or cannot be read (the message names the byte and what was
expected there), 5 the output exists or cannot be written.  Errors are one line on stderr,
never a traceback.
"""
import argparse
import contextlib
from dataclasses import replace
import os
from pathlib import Path
import sys
from typing import List, Optional

import numpy as np

from hair_tracking import executable
from hair_tracking.bags.cli import run_command
from hair_tracking.bags.io import BagError, check_output_path, EXIT_OK, EXIT_USAGE
from hair_tracking.core.scene import Scene, SceneError
from hair_tracking.core.scene_params import GROOM_FITS, GROOM_UNITS, GROOM_UP_AXES
from hair_tracking.grooms.build import import_groom, survey
from hair_tracking.grooms.writers import WRITERS, write_strands

PROG = 'hair_sim_groom'


class _Parser(argparse.ArgumentParser):
    """argparse that reports errors as 'hair_sim_groom: error: ...' with exit code 2."""

    def error(self, message):
        self.print_usage(sys.stderr)
        self.exit(EXIT_USAGE, f'{self.prog}: error: {message}\n')


def groom_spec(args):
    """The groom section of ``--scene`` (default: the default scene) with the file and the
    command line's groom options (BagError EXIT_USAGE naming a bad one)."""
    changes = {'groom__file': args.file, 'groom__units': args.units,
               'groom__up_axis': args.up_axis, 'groom__face_axis': args.face_axis,
               'groom__fit': args.fit,
               'groom__max_strands': args.max_strands}
    for name, text in (('file_rotation_deg', args.rotation), ('file_offset', args.offset)):
        if text is not None:
            try:
                changes['groom__' + name] = [float(v) for v in text.replace(',', ' ').split()]
            except ValueError:
                raise BagError(f'--{name}: expected 3 numbers, got {text!r}', EXIT_USAGE) \
                    from None
    try:
        base = Scene.from_yaml(args.scene) if args.scene else Scene()
        return base.with_changes(**changes).groom
    except SceneError as e:
        raise BagError(str(e), EXIT_USAGE) from None


def _xyz(v) -> str:
    return '[' + ', '.join(f'{float(x):.4g}' for x in v) + ']'


@contextlib.contextmanager
def _whole(out: Path):
    """A temporary name beside ``out`` (same extension) to write to; it becomes ``out`` when the
    block ends, and is removed when the block is left by an exception (a stop among them)."""
    tmp = out.with_name(f'.{out.stem}.partial{out.suffix}')
    try:
        yield tmp
        os.replace(tmp, out)
    finally:
        if tmp.exists():
            tmp.unlink()


def cmd_info(args) -> int:
    info, _ = survey(args.file, args.units, args.up_axis, args.face_axis)
    lo, hi = info.lengths[0], info.lengths[2]
    u = info.unit
    print(f'file:      {args.file} ({info.format})')
    print(f'strands:   {info.strands - info.empty - info.degenerate} of {info.strands} '
          f'({info.empty} empty, {info.degenerate} degenerate skipped)')
    print(f'vertices:  {info.vertices}')
    print(f'lengths:   min {lo:.4g}, median {info.lengths[1]:.4g}, max {hi:.4g} units '
          f'({lo * u:.3g}, {info.lengths[1] * u:.3g}, {hi * u:.3g} m)')
    print(f'box:       {_xyz(info.box[0])} .. {_xyz(info.box[1])} units '
          f'(size {_xyz((info.box[1] - info.box[0]) * u)} m)')
    print(f'units:     {info.units_words}')
    print(f'up axis:   {info.up_words}')
    print(f'face:      {info.face_words}')
    imported = import_groom(groom_spec(args))
    print(f'on the head: {imported.placing}')
    return EXIT_OK


def cmd_convert(args) -> int:
    out = check_output_path(args.output, args.overwrite)
    if out.suffix.lower() not in WRITERS:
        raise BagError(f'{args.output}: the output must be one of '
                       f'{", ".join(WRITERS)}', EXIT_USAGE)
    if args.imported:
        spec = groom_spec(args)
        if args.nodes is not None:
            if not 3 <= args.nodes <= 256:
                raise BagError(f'--nodes must be in [3, 256], got {args.nodes}', EXIT_USAGE)
            spec = replace(spec, ghost_nodes=args.nodes)
        imported = import_groom(spec)
        s = imported.strands
        with _whole(out) as tmp:
            write_strands(tmp, s.reshape(-1, 3), np.full(s.shape[0], s.shape[1]), 1.0, 'z')
        print(f'wrote {out}: {s.shape[0]} strands x {s.shape[1]} nodes on the head '
              f'(metres, head frame); {imported.note}')
        return EXIT_OK
    options = (('--rotation', args.rotation), ('--offset', args.offset),
               ('--max-strands', args.max_strands), ('--fit', args.fit != 'translate'),
               ('--scene', args.scene))
    placing = [name for name, given in options if given]
    if placing:
        raise BagError(f'{", ".join(placing)}: how the strands are put on the head, which a '
                       'conversion as read does not do; add --imported', EXIT_USAGE)
    info, poly = survey(args.file, args.units, args.up_axis, args.face_axis)
    # only what the file stated or the command line said is recorded: a guess stays a guess
    unit = info.unit if args.units != 'auto' or poly.meters_per_unit is not None else None
    up = info.up if args.up_axis != 'auto' or poly.up_axis is not None else None
    with _whole(out) as tmp:
        write_strands(tmp, poly.points, poly.counts, unit, up)
    print(f'wrote {out}: {poly.count} strands, {poly.points.shape[0]} vertices as read '
          f'(units {info.units_words}; up {info.up_words}; recorded: units '
          f'{"-" if unit is None else f"{unit:g} m"}, up {up or "-"})')
    return EXIT_OK


def cmd_preview(args) -> int:
    from hair_tracking.bags.render import picture
    out = check_output_path(args.output, args.overwrite)
    if out.suffix.lower() != '.png':
        raise BagError(f'{args.output}: the output must be a .png file', EXIT_USAGE)
    if args.max_drawn < 1:
        raise BagError(f'--max-drawn must be >= 1, got {args.max_drawn}', EXIT_USAGE)
    spec = groom_spec(args)
    imported = import_groom(spec)
    strands = imported.strands
    title = f'{os.path.basename(args.file)}: {strands.shape[0]} strands on the head'
    with _whole(out) as tmp:
        picture(strands, tmp, title, head_radii=spec.scalp.radii, max_strands=args.max_drawn)
    print(f'wrote {out}; {imported.note}')
    return EXIT_OK


def build_parser() -> argparse.ArgumentParser:
    ap = _Parser(prog=PROG, description=__doc__.split('\n')[0],
                 epilog='Exit codes: 0 ok (also when stopped by Ctrl-C / SIGTERM), 1 failed, 2 '
                        'usage, 3 the file is missing or cannot be read, 5 output '
                        'exists/unwritable. Guide: docs/grooms.md')
    sub = ap.add_subparsers(dest='command', metavar='COMMAND', parser_class=_Parser)
    sub.required = True

    def common(p):
        p.add_argument('file', help='a groom file: .hair, .data, .bin, .ply, .npz, .usd*')
        p.add_argument('--units', choices=('auto',) + tuple(GROOM_UNITS), default='auto',
                       help='length unit of the file (default auto: stated by the file, else '
                            'guessed from the span of the roots)')
        p.add_argument('--up-axis', choices=GROOM_UP_AXES, default='auto',
                       help='the file axis pointing up: x, -x, y, -y, z, -z (default auto: '
                            'stated by the file, else guessed)')
        p.add_argument('--face-axis', choices=GROOM_UP_AXES, default='auto',
                       help='the file axis the face looks toward, across the up axis (default '
                            'auto: the side the roots leave bare, else the up axis\'s '
                            'convention)')
        p.add_argument('--fit', choices=GROOM_FITS, default='translate',
                       help='how the roots are put on the scalp (default translate)')
        p.add_argument('--rotation', metavar='RX,RY,RZ',
                       help='turn about the head x, y, z axes [deg] before fitting')
        p.add_argument('--offset', metavar='X,Y,Z', help='shift after fitting [m, head frame]')
        p.add_argument('--max-strands', type=int, default=0,
                       help='keep at most this many strands, evenly spread (0: all)')
        p.add_argument('--scene', help='scene YAML whose groom section (scalp, nodes) to use')

    p = sub.add_parser('info', help='counts, lengths, box, units and up axis of a groom file')
    common(p)
    p.set_defaults(func=cmd_info)
    p = sub.add_parser('convert', help='a groom file as .hair, .data, .ply, .npz or USD')
    common(p)
    p.add_argument('-o', '--output', required=True,
                   help='the file to write: .hair, .data, .ply, .npz, .usd, .usda or .usdc')
    p.add_argument('--imported', action='store_true',
                   help='the strands as put on the head (metres, head frame, resampled to '
                        '--nodes) instead of as read')
    p.add_argument('--nodes', type=int, help='nodes per strand with --imported (default: the '
                                             "scene's groom.ghost_nodes)")
    p.add_argument('--overwrite', action='store_true', help='replace an existing output')
    p.set_defaults(func=cmd_convert)
    p = sub.add_parser('preview', help='a picture of the groom on the head (front and side)')
    common(p)
    p.add_argument('-o', '--output', required=True, help='the .png file to write')
    p.add_argument('--max-drawn', type=int, default=600, help='draw at most this many strands')
    p.add_argument('--overwrite', action='store_true', help='replace an existing output')
    p.set_defaults(func=cmd_preview)
    return ap


def main(argv: Optional[List[str]] = None) -> int:
    """Console entry point ``hair_sim_groom``; returns the exit code (see module doc).  Every
    command is plain Python and numba work: a stop request interrupts it anywhere."""
    args = build_parser().parse_args(argv)
    with executable.started() as stop:
        args.stop = stop
        return run_command(PROG, args, interruptible=True)


if __name__ == '__main__':
    sys.exit(main())
