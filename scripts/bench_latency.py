#!/usr/bin/env python3
"""Latency from a head-pose message to the published hair cloud, through DDS, in one process.

    python scripts/bench_latency.py [--ghosts 1000 10000] [--seconds 8] [--json out/lat.json]

For each ghost count and publishing mode a ``hair_sim`` node (:class:`HairSimNode`) and a probe
node share one rclpy context.  The probe publishes ``head_pose`` (PoseStamped, a moving and
turning head) at ``--pose-rate`` Hz from a thread of its own and subscribes to ``hair/points``
(raw CDR, so the probe does not pay for deserialising); the node spins in the main thread.
Latency of a pose = arrival time of the first cloud that shows it - the time the pose was
published.  Pose stamps sit on the simulator's substep grid, so each cloud's stamp is exactly
the stamp of the pose it answers; a pose without a cloud of its own (the node's pose queue keeps
only the newest, so a pose that comes while another waits replaces it; or the publishing rate
left it without a frame) is shown by the next cloud, stamped later, whose motion includes it.
Reported for every pose (``latency_every_pose``, the headline) and for the poses with a cloud
of their own (``latency``).

Modes: ``timer`` publishes on the node's own timer at ``--publish-rate`` Hz (the latency then
includes waiting for the next tick, up to one period); ``on_pose`` sets ``publish_on_pose`` so
a frame goes out right after its pose was simulated (rate still capped).  Also reported: the
node's own step time (simulation of one pose) and publish time (encoding + handing the bytes to
DDS), median and p99, and the cloud's size with the time of one single-threaded copy of its
bytes measured right after the case (the middleware copies each cloud at least three times
between the publish call and the probe's take, docs/node.md), and the garbage collector's
pauses (the full collections during the stream, and one made after it: what ``--no-gc-freeze``
leaves the node to walk; :class:`GcPauses`).  Goals: p99 latency of 8 ms at 10 k ghosts and
33 ms at 100 k.  Numbers depend on the machine; the JSON starts with its provenance (machine,
date, command: hair_tracking/evaluation/provenance.py).
"""
import argparse
import gc
import json
import os
import platform
import sys
import threading
import time

import numpy as np
import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, ReliabilityPolicy

from geometry_msgs.msg import PoseStamped
from sensor_msgs.msg import PointCloud2
from visualization_msgs.msg import MarkerArray

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from hair_tracking import executable  # noqa: E402

executable.use_numba_cache()    # before numba loads: the cache make install fills

from hair_tracking.output.settings import by_name  # noqa: E402
from hair_tracking.evaluation.provenance import command_line, provenance  # noqa: E402
from cpu_steal import format_share, StealMeter  # noqa: E402  (scripts/cpu_steal.py)
from hair_tracking.ros.node import HairSimNode  # noqa: E402
from msg_adapters.pose import pose_stamped_msg  # noqa: E402
from msg_adapters.stamps import time_to_ns  # noqa: E402
from rcl_take import SerializedTaker, SerializedWaiter  # noqa: E402  (scripts/rcl_take.py)

FRAME_MS = 1000.0 / 60.0


def groom_for(ghosts):
    """(guides, ghosts_per_guide) giving about ``ghosts`` ghost strands."""
    guides = 64 if ghosts <= 2048 else 128
    return guides, max(1, int(round(ghosts / guides)))


def _setting(text):
    """``NAME=VALUE`` -> (name, bool / int / float / str value) for a node parameter."""
    name, sep, value = text.partition('=')
    if not sep or not name:
        raise argparse.ArgumentTypeError(f'{text!r}: expected NAME=VALUE')
    if name not in by_name():     # rclpy ignores overrides of undeclared names silently
        raise argparse.ArgumentTypeError(f'{name!r} is not a parameter of the node '
                                         f'(NAME=VALUE, e.g. tracking.every_substep=false)')
    low = value.strip().lower()
    if low in ('true', 'false'):
        return name, low == 'true'
    for cast in (int, float):
        try:
            return name, cast(value)
        except ValueError:
            pass
    return name, value


def stats(values):
    a = np.asarray(values, dtype=float)
    if a.size == 0:
        return {'n': 0, 'median_ms': None, 'p90_ms': None, 'p99_ms': None, 'max_ms': None,
                'share_within_frame': None}
    return {'n': int(a.size), 'median_ms': float(np.median(a)),
            'p90_ms': float(np.percentile(a, 90)), 'p99_ms': float(np.percentile(a, 99)),
            'max_ms': float(a.max()), 'share_within_frame': float(np.mean(a < FRAME_MS))}


def shown_latency(sent, received, stamps):
    """Latency [ms] of each pose in ``stamps`` to the first cloud that shows it: the earliest
    arrival of a cloud stamped at or after the pose (``sent``/``received``: stamp -> time [s]).
    A pose the node never simulated on its own (its queue keeps only the newest, or the
    publishing rate left it without a frame) is shown by the next cloud, whose motion includes
    it; a pose no cloud followed is left out.  Returns (latencies, poses left out)."""
    clouds = np.array(sorted(received), dtype=np.int64)
    if clouds.size == 0:
        return [], len(stamps)
    arrival = np.array([received[c] for c in clouds.tolist()])
    first = np.minimum.accumulate(arrival[::-1])[::-1]     # earliest arrival from here on
    out, left = [], 0
    for t in stamps:
        i = int(np.searchsorted(clouds, t, side='left'))
        if i == clouds.size:
            left += 1
            continue
        out.append((first[i] - sent[t]) * 1e3)
    return out, left


def copy_ms(nbytes, reps=15):
    """Median time [ms] of one single-threaded copy of ``nbytes`` between warm buffers."""
    src = np.ones(nbytes, dtype=np.uint8)
    dst = np.zeros_like(src)
    np.copyto(dst, src)
    times = []
    for _ in range(reps):
        t0 = time.perf_counter()
        np.copyto(dst, src)
        times.append(time.perf_counter() - t0)
    return float(np.median(times)) * 1e3


def stamp_of(raw):
    """Header stamp [ns] of a serialized PointCloud2 (CDR: 4-byte header, int32 sec, uint32)."""
    sec = int.from_bytes(bytes(raw[4:8]), 'little', signed=True)
    nsec = int.from_bytes(bytes(raw[8:12]), 'little')
    return sec * 1_000_000_000 + nsec


class StageClock:
    """Per-pose timestamps (``time.perf_counter``) of the stages a pose goes through, keyed
    by its stamp: ``sent`` (the probe publishes it), ``callback`` / ``returned`` (the node's
    pose callback starts / ends), ``stepped`` (its simulation ends), ``encoded`` /
    ``published`` (the cloud written / handed to DDS, on pose), ``woken`` (the probe's wait
    returned), ``taken`` (the probe's take returned) and ``received`` (the probe's callback)."""

    def __init__(self):
        self.marks = {}
        self.current = None          # stamp of the pose the node's callback is handling

    def mark(self, stamp, stage, when=None):
        if stamp is not None:
            self.marks.setdefault(stamp, {}).setdefault(stage, when or time.perf_counter())

    def stages(self, stamps):
        """{stage: stats of its duration [ms]} over ``stamps``: pickup (sent -> callback),
        step, cloud (writing it), publish (the node's call), delivery (from the start of that
        call until the probe's take returned: DDS and the probe's wake-up and copy), probe_take
        (the take alone) and probe_callback; ``wait_after_busy`` is the time from the end of
        the previous pose's callback to the start of this one's when this pose arrived while
        the node was busy."""
        chain = [('pickup', 'sent', 'callback'), ('step', 'callback', 'stepped'),
                 ('cloud', 'stepped', 'encoded'), ('publish', 'encoded', 'published'),
                 # the probe wakes while the node's publish call still runs (the GIL is free
                 # then), so its part is timed from the start of that call
                 ('delivery', 'encoded', 'taken'), ('probe_take', 'woken', 'taken'),
                 ('probe_callback', 'taken', 'received')]
        out = {}
        for name, a, b in chain:
            out[name] = stats([(self.marks[t][b] - self.marks[t][a]) * 1e3 for t in stamps
                               if a in self.marks.get(t, {}) and b in self.marks[t]])
        busy = []
        for prev, t in zip(stamps, stamps[1:]):
            m0, m1 = self.marks.get(prev, {}), self.marks.get(t, {})
            if 'returned' in m0 and 'sent' in m1 and 'callback' in m1 and \
                    m0['returned'] > m1['sent']:
                busy.append((m1['callback'] - m0['returned']) * 1e3)
        out['wait_after_busy'] = stats(busy)
        out['share_arriving_busy'] = len(busy) / max(1, len(stamps) - 1)
        return out


class GcPauses:
    """The cyclic garbage collector's pauses while a case runs (``gc.callbacks``), per
    generation; a full (generation 2) collection walks every tracked object that is not frozen
    (``--no-gc-freeze`` leaves the start-up objects in its reach)."""

    def __init__(self):
        self.pauses = {0: [], 1: [], 2: []}
        self._start = None

    def __call__(self, phase, info):
        if phase == 'start':
            self._start = time.perf_counter()
        elif self._start is not None:
            self.pauses[info['generation']].append((time.perf_counter() - self._start) * 1e3)
            self._start = None

    def __enter__(self):
        gc.callbacks.append(self)
        return self

    def __exit__(self, *exc):
        gc.callbacks.remove(self)

    def summary(self):
        """{'gen0'..'gen2': {n, max_ms}} and ``full_ms``, one full collection made now."""
        out = {f'gen{g}': {'n': len(v), 'max_ms': max(v, default=0.0)}
               for g, v in self.pauses.items()}
        start = time.perf_counter()
        gc.collect()
        out['full_ms'] = (time.perf_counter() - start) * 1e3
        return out


def timed_node(clock):
    """A :class:`HairSimNode` subclass that marks its stages on ``clock``."""
    class TimedNode(HairSimNode):
        def _on_pose(self, msg):
            stamp = time_to_ns(msg.header.stamp)
            clock.current = stamp
            clock.mark(stamp, 'callback')
            try:
                super()._on_pose(msg)
            finally:
                clock.mark(stamp, 'returned')
                clock.current = None

        def _step(self, t_ns):
            super()._step(t_ns)
            clock.mark(clock.current, 'stepped')
    return TimedNode


def _marking(fn, clock, stage):
    def wrapped(*a, **k):
        out = fn(*a, **k)
        clock.mark(clock.current, stage)
        return out
    return wrapped


def run_case(ghosts, mode, args, domain_id):
    guides, per_guide = groom_for(ghosts)
    ctx = Context()
    rclpy.init(context=ctx, domain_id=domain_id)
    overrides = {
        'groom.guides': guides, 'groom.ghosts_per_guide': per_guide,
        'publish_rate_hz': float(args.publish_rate), 'publish_on_pose': mode == 'on_pose',
        'stale_timeout': 10.0, 'solver.type': args.solver, 'numba_threads': args.threads,
    }
    if args.pose_depth is not None:
        overrides['pose_queue_depth'] = args.pose_depth
    overrides.update(args.set)
    clock = StageClock()
    node_type = timed_node(clock) if args.stages else HairSimNode
    node = node_type(context=ctx, parameter_overrides=[
        Parameter(k, value=v) for k, v in overrides.items()])
    if args.gc_freeze:
        executable.freeze_heap()      # as hair_sim_node's main() does once set up
    probe = rclpy.create_node('bench_probe', context=ctx)
    sent, received = {}, {}
    lock = threading.Lock()
    cloud_bytes = [0]                   # the size of the last cloud taken

    def on_cloud(raw):
        now = time.perf_counter()
        t = stamp_of(raw)
        cloud_bytes[0] = len(raw)
        with lock:
            received.setdefault(t, now)
        if args.stages:
            clock.mark(t, 'received', now)
    qos = QoSProfile(depth=5, reliability=ReliabilityPolicy.RELIABLE)
    subs = {probe.create_subscription(PointCloud2, 'hair/points', on_cloud, qos, raw=True):
            on_cloud}
    if args.markers:
        subs[probe.create_subscription(MarkerArray, 'hair/markers', lambda raw: None, qos,
                                       raw=True)] = lambda raw: None
    pub = probe.create_publisher(PoseStamped, 'head_pose', qos)
    node_ex = SingleThreadedExecutor(context=ctx)
    node_ex.add_node(node)
    probe_ex = SingleThreadedExecutor(context=ctx)
    stop = threading.Event()
    takers = {}
    if args.probe == 'rcl':
        takers = {sub: SerializedTaker(sub, 4 << 20) for sub in subs}
        waiter = SerializedWaiter(ctx, subs)

        def spin_probe():
            while not stop.is_set() and ctx.ok():
                for sub in waiter.wait(0.05):
                    woken = time.perf_counter()
                    while (raw := takers[sub].take()) is not None:
                        if args.stages and sub.topic_name.endswith('hair/points'):
                            t = stamp_of(raw)
                            clock.mark(t, 'woken', woken)
                            clock.mark(t, 'taken')
                        subs[sub](raw)
    else:
        probe_ex.add_node(probe)

        def spin_probe():
            while not stop.is_set() and ctx.ok():
                probe_ex.spin_once(timeout_sec=0.05)
    if args.stages:
        points = node.outputs['points']
        points.cloud.encode = _marking(points.cloud.encode, clock, 'encoded')
        points.raw.publish = _marking(points.raw.publish, clock, 'published')
    probe_thread = threading.Thread(target=spin_probe, daemon=True)
    probe_thread.start()
    deadline = time.monotonic() + 20.0
    while time.monotonic() < deadline and not (
            pub.get_subscription_count() > 0 and node.outputs['points'].wanted()):
        node_ex.spin_once(timeout_sec=0.01)

    dt_ns = node.sim.dt_ns
    period = 1.0 / args.pose_rate
    step = max(1, int(round(period * 1e9 / dt_ns)))
    n_poses = int(args.seconds * args.pose_rate)

    def publish_poses():
        t0 = 1_000_000_000
        start = time.perf_counter()
        for k in range(n_poses):
            target = start + k * period
            while True:
                left = target - time.perf_counter()
                if left <= 0:
                    break
                time.sleep(min(left, 0.002))
            s = k / args.pose_rate
            p = [0.1 * np.sin(2.0 * s), 0.05 * np.sin(3.1 * s), 0.02 * np.cos(1.7 * s)]
            yaw = 0.6 * np.sin(1.3 * s)
            q = [0.0, 0.0, float(np.sin(yaw / 2)), float(np.cos(yaw / 2))]
            t = t0 + k * step * dt_ns
            msg = pose_stamped_msg(t, p, q, 'world')
            with lock:
                sent[t] = time.perf_counter()
            clock.mark(t, 'sent', sent[t])
            pub.publish(msg)
    pose_thread = threading.Thread(target=publish_poses, daemon=True)
    pose_thread.start()
    # The node's thread waits as ``executor.spin()`` in hair_sim_node does, woken by work; the
    # timeout only bounds the loop.  (A 5 ms timeout cost about 0.5 ms of CPU per empty spin
    # here: rclpy rebuilds its wait set on every spin_once, 10 % of a core at 200 spins/s.)
    with GcPauses() as pauses:
        while pose_thread.is_alive():
            node_ex.spin_once(timeout_sec=0.05)
        end = time.monotonic() + 0.5
        while time.monotonic() < end:
            node_ex.spin_once(timeout_sec=0.05)
    stop.set()
    probe_thread.join(2.0)
    for taker in takers.values():
        taker.close()

    skip = int(args.warmup_s * args.pose_rate)
    with lock:
        stamps = sorted(sent)[skip:]
        lat = [(received[t] - sent[t]) * 1e3 for t in stamps if t in received]
        missing = sum(1 for t in stamps if t not in received)
        shown, unshown = shown_latency(sent, received, stamps)
    step_ms = list(node.step_ms)          # kernels were warmed up before the first pose
    pub_ms = list(node.publish_ms)
    c = node.sim.counters
    result = {
        'ghosts': int(node.sim.ghosts.count), 'guides': int(node.sim.guides.count),
        'nodes_per_strand': int(node.sim.ghosts.nodes), 'mode': mode,
        'solver': args.solver, 'settings': dict(args.set),
        'numba_threads': int(node.numba_threads),
        'pose_queue_depth': int(node.get_parameter('pose_queue_depth').value),
        'pose_rate_hz': args.pose_rate,
        'publish_rate_hz': args.publish_rate, 'markers_subscribed': bool(args.markers),
        'probe': args.probe,
        'publish_through_rcl': bool(node.get_parameter('publish_through_rcl').value),
        'latency': stats(lat), 'poses_without_cloud': missing,
        'latency_every_pose': stats(shown), 'poses_never_shown': unshown,
        'cloud_bytes': cloud_bytes[0],
        'step': stats(step_ms), 'publish': stats(pub_ms),
        'substeps_dropped': int(c.substeps_dropped), 'poses_rejected': int(node.rejected),
        'load_shedding_switches': int(node.shedder.switches),
        'load_shedding_at_end': bool(node.sim.track_once_per_call),
        'gc': pauses.summary(),
    }
    if args.stages:
        result['stages'] = clock.stages(stamps)
    node_ex.shutdown(timeout_sec=1.0)
    probe_ex.shutdown(timeout_sec=1.0)
    node.destroy_node()
    probe.destroy_node()
    rclpy.shutdown(context=ctx)
    return result


def fmt(s):
    if s['median_ms'] is None:
        return '      n/a        n/a'
    return f"{s['median_ms']:8.2f} {s['p99_ms']:8.2f}"


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--ghosts', type=int, nargs='+', default=[1000, 10000])
    ap.add_argument('--modes', nargs='+', default=['timer', 'on_pose'],
                    choices=['timer', 'on_pose'])
    ap.add_argument('--seconds', type=float, default=8.0, help='pose stream length per case')
    ap.add_argument('--warmup-s', type=float, default=1.0, help='first seconds not counted')
    ap.add_argument('--pose-rate', type=float, default=60.0)
    ap.add_argument('--publish-rate', type=float, default=60.0)
    ap.add_argument('--solver', default='ftl', choices=['ftl', 'pbd', 'xpbd'])
    ap.add_argument('--pose-depth', type=int, default=None,
                    help="pose_queue_depth of the node (default: the node's own, 1)")
    ap.add_argument('--threads', type=int, default=0,
                    help='numba_threads of the node (0 = all cores)')
    ap.add_argument('--markers', action='store_true',
                    help='also subscribe to hair/markers (the node then encodes both)')
    ap.add_argument('--set', nargs='+', default=[], type=_setting, metavar='NAME=VALUE',
                    help='more node parameters, e.g. tracking.every_substep=false')
    ap.add_argument('--probe', choices=['rcl', 'rclpy'], default='rcl',
                    help="how the probe takes the clouds: rcl = rcl's serialized take called "
                         'directly, the GIL released, into one reused buffer (as a C++ '
                         "subscriber would); rclpy = rclpy's raw take, which holds the GIL "
                         'for two copies of each cloud and so stalls the node it measures')
    ap.add_argument('--stages', action='store_true',
                    help='also time each stage of each pose (pickup, step, cloud, publish, the '
                         "probe's wake and take; see StageClock) and print their medians / p99")
    ap.add_argument('--domain-id', type=int, default=48)
    ap.add_argument('--json', metavar='PATH', help='write the results as JSON')
    ap.add_argument('--switch-interval', type=float, default=0.0005,
                    help="Python's GIL switch interval [s] (default 5 ms makes the node wait "
                         'for the probe threads)')
    executable.add_arguments(ap)
    args = ap.parse_args(argv)
    args.set = dict(args.set)
    for line in executable.apply(args):     # as hair_sim_node's main() does
        print(line)
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    sys.setswitchinterval(args.switch_interval)

    results = []
    print(f'pose -> hair/points latency through DDS, one process ({os.cpu_count()} CPUs, '
          f'load average {os.getloadavg()[0]:.1f} at start); '
          f'poses at {args.pose_rate:g} Hz, publish_rate_hz {args.publish_rate:g}, '
          f'numba_threads {args.threads}, probe takes through {args.probe}, '
          f'one frame {FRAME_MS:.1f} ms')
    print(f"{'ghosts':>7} {'mode':>8} | {'latency med':>11} {'p99':>8} | "
          f"{'own cloud med':>13} {'p99':>8} | {'step med':>8} {'p99':>8} | "
          f"{'publish med':>11} {'p99':>8} | dropped / no cloud of their own")
    for ghosts in args.ghosts:
        for mode in args.modes:
            steal = StealMeter()
            r = run_case(ghosts, mode, args, args.domain_id)
            r['cpu_steal_share'] = steal.share()
            r['copy_ms'] = copy_ms(r['cloud_bytes']) if r['cloud_bytes'] else None
            results.append(r)
            lat = r['latency_every_pose']
            within = '' if lat['n'] == 0 else \
                f"; latency p90 {lat['p90_ms']:.1f} ms, {100 * lat['share_within_frame']:.0f} % " \
                f'within {FRAME_MS:.1f} ms'
            print(f"{r['ghosts']:>7} {mode:>8} | {fmt(lat):>20} | "
                  f"{fmt(r['latency']):>22} | {fmt(r['step']):>17} | {fmt(r['publish']):>20} | "
                  f"{r['substeps_dropped']} substeps, {r['poses_without_cloud']} poses{within}"
                  f"; load shedding switched {r['load_shedding_switches']}x"
                  f"{', on at the end' if r['load_shedding_at_end'] else ''}"
                  f"; CPU stolen {format_share(r['cpu_steal_share'])}"
                  f"; {r['gc']['gen2']['n']} full GC pauses (longest "
                  f"{r['gc']['gen2']['max_ms']:.1f} ms), one full GC {r['gc']['full_ms']:.1f} ms"
                  f"; cloud {r['cloud_bytes'] / 1e6:.1f} MB, one copy of it "
                  f"{r['copy_ms'] or float('nan'):.2f} ms",
                  flush=True)
            if 'stages' in r:
                st = r['stages']
                parts = [f"{k} {v['median_ms']:.2f} / {v['p99_ms']:.2f}"
                         for k, v in st.items() if isinstance(v, dict) and v['n']]
                print(f"{'':>17}stages, median / p99 ms: " + ', '.join(parts) +
                      f"; {100 * st['share_arriving_busy']:.0f} % of poses arrived while the "
                      'node was busy', flush=True)
    if args.json:
        os.makedirs(os.path.dirname(os.path.abspath(args.json)), exist_ok=True)
        with open(args.json, 'w', encoding='utf-8') as f:
            json.dump({'provenance': provenance(command_line('python scripts/bench_latency.py',
                                                             argv)),
                       'machine': {'loadavg_end': os.getloadavg(),
                                   'platform': platform.platform()},
                       'frame_ms': FRAME_MS, 'results': results}, f, indent=2)
        print(f'wrote {args.json}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
