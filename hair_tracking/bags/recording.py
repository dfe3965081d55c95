"""A head-motion recording read as ``hair_sim_bag import`` reads it: a BVH capture, a pose table
or a head-pose bag, and the options that say how.

:func:`add_arguments` puts the reading options on a parser (``hair_sim_bag import`` for its
RECORDING, ``hair_sim_eval accuracy`` and ``dominance`` for their ``--motion`` files) and
:func:`load_recording` reads one file following them, so that a file evaluates exactly as it
imports.  The kind of file: ``--format``, else ``.bvh`` is BVH, a bag (a folder, ``.mcap`` /
``.db3`` / ``.bag``, or a bag's first bytes) is a bag, anything else a pose table.

Units: a BVH's length unit is recognised from its skeleton
(:func:`hair_tracking.motion.bvh.recognise_units`) unless ``--units`` / ``--scale`` name it; a
table's time unit from the column (:func:`hair_tracking.motion.pose_table.recognise_time_unit`)
unless ``--time-unit`` / ``--time-scale`` name it.  A recording whose timing is no head-pose
stream's (:func:`hair_tracking.motion.head_motion.timing_problem`) is refused when the units
were recognised, and reported on stderr when an option named them.
"""
import math
import sys
from typing import Callable, Optional

import numpy as np

from hair_tracking.bags.io import BagError, EXIT_INPUT, EXIT_USAGE

FORMATS = ('auto', 'bvh', 'table', 'bag')


def _floats(text: str, n: int, what: str):
    try:
        vals = [float(v) for v in text.replace(',', ' ').split()]
    except ValueError:
        raise BagError(f'{what}: expected {n} numbers, got {text!r}', EXIT_USAGE) from None
    if len(vals) != n or not all(math.isfinite(v) for v in vals):
        raise BagError(f'{what}: expected {n} finite numbers, got {text!r}', EXIT_USAGE)
    return vals


def _names(text: str, n: int, what: str):
    names = [v.strip() for v in text.split(',') if v.strip()]
    if len(names) != n:
        raise BagError(f'{what}: expected {n} comma-separated column names, got {text!r}',
                       EXIT_USAGE)
    return names


def add_arguments(p) -> None:
    """The options of :func:`load_recording` on the argparse parser ``p`` (``--format`` and the
    groups 'BVH' and 'pose table')."""
    from hair_tracking.motion.bvh import BVH_UNITS
    from hair_tracking.motion.pose_table import TIME_UNITS

    p.add_argument('--format', choices=FORMATS, default='auto',
                   help='recording format (auto: .bvh is BVH, a bag is a bag, anything else a '
                        'pose table)')
    g = p.add_argument_group('BVH')
    g.add_argument('--joint', default='Head', help='joint that is the head (default Head)')
    g.add_argument('--units', choices=('auto',) + tuple(BVH_UNITS), default='auto',
                   help='BVH length unit: cmu (0.056444 m), m, cm, mm, in, or auto (from the '
                        'rest-pose height of the skeleton; default)')
    g.add_argument('--scale', type=float, help='metres per BVH unit (overrides --units)')
    g.add_argument('--origin', choices=('center', 'joint'), default='center',
                   help='head-frame origin: the middle of the head bone (default) or the joint')
    g.add_argument('--axes', choices=('cmu', 'infer'), default='cmu',
                   help='head axes in the joint frame: the CMU skeleton convention (default) or '
                        'inferred from the walking direction')
    g = p.add_argument_group('pose table')
    g.add_argument('--time-column', default=None,
                   help='time column (default: recognised by name: t_s, t, time, timestamp, '
                        'stamp, ...)')
    g.add_argument('--time-unit', choices=('auto',) + TIME_UNITS, default='auto',
                   help='unit of the time column; 100ns: the ticks of .NET / Unity / Windows '
                        '(default auto: from the column name, a date, or the median step)')
    g.add_argument('--time-scale', default=None, metavar='SECONDS',
                   help='seconds per tick of the time column instead of --time-unit, e.g. 1e-7 '
                        'for 100 ns ticks; any epoch (the first stamp is subtracted exactly)')
    g.add_argument('--quat-columns', default=None,
                   help='the four quaternion columns, in --quat-order (default: recognised by '
                        'name: qx qy qz qw, quat_x ..., rot_x ..., orientation_x ..., or w x y z)')
    g.add_argument('--quat-order', choices=('xyzw', 'wxyz'), default='xyzw')
    g.add_argument('--position-columns', default=None,
                   help="three position columns [m], or 'none' for orientation only (default: "
                        'recognised by name: px py pz, x y z, pos_x ..., or none found)')
    g.add_argument('--neck-offset', default='0,0,0',
                   help='orientation only: head origin from the neck pivot, head frame [m]')
    g.add_argument('--pivot', default='0,0,0', help='orientation only: neck pivot, world [m]')
    g.add_argument('--delimiter', default=None,
                   help="column separator (default: ',' if the header has one, else spaces)")


def recording_format(path: str, fmt: str = 'auto') -> str:
    """'bvh', 'table' or 'bag': ``fmt`` unless it is 'auto' (see the module doc)."""
    from hair_tracking.bags import io as bag_io
    if fmt != 'auto':
        return fmt
    if str(path).lower().endswith('.bvh'):
        return 'bvh'
    return 'bag' if bag_io.looks_like_bag(path) else 'table'


def _bvh(path, args, warn: Callable[[str], None]):
    """A BVH capture; a unit that ``--units`` names is refused, and a ``--scale`` warned
    about, when it makes the skeleton no person's height
    (:func:`hair_tracking.motion.bvh.units_problem`)."""
    from hair_tracking.motion import bvh as mocap
    if args.scale is not None and not (math.isfinite(args.scale) and args.scale > 0):
        raise BagError(f'--scale must be > 0 metres per unit, got {args.scale}', EXIT_USAGE)
    skeleton = mocap.read_bvh(path)               # read once for the units and the axes
    if args.scale is not None:
        scale, words = args.scale, f'{args.scale} m/unit'
    elif args.units != 'auto':
        scale, words = mocap.BVH_UNITS[args.units], args.units
    else:
        scale, words = mocap.recognise_units(skeleton)
    if args.scale is not None or args.units != 'auto':
        problem = mocap.units_problem(skeleton, scale, words)
        if problem and args.scale is None:
            raise BagError(f'{problem}: give that --units (or --scale to force a scale)',
                           EXIT_USAGE)
        if problem:
            warn(f'warning: {problem}')
    axes = mocap.CMU_HEAD_AXES
    if args.axes == 'infer':
        axes = mocap.infer_head_axes(skeleton, args.joint, scale=scale)
    motion = mocap.load_bvh_head_motion(path, joint=args.joint, scale=scale, head_axes=axes,
                                        origin=args.origin)
    return motion, f'BVH joint {args.joint!r}, units {words}, head axes {args.axes}'


def _table(path, args):
    from hair_tracking.motion import pose_table as tables
    time_col, quat_cols, pos_cols = args.time_column, None, None
    quat_order = args.quat_order
    if args.quat_columns:
        quat_cols = _names(args.quat_columns, 4, '--quat-columns')
    if args.position_columns and args.position_columns.strip().lower() != 'none':
        pos_cols = _names(args.position_columns, 3, '--position-columns')
    if time_col is None or quat_cols is None or args.position_columns is None:
        found = tables.recognise_columns(path, args.delimiter)     # by their names
        time_col = time_col or found[0]
        if quat_cols is None:
            quat_cols, quat_order = found[1], 'xyzw'
        if args.position_columns is None:
            pos_cols = found[2]
    motion = tables.read_pose_table(
        path, time_column=time_col, time_unit=args.time_unit, quat_columns=quat_cols,
        quat_order=quat_order, position_columns=pos_cols,
        neck_offset=_floats(args.neck_offset, 3, '--neck-offset'),
        pivot=_floats(args.pivot, 3, '--pivot'), delimiter=args.delimiter,
        time_scale=args.time_scale)
    unit = f'{args.time_scale} s ticks' if args.time_scale else motion.units or args.time_unit
    return motion, (f'pose table, time {time_col!r} [{unit}], quaternion '
                    f'{",".join(quat_cols)} ({quat_order})'
                    + (', orientation only' if pos_cols is None else
                       f', position {",".join(pos_cols)}'))


def _bag(path):
    """The head poses of a bag as a HeadMotion: stamps that do not increase are dropped and
    counted, quaternions that are not unit (to 1e-9) normalised."""
    from hair_tracking.bags import io as bag_io
    from hair_tracking.motion.head_motion import HeadMotion
    poses = bag_io.read_head_poses(path)
    t = poses.t_ns
    keep = np.ones(len(t), dtype=bool)
    last = None
    for i, ti in enumerate(t.tolist()):
        if last is not None and ti <= last:
            keep[i] = False
        else:
            last = ti
    q = poses.quaternion[keep]
    norm = np.linalg.norm(q, axis=1, keepdims=True)
    q = np.where(np.abs(norm - 1.0) > 1e-9, q / norm, q)
    dropped = {'bad_pose': poses.invalid, 'bad_time': int(np.sum(~keep))}
    motion = HeadMotion(t[keep], poses.position[keep], q,
                        source=f'{path} ({poses.topic})', dropped=dropped)
    return motion, f'head-pose bag, {poses.topic} [{poses.msgtype.split("/")[-1]}]'


def load_recording(path: str, args, warn: Optional[Callable[[str], None]] = None):
    """``(HeadMotion, words saying how it was read)`` of one recording, following the options of
    :func:`add_arguments` in ``args``.  Raises BagError: EXIT_USAGE when an option is bad or the
    units must be named, EXIT_INPUT when the file is missing or malformed (bags: the codes of
    :mod:`hair_tracking.bags.io`).  A timing no head-pose stream has, with units the options
    named, is reported through ``warn`` (default: a line on stderr)."""
    from hair_tracking.motion.head_motion import (HeadMotionError, speed_problem,
                                                  timing_problem, UnitsError)
    path = str(path)
    warn = warn or (lambda text: print(text, file=sys.stderr))
    fmt = recording_format(path, args.format)
    try:
        if fmt == 'bvh':
            motion, note = _bvh(path, args, warn)
        elif fmt == 'table':
            motion, note = _table(path, args)
        else:
            motion, note = _bag(path)
    except UnitsError as exc:
        raise BagError(str(exc), EXIT_USAGE) from None
    except HeadMotionError as exc:
        raise BagError(str(exc), EXIT_INPUT) from None
    except OSError as exc:
        raise BagError(f'{path}: cannot read: {exc.strerror or exc}', EXIT_INPUT) from None
    problem = timing_problem(motion.rate_hz, motion.duration_s)
    if problem:
        fix = {'table': '; a wrong --time-unit / --time-scale?',
               'bvh': '; check its Frame Time'}.get(fmt, '')
        warn(f'warning: {path}: {problem}{fix}')
    problem = speed_problem(motion.position, motion.t_ns)
    if problem:
        fix = {'table': '; positions in another unit than metres?',
               'bvh': '; a wrong --units / --scale?'}.get(fmt, '')
        warn(f'warning: {path}: {problem}{fix}')
    return motion, note
