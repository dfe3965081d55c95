"""``hair_sim_bag``: record a head-pose stream once, run the hair on it many times.

Sub-commands (``hair_sim_bag <command> --help`` for every option; guide: docs/bags.md)::

    info    [BAG]                 topics, types, counts and duration of a bag
    import  RECORDING -o BAG      BVH motion capture, a pose table or a bag -> head-pose bag
    run     [BAG] -o OUT          offline: head poses -> hair -> markers, cloud, diagnostics
    recover BAG OUT               a clean copy (an MCAP cut short: to its last whole message)
    play    [BAG]                 publish a bag live with /clock (like ros2 bag play --clock)
    record  TOPIC... -o OUT       subscribe (raw) and write a bag (like ros2 bag record)
    render  BAG -o DIR            PNG frames / animated GIF of the hair + a diagnostics plot
    export  BAG -o OUT.usda       the hair as an animated USD BasisCurves file (usd-core)

``BAG`` defaults to the bundled sample (CMU 131_01 walk head poses).  Bags are rosbag2
directories or single ``.mcap``/``.db3`` files (ROS 1 ``.bag`` too, for reading); no ROS
installation is needed for info/import/run/recover/render/export.  This module holds those and
the parser (export: :mod:`hair_tracking.bags.export`); ``play`` and ``record`` join a ROS graph
and live in :mod:`hair_tracking.ros.bag_play` and :mod:`hair_tracking.ros.bag_record`, which the
executable (:mod:`hair_tracking.ros.bag_cli`) adds.

Exit codes: 0 success, or stopped by SIGINT (Ctrl-C) or SIGTERM (run and record close their
output bag as it is, a complete bag; import, recover, render and export leave nothing); 1 the run
failed, 2 bad command line, 3 input missing/not a bag/corrupt, 4 the bag lacks what was asked
for (no head-pose topic, unknown frame), 5 output exists or cannot be written.  Errors are one
line on stderr, never a traceback.
"""
import argparse
import math
import os
import sys
from typing import Callable, List, Optional, Sequence

import numpy as np

from hair_tracking import executable
from hair_tracking.bags import export, recording
from hair_tracking.bags.io import (BagError, EXIT_CONTENT, EXIT_FAILURE, EXIT_INPUT, EXIT_OK,
                                   EXIT_OUTPUT, EXIT_USAGE, POSE_KIND_TOPICS, POSE_KINDS,
                                   STORAGES)
from hair_tracking.grooms.polylines import GroomFileError

#: seconds since the epoch given to the first sample of an import (reproducible, non-zero:
#: a stamp of 0 means "now" to the node); 1e9 s is 2001-09-09T01:46:40Z.
DEFAULT_START_TIME_S = 1_000_000_000.0


class _Parser(argparse.ArgumentParser):
    """argparse that reports errors as 'hair_sim_bag: error: ...' with exit code 2."""

    def error(self, message):
        self.print_usage(sys.stderr)
        self.exit(EXIT_USAGE, f'{self.prog}: error: {message}\n')


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
def cmd_import(args) -> int:
    from hair_tracking.bags import io as bag_io
    _check_seconds(args.start, '--start')
    _check_seconds(args.duration, '--duration', positive=True)
    bag_io.check_output_path(args.output, args.overwrite)
    bag_io.output_storage(args.output, args.storage)
    motion, note = recording.load_recording(args.recording, args)
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
    from hair_tracking.bags.offline import (load_settings, parse_overrides, progress_bar,
                                            run_bag, RunOptions)

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
    progress, close = progress_bar('run', args.quiet)

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
        close()
    print(summary.text())
    return EXIT_OK if summary.finite else EXIT_FAILURE


# ================================================================ recover
def cmd_recover(args) -> int:
    from hair_tracking.bags import io as bag_io
    if (args.output is None) == (args.output_option is None):
        raise BagError('give the output bag once: hair_sim_bag recover IN OUT (or -o OUT)',
                       EXIT_USAGE)
    output = args.output or args.output_option
    bag_io.check_output_path(output, args.overwrite)
    bag_io.output_storage(output, args.storage)
    counts = bag_io.copy_bag(args.bag, output, storage=args.storage, compress=args.compress,
                             overwrite=args.overwrite)
    print(f'wrote {output}: {sum(counts.values())} messages')
    for topic, n in sorted(counts.items()):
        print(f'  {topic}: {n}')
    return EXIT_OK


# ================================================================ render
def cmd_render(args) -> int:
    from hair_tracking.bags.render import main_render
    return main_render(args)


# ================================================================ parser
def finish_parser(p, func: Callable[[argparse.Namespace], int], quiet_help: str,
                  omp_wait_policy: Optional[str] = None, gc_freeze: bool = False) -> None:
    """The end of a sub-command that runs a while: ``-q`` (``quiet_help``), the process-wide
    settings (:func:`hair_tracking.executable.add_arguments`: ``omp_wait_policy`` and
    ``gc_freeze`` for one that runs the numba kernels) and ``func`` to run it."""
    p.add_argument('-q', '--quiet', action='store_true', help=quiet_help)
    executable.add_arguments(p, omp_wait_policy=omp_wait_policy, gc_freeze=gc_freeze)
    p.set_defaults(func=func)


def build_parser(live: Sequence[Callable] = ()) -> argparse.ArgumentParser:
    """The ``hair_sim_bag`` parser; each of ``live`` adds a sub-command to the sub-parsers it is
    given (``play``, ``record``: :mod:`hair_tracking.ros.bag_cli`)."""
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
    p = sub.add_parser('import', help='BVH / pose table / bag -> head-pose bag',
                       description='Turn a head-motion recording into a head-pose bag. BVH: '
                       'the chosen joint by forward kinematics, units to metres, BVH y-up to '
                       'REP-103 z-up, head axes x forward / y left / z up. Tables: CSV or '
                       'whitespace text with a header line naming the columns. Bags: the '
                       'head-pose stream run would read.')
    p.add_argument('recording', help='a .bvh file, a pose table (.csv/.txt) or a bag')
    p.add_argument('-o', '--output', required=True,
                   help='bag to create: NAME.mcap / NAME.db3 (one file) or a folder name')
    recording.add_arguments(p)
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
    for name, topic in (('points', '/hair/points'), ('markers', '/hair/markers'),
                        ('diagnostics', '/diagnostics')):
        p.add_argument(f'--no-{name}', action='store_true', help=f'do not write {topic}')
    p.add_argument('--no-head-pose', action='store_true', help='do not copy /head_pose')
    p.add_argument('--overwrite', action='store_true', help='replace an existing output')
    finish_parser(p, cmd_run, 'no progress bar', omp_wait_policy='passive', gc_freeze=True)

    # ---- recover
    p = sub.add_parser('recover', help='a clean copy of a bag, an MCAP cut short read to its '
                                       'last whole message',
                       description='Write every message of a bag into a new one. An MCAP file '
                       'a recorder left cut short (no summary, no end magic) is read to its '
                       'last whole message; the copy is a whole, indexed bag.')
    p.add_argument('bag', help='the bag to copy')
    p.add_argument('output', nargs='?',
                   help='bag to create: NAME.mcap / NAME.db3 (one file) or a folder name')
    p.add_argument('-o', dest='output_option', metavar='OUTPUT', help='the same as OUTPUT')
    p.add_argument('--storage', choices=STORAGES,
                   help='mcap (default) or sqlite3 (a .mcap/.db3 name decides by itself)')
    p.add_argument('--compress', action='store_true', help='zstd-compress (MCAP chunks)')
    p.add_argument('--overwrite', action='store_true', help='replace an existing output')
    p.set_defaults(func=cmd_recover)

    # ---- play, record: they join a ROS graph (hair_tracking.ros.bag_cli puts them in)
    for add in live:
        add(sub)

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

    # ---- export
    export.add_command(sub, finish_parser)
    return ap


#: Commands that run plain Python and numba, writing their output under a temporary name: a
#: stop request interrupts them anywhere (the others check it between messages or poses)
INTERRUPTIBLE = ('info', 'import', 'recover', 'render', 'export')


def run_command(prog: str, args, interruptible: bool) -> int:
    """``args.func(args)``, the sub-command ``args.command`` of ``prog``, and its exit code (see
    module doc): an error is one line on stderr, never a traceback; inside ``interruptible``
    work a stop request (``args.stop``) interrupts it anywhere, exit code 0, nothing written.
    ``hair_sim_bag`` and ``hair_sim_groom`` run their commands so."""
    stop = args.stop
    try:
        if interruptible:
            with stop.interruptible():
                return int(args.func(args) or 0)
        return int(args.func(args) or 0)
    except BagError as exc:
        print(f'{prog} {args.command}: error: {exc}', file=sys.stderr)
        return exc.code
    except GroomFileError as exc:
        print(f'{prog} {args.command}: error: {exc}', file=sys.stderr)
        return EXIT_INPUT
    except KeyboardInterrupt:                       # a stop inside an interruptible command
        print(f'{prog} {args.command}: stopped ({stop.signal_name}), nothing written',
              file=sys.stderr)
        return EXIT_OK
    except BrokenPipeError:
        return EXIT_OK
    except OSError as exc:
        where = f' ({exc.filename})' if getattr(exc, 'filename', None) else ''
        print(f'{prog} {args.command}: error: {exc.strerror or exc}{where}', file=sys.stderr)
        return EXIT_OUTPUT if isinstance(exc, (PermissionError, IsADirectoryError)) \
            or getattr(exc, 'errno', None) == 28 else EXIT_FAILURE
    except Exception as exc:       # noqa: B902 - a user sees one line, never a traceback
        if os.environ.get('HAIR_SIM_BAG_DEBUG'):
            raise
        print(f'{prog} {args.command}: error: {type(exc).__name__}: {exc} '
              f'(set HAIR_SIM_BAG_DEBUG=1 for the traceback)', file=sys.stderr)
        return EXIT_FAILURE


def main(argv: Optional[List[str]] = None, live: Sequence[Callable] = ()) -> int:
    """``hair_sim_bag`` with the sub-commands ``live`` adds (see :func:`build_parser`); returns
    the exit code (see module doc).  The executable is :mod:`hair_tracking.ros.bag_cli`; each
    command finds the process's stop request in ``args.stop``."""
    parser = build_parser(live)
    args = parser.parse_args(argv)
    with executable.started() as stop:
        args.stop = stop
        if hasattr(args, 'malloc_retain_mb'):       # run, play, record: process settings
            try:
                executable.apply(args)
            except ValueError as e:
                print(f'hair_sim_bag {args.command}: error: {e}', file=sys.stderr)
                return EXIT_USAGE
        return run_command('hair_sim_bag', args, args.command in INTERRUPTIBLE)
