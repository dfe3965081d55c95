"""``make demo``: the whole live pipeline over real DDS on this machine, ending by itself.

    python -m hair_tracking.ros.live_demo [--out out/demo] [--bag BAG] [--rate 1.0]

1. starts the ``hair_sim`` node as its own process with ``use_sim_time:=true``
   (``python -m hair_tracking.ros.node --ros-args ...``) and waits until it subscribes;
2. records the node's output (``/hair/points``, ``/diagnostics``, the head marker
   ``/hair/head`` and the ``/head_pose`` it is fed; ``--markers`` adds ``/hair/markers``) into
   ``OUT/hair_output.mcap``, logging at ``/clock`` time;
3. plays the bundled head-pose bag (CMU 131_01 walk, 8.3 s) into it with ``/clock`` before
   each message, paced by the wall clock;
4. stops the node with SIGINT (SIGTERM and then SIGKILL only as fallbacks for a node that
   does not stop, each said), renders ``OUT/pictures/`` (``hair.gif``, ``hair.png``,
   ``diagnostics.png``) from the recording, and prints a summary: frames, rate, the node's
   step times, stretch, penetration, rejected poses.

SIGINT (Ctrl-C) or SIGTERM stops it at any step: the recording is closed as it is, the node
stopped, nothing rendered, exit code 0.

Everything stays on this machine (``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``) on its own
domain id (``--domain-id``, else ``$HAIR_DEMO_DOMAIN_ID``, else 88).  Exit code 0 when hair
frames came back and were finite, 1 otherwise (the node's log is then printed).
"""
import argparse
import os
from pathlib import Path
import signal
import subprocess
import sys
import threading
import time
from typing import Dict, List, Optional

import numpy as np

from hair_tracking import executable
from hair_tracking.bags import io as bag_io
from hair_tracking.bags.io import BagError

DEFAULT_DOMAIN = 88
NODE_READY_TIMEOUT_S = 120.0      # first start may compile every numba kernel
DRAIN_S = 1.5                     # keep recording this long after the last message played
STOP_WAIT_S = 10.0                # how long the node may take to exit after each signal


def _log(text: str) -> None:
    print(f'[demo] {text}', flush=True)


def start_node(domain: int, log_path: Path, params: List[str], threads: Optional[int]):
    """The hair_sim node as a subprocess (its stdout/stderr go to ``log_path``)."""
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain), PYTHONUNBUFFERED='1')
    env.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    if threads:
        env['NUMBA_NUM_THREADS'] = str(threads)
    root = str(Path(__file__).resolve().parents[2])     # the folder holding hair_tracking/
    env['PYTHONPATH'] = root + (os.pathsep + env['PYTHONPATH'] if env.get('PYTHONPATH') else '')
    cmd = [sys.executable, '-m', 'hair_tracking.ros.node', '--ros-args',
           '-p', 'use_sim_time:=true']
    for p in params:
        cmd += ['-p', p]
    log = open(log_path, 'w', encoding='utf-8')
    proc = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, env=env,
                            start_new_session=True)
    return proc, log


def _wait(proc, sig, timeout: float) -> None:
    """Wait up to ``timeout`` seconds for ``proc`` to end after ``sig``."""
    try:
        proc.wait(timeout)
    except subprocess.TimeoutExpired:
        pass


def stop_node(proc, timeout: float = STOP_WAIT_S, log=_log, wait=_wait) -> int:
    """Stop the node as a user would: SIGINT (Ctrl-C; the node stops at once however it waits,
    :mod:`hair_tracking.shutdown`).  Fallbacks for a process that does not stop within
    ``timeout`` seconds (``wait(proc, signal, timeout)`` waits; a test injects its own):
    SIGTERM, then SIGKILL as the last resort; each escalation is logged.  Returns the node's
    exit code."""
    for sig in (signal.SIGINT, signal.SIGTERM):
        if proc.poll() is not None:
            break
        if sig != signal.SIGINT:
            log(f'the node did not stop within {timeout:g} s of SIGINT: sending SIGTERM')
        proc.send_signal(sig)
        wait(proc, sig, timeout)
    if proc.poll() is None:
        log(f'the node did not stop within {timeout:g} s of SIGTERM either: killing it (SIGKILL)')
        proc.kill()
        proc.wait(timeout)
    return proc.returncode


def _last_diagnostics(path) -> Dict[str, str]:
    ts = bag_io.typestore()
    last: Dict[str, str] = {}
    with bag_io.open_bag(path) as r:
        conns = [c for c in r.connections if c.topic == '/diagnostics']
        for _, _, raw in bag_io.messages(r, conns):
            msg = ts.deserialize_cdr(raw, 'diagnostic_msgs/msg/DiagnosticArray')
            for st in msg.status:
                if 'hair' in st.name:
                    last = {kv.key: kv.value for kv in st.values}
                    last['_level'] = str(int(st.level))
                    last['_message'] = st.message
    return last


def _frames(path):
    """(distinct stamps [ns], messages, all finite) of /hair/points in a recording."""
    # imported here: it loads numba, whose cache folder main() sets first
    from msg_adapters.pointcloud import pointcloud2_to_strands
    stamps, n, finite, shape = [], 0, True, None
    for t, msg in bag_io.cloud_messages(path):
        n += 1
        if not stamps or stamps[-1] != t:
            stamps.append(t)
            pts = pointcloud2_to_strands(msg)[0]
            finite = finite and bool(np.all(np.isfinite(pts)))
            shape = pts.shape
    return stamps, n, finite, shape


def run_demo(args, stop) -> int:
    """The demo (module doc); ``stop`` the process's stop request."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter
    from rclpy.signals import SignalHandlerOptions

    from hair_tracking.bags.render import render
    from hair_tracking.ros.bag_play import BagPlayer
    from hair_tracking.ros.bag_record import BagRecorder

    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    bag = args.bag or bag_io.bundled_bag()
    info = bag_io.bag_info(bag)
    output = out / 'hair_output.mcap'
    pictures = out / 'pictures'
    for old in (output, pictures):
        if old.exists():
            bag_io.remove_path(old)
    domain = args.domain_id
    if domain is None:
        domain = int(os.environ.get('HAIR_DEMO_DOMAIN_ID', DEFAULT_DOMAIN))
    _log(f'input: {bag} ({info["duration_s"]:.2f} s, {info["messages"]} messages)')
    _log(f'domain id {domain}, discovery {os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"]}')

    t_start = time.monotonic()
    node_log = out / 'node.log'
    proc, log_fh = start_node(domain, node_log, args.param or [], args.node_threads)
    _log(f'started hair_sim (pid {proc.pid}, log {node_log})')
    rclpy.init(args=None, domain_id=domain, signal_handler_options=SignalHandlerOptions.NO)
    rec_node = play_node = player = recorder = None
    ok = False
    try:
        sim_time = Parameter('use_sim_time', Parameter.Type.BOOL, True)
        rec_node = rclpy.create_node('hair_demo_recorder', parameter_overrides=[sim_time])
        play_node = rclpy.create_node('hair_demo_player')
        topics = ['/hair/points', '/diagnostics', '/head_pose', '/hair/head']
        if args.markers:
            topics.append('/hair/markers')
        player = BagPlayer(play_node, bag, rate=args.rate, duration_s=args.duration,
                           log=_log)
        stop.on_request(player.stop)
        recorder = BagRecorder(rec_node, output, topics, log=_log)
        ex = SingleThreadedExecutor()
        ex.add_node(rec_node)

        def spin_until(cond, timeout):
            end = time.monotonic() + timeout
            while not cond() and time.monotonic() < end and not stop.requested:
                if proc.poll() is not None:
                    return False
                ex.spin_once(timeout_sec=0.05)
            return cond()

        ready = spin_until(lambda: play_node.count_subscribers('/head_pose') > 0
                           and not recorder.missing(), NODE_READY_TIMEOUT_S)
        if stop.requested:
            recorder.close()
            return 0                     # the node is stopped below
        if not ready:
            why = ('the node exited' if proc.poll() is not None
                   else f'not ready after {NODE_READY_TIMEOUT_S:.0f} s')
            raise RuntimeError(f'hair_sim did not come up ({why}); missing: '
                               f'{recorder.missing() or "-"}')
        _log(f'node ready after {time.monotonic() - t_start:.1f} s; recording '
             f'{", ".join(topics)}')
        lonely = player.wait_for_subscribers(10.0)
        if lonely:
            _log(f'warning: no subscriber on {", ".join(lonely)}')
        result = {}
        th = threading.Thread(target=lambda: result.update(stats=player.play()), daemon=True)
        t_play = time.monotonic()
        th.start()
        _log(f'playing at rate {args.rate:g} with /clock ...')
        spin_until(lambda: not th.is_alive(), info['duration_s'] / args.rate * 3 + 30)
        player.stop()
        th.join(5)
        spin_until(lambda: False, DRAIN_S)
        play_wall = time.monotonic() - t_play
        recorder.close()
        stats = result.get('stats')
        _log(f'played {sum(stats.published.values()) if stats else "?"} messages in '
             f'{play_wall:.1f} s')
        ok = True
    except (RuntimeError, BagError) as exc:
        _log(f'FAILED: {exc}')
        if recorder is not None:
            recorder.abort()
    finally:
        if player is not None:
            player.destroy()
        for n in (rec_node, play_node):
            if n is not None:
                n.destroy_node()
        rclpy.try_shutdown()
        code = stop_node(proc)
        log_fh.close()
        if stop.requested:
            _log(f'{stop.signal_name}: stopped; {output} holds what was recorded')
    if stop.requested:
        return 0
    if not ok:
        _print_log_tail(node_log)
        return 1
    _log(f'node stopped (exit code {code})')

    stamps, n_msgs, finite, shape = _frames(output)
    if not stamps:
        _log('FAILED: no hair frame was recorded')
        _print_log_tail(node_log)
        return 1
    t_render = time.monotonic()
    pics = render(output, pictures, gif=True, png=False, fps=args.fps,
                  max_frames=args.max_frames, overwrite=True)
    render_s = time.monotonic() - t_render
    diag = _last_diagnostics(output)
    span = (stamps[-1] - stamps[0]) * 1e-9
    rate = (len(stamps) - 1) / span if span > 0 else 0.0
    size_mb = output.stat().st_size / 1e6
    print()
    print('=== hair_tracking live demo ===')
    print(f'input        {bag}: {info["duration_s"]:.2f} s of head poses, played at rate '
          f'{args.rate:g} with /clock')
    if shape is not None:
        print(f'hair         {shape[0]} strands x {shape[1]} points per frame')
    print(f'output       {output} ({size_mb:.1f} MB): {len(stamps)} hair frames '
          f'({n_msgs} messages) over {span:.2f} s of sim time = {rate:.1f} Hz')
    print('             ' + ', '.join(f'{t}: {c}' for t, c in sorted(recorder.counts.items())))
    if diag:
        print(f'node         step {diag.get("step_ms_last", "?")} ms (max recent '
              f'{diag.get("step_ms_max_recent", "?")} ms), publish '
              f'{diag.get("publish_ms_last", "?")} ms; substeps {diag.get("substeps", "?")} '
              f'run, {diag.get("substeps_dropped", "?")} dropped')
        print(f'hair health  max stretch {float(diag.get("max_stretch", "nan")) * 100:.3f} %, '
              f'penetration {float(diag.get("penetration_m", "nan")) * 1e3:.2f} mm, '
              f'poses rejected {diag.get("poses_rejected", "?")}, '
              f'resets {diag.get("hair_resets", "?")}; status: {diag.get("_message", "?")}')
        dropped = int(float(diag.get('substeps_dropped', '0') or 0))
        if dropped:
            print(f'note         the node fell behind real time ({dropped} substeps dropped, '
                  f'hair kept up by sweeping each interval in at most solver.max_substeps); '
                  f'on a busy machine try --rate 0.5 or a smaller groom '
                  f'(--param groom.ghosts_per_guide:=4)')
    else:
        print('node         (no diagnostics recorded)')
    print(f'pictures     {pics.get("gif")}, {pics.get("png")}'
          + (f', {pics["diagnostics"]}' if 'diagnostics' in pics else '')
          + f' ({pics["frames"]} pictures, {render_s:.1f} s)')
    print(f'total        {time.monotonic() - t_start:.1f} s')
    if not finite:
        print('ERROR: non-finite hair in the recording')
        return 1
    return 0


def _print_log_tail(path: Path, lines: int = 30) -> None:
    try:
        text = path.read_text(encoding='utf-8', errors='replace').splitlines()
    except OSError:
        return
    print(f'--- last lines of {path} ---')
    for ln in text[-lines:]:
        print(ln)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog='python -m hair_tracking.ros.live_demo',
                                 description=__doc__.split('\n')[0])
    ap.add_argument('--out', default='out/demo', help='output folder (default out/demo)')
    ap.add_argument('--bag', help='head-pose bag to play (default: the bundled walk)')
    ap.add_argument('--rate', type=float, default=1.0, help='playback speed factor')
    ap.add_argument('--duration', type=float, help='play only this many seconds')
    ap.add_argument('--domain-id', type=int,
                    help=f'ROS domain id (default $HAIR_DEMO_DOMAIN_ID or {DEFAULT_DOMAIN})')
    ap.add_argument('--param', action='append', metavar='NAME:=VALUE',
                    help='a parameter for the node, e.g. groom.guides:=32 (repeatable)')
    ap.add_argument('--node-threads', type=int, default=1,
                    help='numba threads of the node (default 1: the demo shares a small '
                         'machine with its own player and recorder; 0 = numba default)')
    ap.add_argument('--markers', action='store_true', help='also record /hair/markers')
    ap.add_argument('--fps', type=float, default=10.0, help='pictures per second of the GIF')
    ap.add_argument('--max-frames', type=int, default=100, help='at most this many pictures')
    executable.add_arguments(ap, omp_wait_policy=None, gc_freeze=False)
    args = ap.parse_args(argv)
    if not args.rate > 0:
        ap.error('--rate must be > 0')
    with executable.started() as stop:
        try:
            executable.apply(args)        # the player and the recorder run in this process
        except ValueError as e:
            ap.error(str(e))
        try:
            return run_demo(args, stop)
        except BagError as exc:
            print(f'[demo] error: {exc}', file=sys.stderr)
            return exc.code


if __name__ == '__main__':
    sys.exit(main())
