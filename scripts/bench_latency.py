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

Ghost shards (``--shards 0 1 2 4``; 0, the default, is the single-process node): with N > 0
the node runs with ``shards:=N`` (it simulates the guides and publishes their state, no ghosts
of its own) and N ``hair_sim_ghosts`` processes place and publish the ghosts, each on
``hair/shard_<k>/points``; the probe takes every shard's cloud, and a pose's cloud has arrived
when the last shard's has.  Also reported per shard: its own time per frame (placing, encoding
and publishing its share, median and p99, from its diagnostics) and its cloud's bytes, the
GuideState's bytes against the whole cloud's, and what N machines would give: the guides
node's time per pose (step and publish) plus the slowest shard's own time, each shard on a
machine of its own with its cloud on its own link (a model from the measured parts, not a
measurement).

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
from rclpy.serialization import deserialize_message

from geometry_msgs.msg import PoseStamped
from sensor_msgs.msg import PointCloud2
from visualization_msgs.msg import MarkerArray

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from hair_tracking import executable  # noqa: E402

executable.use_numba_cache()    # before numba loads: the cache make install fills

from hair_tracking.core.param_table import by_name  # noqa: E402
from hair_tracking.evaluation.provenance import command_line, provenance  # noqa: E402
from cpu_steal import format_share, StealMeter  # noqa: E402  (scripts/cpu_steal.py)
from hair_tracking.ros.node import HairSimNode  # noqa: E402
from hair_tracking.ros.pose_intake import PoseIntake  # noqa: E402
from hair_tracking.ros.ghosts import shard_topic  # noqa: E402
from hair_tracking.output.shards import guide_state_bytes  # noqa: E402
from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
import subprocess  # noqa: E402
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


def shown_by_all(sent, by_shard, stamps):
    """Latency [ms] of each pose in ``stamps`` until every shard has shown it: for each shard
    the earliest arrival of its cloud stamped at or after the pose (:func:`shown_latency`), the
    latest of those over the shards (shards place the newest guides each, so they need not
    publish the same stamps).  Returns (latencies, poses some shard never showed)."""
    per = []
    for received in by_shard:
        clouds = np.array(sorted(received), dtype=np.int64)
        arrival = np.array([received[c] for c in clouds.tolist()])
        first = np.minimum.accumulate(arrival[::-1])[::-1] if clouds.size else arrival
        per.append((clouds, first))
    out, left = [], 0
    for t in stamps:
        worst = None
        for clouds, first in per:
            i = int(np.searchsorted(clouds, t, side='left'))
            if i == clouds.size:
                worst = None
                break
            worst = first[i] if worst is None else max(worst, first[i])
        if worst is None:
            left += 1
        else:
            out.append((worst - sent[t]) * 1e3)
    return out, left


def shard_alone(node, shards, reps=9):
    """Median time [ms] one shard of ``shards`` takes for a frame (placing its share of the
    node's ghosts from a guides message and writing its cloud, one thread) in this process
    after the stream: what the shard costs on a core of its own, without the DDS hand-off."""
    import numba
    from msg_adapters.guide_state import guide_state_from_cdr
    from hair_tracking.output.shards import fingerprint, GhostShard, settings_text
    text = settings_text(node.settings)
    shard = GhostShard(text, 0, shards)
    sample = guide_state_from_cdr(guide_state_bytes(node.sim, 'world', 1, fingerprint(text), 1))
    before = numba.get_num_threads()
    numba.set_num_threads(1)
    times = []
    try:
        for _ in range(reps + 1):
            start = time.perf_counter()
            shard.apply(sample)
            shard.encode(['points'], 'world')
            times.append((time.perf_counter() - start) * 1e3)
    finally:
        numba.set_num_threads(before)
    return float(np.median(times[1:]))


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
    """A :class:`HairSimNode` subclass whose pose intake marks its stages on ``clock``."""
    class TimedIntake(PoseIntake):
        def on_pose(self, msg, from_tf=False):
            stamp = time_to_ns(msg.header.stamp)
            clock.current = stamp
            clock.mark(stamp, 'callback')
            try:
                super().on_pose(msg, from_tf)
            finally:
                clock.mark(stamp, 'returned')
                clock.current = None

        def step(self, t_ns):
            super().step(t_ns)
            clock.mark(clock.current, 'stepped')

    class TimedNode(HairSimNode):
        intake_type = TimedIntake
    return TimedNode


def _marking(fn, clock, stage):
    def wrapped(*a, **k):
        out = fn(*a, **k)
        clock.mark(clock.current, stage)
        return out
    return wrapped


def start_shards(n, domain_id):
    """``n`` hair_sim_ghosts processes on ``domain_id`` (numba threads shared out among
    them); their Popen objects."""
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain_id),
               NUMBA_NUM_THREADS=str(max(1, (os.cpu_count() or 1) // n)),
               PYTHONPATH=os.pathsep.join(filter(None, [root, os.environ.get('PYTHONPATH')])))
    return [subprocess.Popen([sys.executable, '-m', 'hair_tracking.ros.ghosts', '--ros-args',
                              '-r', f'__node:=hair_sim_ghosts_{k}', '-p', f'shard:={k}',
                              '-p', f'shards:={n}'], env=env,
                             stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
            for k in range(n)]


def stop_shards(procs):
    for p in procs:
        if p.poll() is None:
            p.terminate()
    for p in procs:
        try:
            p.wait(timeout=30)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait()


def run_case(ghosts, mode, args, domain_id, shards=0):
    guides, per_guide = groom_for(ghosts)
    procs = start_shards(shards, domain_id) if shards else []
    try:
        return _run_case(ghosts, mode, args, domain_id, shards, guides, per_guide)
    finally:
        stop_shards(procs)


def _run_case(ghosts, mode, args, domain_id, shards, guides, per_guide):
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
    if shards:
        overrides['shards'] = shards
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

    by_shard = [{} for _ in range(shards)]      # shard -> stamp -> arrival
    shard_bytes = {}

    def on_cloud(raw, shard=None):
        now = time.perf_counter()
        t = stamp_of(raw)
        with lock:
            if shard is not None:
                shard_bytes[shard] = len(raw)
                by_shard[shard].setdefault(t, now)
                if not all(t in got for got in by_shard):
                    return
            cloud_bytes[0] = len(raw) if shard is None else sum(shard_bytes.values())
            received.setdefault(t, now)
        if args.stages:
            clock.mark(t, 'received', now)
    qos = QoSProfile(depth=5, reliability=ReliabilityPolicy.RELIABLE)
    if shards:
        subs = {}
        for k in range(shards):
            def on_shard(raw, k=k):
                on_cloud(raw, k)
            subs[probe.create_subscription(PointCloud2, shard_topic(k, 'points'), on_shard,
                                           qos, raw=True)] = on_shard
    else:
        subs = {probe.create_subscription(PointCloud2, 'hair/points', on_cloud, qos,
                                          raw=True): on_cloud}
    shard_status = {}

    def on_diagnostics(msg):
        for st in msg.status:
            if 'ghost shard' in st.name:
                shard_status[st.name] = {kv.key: kv.value for kv in st.values}
    diag_sub = probe.create_subscription(DiagnosticArray, '/diagnostics', on_diagnostics, 10)
    if shards:                          # the rcl probe takes them as bytes
        subs[diag_sub] = lambda raw: on_diagnostics(deserialize_message(bytes(raw),
                                                                        DiagnosticArray))
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
        encoder = node.publishing.encoder
        encoder.cloud = _marking(encoder.cloud, clock, 'encoded')
        points.raw.publish = _marking(points.raw.publish, clock, 'published')
    probe_thread = threading.Thread(target=spin_probe, daemon=True)
    probe_thread.start()
    deadline = time.monotonic() + (300.0 if shards else 20.0)
    while time.monotonic() < deadline and not (
            pub.get_subscription_count() > 0 and
            (all(sub.get_publisher_count() > 0 for sub in list(subs)[:shards])
             if shards else node.outputs['points'].wanted())):
        node_ex.spin_once(timeout_sec=0.01)
    if shards:                           # every shard has built its groom
        deadline = time.monotonic() + 300.0
        while time.monotonic() < deadline and len(shard_status) < shards:
            node_ex.spin_once(timeout_sec=0.05)
        while time.monotonic() < deadline and not all(
                v['strands'] != 'n/a' for v in shard_status.values()):
            node_ex.spin_once(timeout_sec=0.05)

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
    if shards:                           # the shards' diagnostics after the stream
        end = time.monotonic() + 2.5
        seen = {k: v.get('guides_applied') for k, v in shard_status.items()}
        while time.monotonic() < end and any(
                shard_status[k].get('guides_applied') == seen[k] for k in seen):
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
        if shards:
            shown, unshown = shown_by_all(sent, by_shard, stamps)
        else:
            shown, unshown = shown_latency(sent, received, stamps)
    step_ms = list(node.intake.step_ms)          # kernels were warmed up before the first pose
    pub_ms = list(node.publishing.publish_ms)
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
        'shards': shards,
        'guide_state_bytes': len(guide_state_bytes(node.sim, 'world', 0, 0, 0)),
    }
    if shards:
        result['shard'] = [_shard_figures(v) for _, v in sorted(shard_status.items())]
        result['shard_alone'] = shard_alone(node, shards)
    if args.stages:
        result['stages'] = clock.stages(stamps)
    node_ex.shutdown(timeout_sec=1.0)
    probe_ex.shutdown(timeout_sec=1.0)
    node.destroy_node()
    probe.destroy_node()
    rclpy.shutdown(context=ctx)
    return result


def _shard_figures(values):
    """One shard's diagnostics as numbers: its strands, time per frame, cloud bytes."""
    def num(key):
        try:
            return float(values.get(key, 'nan'))
        except ValueError:
            return None
    return {'strands': values.get('strands'), 'work_median_ms': num('work_ms_median'),
            'work_p99_ms': num('work_ms_p99'), 'cloud_bytes': int(num('cloud_bytes') or 0),
            'guides_applied': values.get('guides_applied'),
            'guides_dropped_late': values.get('guides_dropped_late')}


def machines_model(r, link_gbit=10.0):
    """What N machines would give (ms), from the measured parts: the guides node's step per
    pose (median) plus one shard's time for a frame on a core of its own
    (:func:`shard_alone`) plus its cloud on a ``link_gbit`` link, each shard with a machine
    and a link of its own; DDS's copies on either end are not in it."""
    if not r['shards'] or r.get('shard_alone') is None:
        return None
    wire = r['cloud_bytes'] / r['shards'] * 8 / (link_gbit * 1e9) * 1e3
    return {'median_ms': r['step']['median_ms'] + r['shard_alone'] + wire,
            'shard_ms': r['shard_alone'], 'wire_ms': wire, 'link_gbit': link_gbit}


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
    ap.add_argument('--shards', type=int, nargs='+', default=[0],
                    help='ghost shard processes (hair_sim_ghosts) per case; 0 = the '
                         'single-process node (default)')
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
    print(f"{'ghosts':>7} {'mode':>10} | {'latency med':>11} {'p99':>8} | "
          f"{'own cloud med':>13} {'p99':>8} | {'step med':>8} {'p99':>8} | "
          f"{'publish med':>11} {'p99':>8} | dropped / no cloud of their own")
    for ghosts, mode, shards in ((g, m, n) for g in args.ghosts for m in args.modes
                                 for n in args.shards):
        steal = StealMeter()
        r = run_case(ghosts, mode, args, args.domain_id, shards)
        r['machines_model'] = machines_model(r)
        r['cpu_steal_share'] = steal.share()
        r['copy_ms'] = copy_ms(r['cloud_bytes']) if r['cloud_bytes'] else None
        results.append(r)
        lat = r['latency_every_pose']
        within = '' if lat['n'] == 0 else \
            f"; latency p90 {lat['p90_ms']:.1f} ms, {100 * lat['share_within_frame']:.0f} % " \
            f'within {FRAME_MS:.1f} ms'
        label = mode if not shards else f'{mode} {shards}sh'
        print(f"{r['ghosts']:>7} {label:>10} | {fmt(lat):>20} | "
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
        if shards:
            per = '; '.join(f"shard {s['strands']}: {s['work_median_ms']:.2f} / "
                            f"{s['work_p99_ms']:.2f} ms, {s['cloud_bytes'] / 1e6:.2f} MB"
                            for s in r['shard'] if s['work_median_ms'] is not None)
            model = r['machines_model']
            print(f"{'':>17}{shards} shards, own time median / p99 and cloud: {per}; "
                  f"GuideState {r['guide_state_bytes']} bytes = "
                  f"{100 * r['guide_state_bytes'] / max(1, r['cloud_bytes']):.3f} % of "
                  f"the cloud; one shard alone {r['shard_alone']:.1f} ms a frame" +
                  ('' if model is None else
                   f"; {shards} machines: about {model['median_ms']:.1f} ms (guides step + "
                   f"one shard + {model['wire_ms']:.1f} ms on a {model['link_gbit']:g} Gbit/s "
                   'link)'), flush=True)
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
