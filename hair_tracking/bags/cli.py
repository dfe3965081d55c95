"""``hair_sim_bag``: record a head-pose stream once, run the hair on it many times.

Sub-commands (``hair_sim_bag <command> --help`` for every option; guide: docs/bags.md)::

    info    [BAG]                 topics, types, counts and duration of a bag
    import  RECORDING -o BAG      BVH motion capture or a pose table -> head-pose bag
    run     [BAG] -o OUT          offline: head poses -> hair -> markers, cloud, diagnostics
    play    [BAG]                 publish a bag live with /clock (like ros2 bag play --clock)
    record  TOPIC... -o OUT       subscribe (raw) and write a bag (like ros2 bag record)
    render  BAG -o DIR            PNG frames / animated GIF of the hair + a diagnostics plot

``BAG`` defaults to the bundled sample (CMU 131_01 walk head poses).  Bags are rosbag2
directories or single ``.mcap``/``.db3`` files (ROS 1 ``.bag`` too, for reading); no ROS
installation is needed for info/import/run/render.

Exit codes: 0 success, or stopped by SIGINT (Ctrl-C) or SIGTERM (run and record close their
output bag as it is, a complete bag; import and render leave nothing); 1 the run failed, 2 bad
command line, 3 input missing/not a bag/corrupt, 4 the bag lacks what was asked for (no head-pose
topic, unknown frame), 5 output exists or cannot be written.  Errors are one line on stderr,
never a traceback.
"""
import argparse
import math
import os
import sys
from typing import List, Optional

import numpy as np

from hair_tracking import executable
from hair_tracking.bags.io import (BagError, EXIT_CONTENT, EXIT_FAILURE, EXIT_INPUT, EXIT_OK,
                                   EXIT_OUTPUT, EXIT_USAGE, POSE_KIND_TOPICS, POSE_KINDS,
                                   STORAGES)

#: seconds since the epoch given to the first sample of an import (reproducible, non-zero:
#: a stamp of 0 means "now" to the node); 1e9 s is 2001-09-09T01:46:40Z.
DEFAULT_START_TIME_S = 1_000_000_000.0

#: metres per BVH length unit for --units
BVH_UNITS = {'cmu': 0.056444, 'm': 1.0, 'cm': 0.01, 'mm': 0.001, 'in': 0.0254}


class _Parser(argparse.ArgumentParser):
    """argparse that reports errors as 'hair_sim_bag: error: ...' with exit code 2."""

    def error(self, message):
        self.print_usage(sys.stderr)
        self.exit(EXIT_USAGE, f'{self.prog}: error: {message}\n')


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


def _check_seconds(value, what, allow_none=True, positive=False):
    if value is None and allow_none:
        return
    if not math.isfinite(value) or value < 0 or (positive and value == 0):
        raise BagError(f'{what} must be a finite number of seconds '
                       f'{"> 0" if positive else ">= 0"}, got {value}', EXIT_USAGE)


# ================================================================ info
def cmd_info(args) -> int:
    from hair_tracking.bags import io as bag_io
    path = args.bag or bag_io.bundled_bag()
    info = bag_io.bag_info(path)
    kinds = {'dir': 'rosbag2 directory', 'mcap': 'rosbag2 MCAP file',
             'sqlite3': 'rosbag2 sqlite3 file', 'ros1': 'ROS 1 bag'}
    print(f'bag:      {path} ({kinds[info["kind"]]})')
    print(f'messages: {info["messages"]}')
    if info['messages']:
        sec, nsec = divmod(info['start_ns'], 1_000_000_000)
        print(f'start:    {sec}.{nsec:09d} s')
        print(f'duration: {info["duration_s"]:.3f} s')
    print('topics:')
    print(bag_io.format_topics(info['topics']))
    return EXIT_OK


# ================================================================ import
def _bvh_scale(path: str, units: str, joint: str):
    """(metres per unit, words) for --units; 'auto' from the rest-pose height of the skeleton."""
    from hair_tracking.bags.head_motion import Bvh, read_bvh
    if units != 'auto':
        return BVH_UNITS[units], units
    bvh = read_bvh(path)
    rest = Bvh(joints=bvh.joints, motion=np.zeros((1, bvh.motion.shape[1])),
               frame_time=bvh.frame_time, path=path)
    pts = rest.all_positions()[0]
    height = float(np.ptp(pts[:, 1]))          # BVH is y up
    if not height > 0:
        raise BagError(f'{path}: cannot infer the units (the rest pose has no height); give '
                       f'--units or --scale', EXIT_USAGE)
    implied = 1.7 / height                     # an adult standing 1.7 m tall
    name = min(BVH_UNITS, key=lambda k: abs(math.log(BVH_UNITS[k] / implied)))
    if abs(math.log(BVH_UNITS[name] / implied)) > math.log(1.35):
        raise BagError(f'{path}: cannot infer the units: the rest pose is {height:.4g} units '
                       f'tall, which matches none of {", ".join(BVH_UNITS)}; give --units or '
                       f'--scale', EXIT_USAGE)
    return BVH_UNITS[name], (f'{name} (auto: rest pose {height:.4g} units tall = '
                             f'{height * BVH_UNITS[name]:.2f} m)')


def load_recording(args):
    """HeadMotion of the import's RECORDING, following the options (BagError when bad)."""
    from hair_tracking.bags import head_motion as hm

    path = args.recording
    fmt = args.format
    if fmt == 'auto':
        fmt = 'bvh' if path.lower().endswith('.bvh') else 'table'
    try:
        if fmt == 'bvh':
            if args.scale is not None:
                if not (math.isfinite(args.scale) and args.scale > 0):
                    raise BagError(f'--scale must be > 0 metres per unit, got {args.scale}',
                                   EXIT_USAGE)
                scale, words = args.scale, f'{args.scale} m/unit'
            else:
                scale, words = _bvh_scale(path, args.units, args.joint)
            axes = hm.CMU_HEAD_AXES
            if args.axes == 'infer':
                axes = hm.infer_head_axes(hm.read_bvh(path), args.joint, scale=scale)
            motion = hm.load_bvh_head_motion(path, joint=args.joint, scale=scale,
                                             head_axes=axes, origin=args.origin)
            note = f'BVH joint {args.joint!r}, units {words}, head axes {args.axes}'
        else:
            time_col, quat_cols, pos_cols = args.time_column, None, None
            quat_order = args.quat_order
            if args.quat_columns:
                quat_cols = _names(args.quat_columns, 4, '--quat-columns')
            if args.position_columns and args.position_columns.strip().lower() != 'none':
                pos_cols = _names(args.position_columns, 3, '--position-columns')
            if time_col is None or quat_cols is None or args.position_columns is None:
                found = hm.recognise_columns(path, args.delimiter)     # by their names
                time_col = time_col or found[0]
                if quat_cols is None:
                    quat_cols, quat_order = found[1], 'xyzw'
                if args.position_columns is None:
                    pos_cols = found[2]
            motion = hm.read_pose_table(
                path, time_column=time_col, time_unit=args.time_unit,
                quat_columns=quat_cols, quat_order=quat_order, position_columns=pos_cols,
                neck_offset=_floats(args.neck_offset, 3, '--neck-offset'),
                pivot=_floats(args.pivot, 3, '--pivot'), delimiter=args.delimiter,
                time_scale=args.time_scale)
            unit = f'{args.time_scale} s ticks' if args.time_scale else args.time_unit
            note = (f'pose table, time {time_col!r} [{unit}], quaternion '
                    f'{",".join(quat_cols)} ({quat_order})'
                    + (', orientation only' if pos_cols is None else
                       f', position {",".join(pos_cols)}'))
    except hm.HeadMotionError as exc:
        raise BagError(str(exc), EXIT_INPUT) from None
    except OSError as exc:
        raise BagError(f'{path}: cannot read: {exc.strerror or exc}', EXIT_INPUT) from None
    return motion, note


def cmd_import(args) -> int:
    from hair_tracking.bags import io as bag_io
    _check_seconds(args.start, '--start')
    _check_seconds(args.duration, '--duration', positive=True)
    bag_io.check_output_path(args.output, args.overwrite)
    bag_io.output_storage(args.output, args.storage)
    motion, note = load_recording(args)
    t = motion.t_ns - motion.t_ns[0]
    keep = t >= int(round(args.start * 1e9))
    if args.duration is not None:
        keep &= t < int(round((args.start + args.duration) * 1e9))
    if not keep.any():
        raise BagError(f'{args.recording}: no samples in the chosen range (the recording lasts '
                       f'{motion.duration_s:.3f} s)', EXIT_CONTENT)
    if args.keep_times:
        stamps = motion.t_ns[keep]
        if stamps[0] <= 0:
            raise BagError('--keep-times: the recording starts at time 0 (a ROS stamp of 0 means '
                           '"now"); use --start-time instead', EXIT_USAGE)
    else:
        if not (math.isfinite(args.start_time) and 0 < args.start_time < 2 ** 31 - 3600):
            raise BagError(f'--start-time must be in (0, 2^31) seconds, got {args.start_time}',
                           EXIT_USAGE)
        t0 = int(round(args.start_time * 1e9))
        stamps = t[keep] - t[keep][0] + t0
    src = args.recording
    custom = {'hair_tracking.import.source': os.path.basename(src),
              'hair_tracking.import.how': note}
    out = bag_io.write_head_pose_bag(
        args.output, stamps, motion.position[keep], motion.quaternion[keep], kind=args.message,
        topic=args.topic, frame_id=args.frame_id, child_frame_id=args.child_frame_id,
        storage=args.storage, overwrite=args.overwrite, custom_data=custom,
        compress=args.compress)
    n = int(keep.sum())
    dur = (stamps[-1] - stamps[0]) * 1e-9
    dropped = {k: v for k, v in (motion.dropped or {}).items() if v}
    print(f'imported {src}: {note}')
    print(f'  {n} poses, {dur:.3f} s'
          + (f', median rate {1e9 / np.median(np.diff(stamps)):.1f} Hz' if n > 1 else '')
          + (f'; rows dropped: {dropped}' if dropped else ''))
    topic = args.topic or POSE_KIND_TOPICS[args.message]
    print(f'wrote {out} ({args.message} on {topic}, frame {args.frame_id!r}'
          + (f' -> {args.child_frame_id!r}' if args.message != 'pose' else '') + ')')
    return EXIT_OK


# ================================================================ run
def cmd_run(args) -> int:
    from hair_tracking.bags import io as bag_io
    from hair_tracking.bags.offline import (load_settings, parse_overrides, Progress, run_bag,
                                            RunOptions)

    _check_seconds(args.start_offset, '--start-offset')
    _check_seconds(args.duration, '--duration', positive=True)
    src = args.bag or bag_io.bundled_bag()
    bag_io.check_output_path(args.output, args.overwrite)
    bag_io.output_storage(args.output, args.storage)
    bag_io.bag_kind(src)
    settings = load_settings(args.scene, args.params, parse_overrides(args.set or []))
    if args.threads is not None:
        import numba
        most = numba.config.NUMBA_NUM_THREADS
        if not 1 <= args.threads <= most:
            raise BagError(f'--threads must be in [1, {most}], got {args.threads}', EXIT_USAGE)
        numba.set_num_threads(args.threads)
    opts = RunOptions(topic=args.topic, head_frame=args.head_frame, fixed_frame=args.fixed_frame,
                      start_offset_s=args.start_offset, duration_s=args.duration,
                      storage=args.storage, overwrite=args.overwrite, compress=args.compress,
                      points=not args.no_points, markers=not args.no_markers,
                      diagnostics=not args.no_diagnostics, head_pose=not args.no_head_pose,
                      every_pose=args.every_pose)
    bar = None

    def progress(done, total):
        nonlocal bar
        if args.quiet:
            return
        if bar is None:
            bar = Progress(total, label='run')
        bar.update(done)

    def set_up():
        if not args.quiet:
            print(f'running {src} -> {args.output} (Ctrl-C to stop; the bag is closed as it '
                  f'is)', file=sys.stderr, flush=True)
        if args.gc_freeze:
            executable.freeze_heap()

    try:
        summary = run_bag(src, args.output, settings, opts, progress, after_setup=set_up,
                          should_stop=lambda: args.stop.requested)
    finally:
        if bar is not None:
            bar.close()
    print(summary.text())
    return EXIT_OK if summary.finite else EXIT_FAILURE


# ================================================================ play / record / render
def cmd_play(args) -> int:
    from hair_tracking.bags.play import main_play
    return main_play(args)


def cmd_record(args) -> int:
    from hair_tracking.bags.record import main_record
    return main_record(args)


def cmd_render(args) -> int:
    from hair_tracking.bags.render import main_render
    return main_render(args)


# ================================================================ parser
def build_parser() -> argparse.ArgumentParser:
    ap = _Parser(prog='hair_sim_bag', description=__doc__.split('\n')[0],
                 epilog='Exit codes: 0 ok (also when stopped by Ctrl-C / SIGTERM), 1 run '
                        'failed, 2 usage, 3 bad input bag/file, 4 missing topic/frame, 5 output '
                        'exists/unwritable. Guide: docs/bags.md')
    sub = ap.add_subparsers(dest='command', metavar='COMMAND', parser_class=_Parser)
    sub.required = True

    # ---- info
    p = sub.add_parser('info', help='topics, types, counts and duration of a bag')
    p.add_argument('bag', nargs='?', help='bag (default: the bundled walk sample)')
    p.set_defaults(func=cmd_info)

    # ---- import
    p = sub.add_parser('import', help='BVH / pose table -> head-pose bag',
                       description='Turn a head-motion recording into a head-pose bag. BVH: '
                       'the chosen joint by forward kinematics, units to metres, BVH y-up to '
                       'REP-103 z-up, head axes x forward / y left / z up. Tables: CSV or '
                       'whitespace text with a header line naming the columns.')
    p.add_argument('recording', help='a .bvh file or a pose table (.csv/.txt)')
    p.add_argument('-o', '--output', required=True,
                   help='bag to create: NAME.mcap / NAME.db3 (one file) or a folder name')
    p.add_argument('--format', choices=('auto', 'bvh', 'table'), default='auto',
                   help='input format (auto: .bvh is BVH, anything else a table)')
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
    g.add_argument('--time-unit', choices=('s', 'ms', 'us', 'ns'), default='s')
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
    g = p.add_argument_group('time')
    g.add_argument('--start', type=float, default=0.0,
                   help='skip this many seconds of the recording')
    g.add_argument('--duration', type=float, help='keep this many seconds')
    g.add_argument('--start-time', type=float, default=DEFAULT_START_TIME_S,
                   help='stamp of the first pose, seconds since the epoch (default 1e9: '
                        'reproducible and non-zero)')
    g.add_argument('--keep-times', action='store_true',
                   help="keep the recording's own times as stamps instead")
    g = p.add_argument_group('output')
    g.add_argument('--message', choices=POSE_KINDS, default='pose',
                   help='pose: PoseStamped on /head_pose (default); transform: '
                        'TransformStamped on /head_transform; tf: tf2_msgs/TFMessage on /tf '
                        '(the hair_sim node\'s input topics: pose and transform bags play into '
                        'it without remapping, tf ones with use_tf:=true)')
    g.add_argument('--topic', help='topic name (default: /head_pose, /head_transform or /tf '
                                   'by --message)')
    g.add_argument('--frame-id', default='world', help='fixed frame (default world)')
    g.add_argument('--child-frame-id', default='head', help='head frame (default head)')
    g.add_argument('--storage', choices=STORAGES,
                   help='mcap (default) or sqlite3 (a .mcap/.db3 name decides by itself)')
    g.add_argument('--compress', action='store_true', help='zstd-compress (MCAP chunks)')
    g.add_argument('--overwrite', action='store_true', help='replace an existing output')
    p.set_defaults(func=cmd_import)

    # ---- run
    p = sub.add_parser('run', help='offline: head poses in a bag -> hair -> output bag',
                       description='Simulate the hair at the recorded timestamps and write '
                       '/hair/points (PointCloud2), /hair/markers (MarkerArray), /diagnostics '
                       'and the /head_pose used, as the hair_sim node would publish them.')
    p.add_argument('bag', nargs='?', help='input bag (default: the bundled walk sample)')
    p.add_argument('-o', '--output', required=True,
                   help='output bag: NAME.mcap / NAME.db3 (one file) or a folder name')
    p.add_argument('--scene', help='scene YAML or preset name (e.g. long_hair)')
    p.add_argument('--params', help="the node's ROS 2 params file (hair_sim: ros__parameters)")
    p.add_argument('--set', action='append', metavar='NAME=VALUE',
                   help='override a parameter, e.g. --set groom.guides=16 (repeatable)')
    p.add_argument('--topic', help='head-pose topic (default: found automatically)')
    p.add_argument('--head-frame', help='TF / TransformStamped child frame that is the head')
    p.add_argument('--fixed-frame',
                   help='compose static TF from this frame down to the head\'s parent')
    p.add_argument('--start-offset', type=float, default=0.0,
                   help='skip this many seconds from the bag start')
    p.add_argument('--duration', type=float, help='use this many seconds of the bag')
    p.add_argument('--storage', choices=STORAGES, help='mcap (default) or sqlite3')
    p.add_argument('--compress', action='store_true', help='zstd-compress (MCAP chunks)')
    p.add_argument('--threads', type=int,
                   help='numba threads for the simulation (default: all cores; 1 is often '
                        'faster for small scenes or on a busy machine)')
    p.add_argument('--every-pose', action='store_true',
                   help='write a hair frame after every pose (default: publish_rate_hz)')
    p.add_argument('--no-points', action='store_true', help='do not write /hair/points')
    p.add_argument('--no-markers', action='store_true', help='do not write /hair/markers')
    p.add_argument('--no-diagnostics', action='store_true', help='do not write /diagnostics')
    p.add_argument('--no-head-pose', action='store_true', help='do not copy /head_pose')
    p.add_argument('--overwrite', action='store_true', help='replace an existing output')
    p.add_argument('-q', '--quiet', action='store_true', help='no progress bar')
    executable.add_arguments(p)
    p.set_defaults(func=cmd_run)

    # ---- play
    p = sub.add_parser('play', help='publish a bag live with /clock (ros2 bag play --clock)')
    p.add_argument('bag', nargs='?', help='bag (default: the bundled walk sample)')
    p.add_argument('-r', '--rate', type=float, default=1.0, help='playback speed factor')
    p.add_argument('-l', '--loop', action='store_true', help='play again and again (Ctrl-C)')
    p.add_argument('--start-offset', type=float, default=0.0,
                   help='start this many seconds into the bag')
    p.add_argument('--duration', type=float, help='play this many seconds of the bag')
    p.add_argument('--topics', nargs='+', metavar='TOPIC', help='play only these topics')
    p.add_argument('--remap', nargs='+', default=[], metavar='FROM:=TO',
                   help='rename topics, e.g. --remap /head_pose:=/face/pose')
    p.add_argument('--no-clock', action='store_true', help='do not publish /clock')
    p.add_argument('--wait-for-subscribers', type=float, default=2.0, metavar='SECONDS',
                   help='wait up to this long for every topic to have a subscriber (default 2)')
    p.add_argument('--delay', type=float, default=0.0, help='sleep this long before playing')
    p.add_argument('--domain-id', type=int, help='ROS_DOMAIN_ID to use')
    p.add_argument('-q', '--quiet', action='store_true', help='no progress line')
    executable.add_arguments(p, omp_wait_policy=None, gc_freeze=False)
    p.set_defaults(func=cmd_play)

    # ---- record
    p = sub.add_parser('record', help='subscribe to topics (raw) and write a bag')
    p.add_argument('topics', nargs='*', metavar='TOPIC', help='topics to record')
    p.add_argument('-a', '--all', action='store_true', help='record every topic that appears')
    p.add_argument('-o', '--output', required=True,
                   help='bag to create: NAME.mcap / NAME.db3 or a folder name')
    p.add_argument('--storage', choices=STORAGES, help='mcap (default) or sqlite3')
    p.add_argument('--compress', action='store_true', help='zstd-compress (MCAP chunks)')
    p.add_argument('--duration', type=float, help='stop after this many seconds')
    p.add_argument('--max-messages', type=int, help='stop after this many messages')
    p.add_argument('--idle-timeout', type=float,
                   help='stop when nothing arrived for this many seconds (after the first '
                        'message)')
    p.add_argument('--use-sim-time', action='store_true',
                   help='log messages at /clock time instead of the wall clock')
    p.add_argument('--domain-id', type=int, help='ROS_DOMAIN_ID to use')
    p.add_argument('--overwrite', action='store_true', help='replace an existing output')
    p.add_argument('-q', '--quiet', action='store_true', help='no progress line')
    executable.add_arguments(p, omp_wait_policy=None, gc_freeze=False)
    p.set_defaults(func=cmd_record)

    # ---- render
    p = sub.add_parser('render', help='pictures of an output bag: GIF/PNG + diagnostics plot')
    p.add_argument('bag', help='a bag written by run or record')
    p.add_argument('-o', '--output', required=True, help='folder to create for the pictures')
    p.add_argument('--gif', action='store_true', help='an animated GIF (hair.gif)')
    p.add_argument('--png', action='store_true', help='PNG frames (frames/frame_NNNNN.png)')
    p.add_argument('--fps', type=float, default=10.0, help='frames per second of the pictures')
    p.add_argument('--max-frames', type=int, default=120, help='at most this many pictures')
    p.add_argument('--max-strands', type=int, default=600, help='draw at most this many strands')
    p.add_argument('--view', choices=('side', 'front', 'top', 'both'), default='both',
                   help='side (x-z), front (y-z), top (x-y) or both side and front')
    p.add_argument('--frame', choices=('head', 'world'), default='head',
                   help='draw in the head frame (default; needs /head_pose) or the world frame')
    p.add_argument('--topic', help='hair topic (default /hair/points, else /hair/markers)')
    p.add_argument('--overwrite', action='store_true', help='replace an existing output')
    p.set_defaults(func=cmd_render)
    return ap


#: Commands that run plain Python and numba, writing under a temporary name: a stop request
#: interrupts them anywhere (the others check it between messages or poses)
INTERRUPTIBLE = ('info', 'import', 'render')


def main(argv: Optional[List[str]] = None) -> int:
    """Console entry point ``hair_sim_bag``; returns the exit code (see module doc)."""
    parser = build_parser()
    args = parser.parse_args(argv)
    with executable.started() as stop:
        args.stop = stop
        try:
            if hasattr(args, 'malloc_retain_mb'):       # run, play, record: process settings
                try:
                    executable.apply(args)
                except ValueError as e:
                    raise BagError(str(e), EXIT_USAGE) from None
            if args.command in INTERRUPTIBLE:
                with stop.interruptible():
                    return int(args.func(args) or 0)
            return int(args.func(args) or 0)
        except BagError as exc:
            print(f'hair_sim_bag {args.command}: error: {exc}', file=sys.stderr)
            return exc.code
        except KeyboardInterrupt:                       # a stop inside an interruptible command
            print(f'hair_sim_bag {args.command}: stopped ({stop.signal_name}), nothing written',
                  file=sys.stderr)
            return EXIT_OK
        except BrokenPipeError:
            return EXIT_OK
        except OSError as exc:
            where = f' ({exc.filename})' if getattr(exc, 'filename', None) else ''
            print(f'hair_sim_bag {args.command}: error: {exc.strerror or exc}{where}',
                  file=sys.stderr)
            return EXIT_OUTPUT if isinstance(exc, (PermissionError, IsADirectoryError)) \
                or getattr(exc, 'errno', None) == 28 else EXIT_FAILURE
        except Exception as exc:       # noqa: B902 - a user sees one line, never a traceback
            if os.environ.get('HAIR_SIM_BAG_DEBUG'):
                raise
            print(f'hair_sim_bag {args.command}: error: {type(exc).__name__}: {exc} '
                  f'(set HAIR_SIM_BAG_DEBUG=1 for the traceback)', file=sys.stderr)
            return EXIT_FAILURE


if __name__ == '__main__':
    sys.exit(main())
