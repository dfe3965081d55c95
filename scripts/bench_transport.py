#!/usr/bin/env python3
"""What handing a hair cloud through DDS costs without any simulation: the floor under the
node's pose -> cloud latency (``scripts/bench_latency.py``).

    python scripts/bench_transport.py [--ghosts 10000 100000] [--fields xyz_strand_rgb xyz]

For each cloud (ghosts x ``--points`` points, the node's layout for each ``cloud_fields``
value) and each publish path, one process and one rclpy context hold a publisher and a probe,
as bench_latency does: the main thread publishes a ready cloud (only its stamp changes) at
``--rate`` Hz through rclpy's ``Publisher.publish`` or rcl's serialized publish
(``publish_through_rcl``), and a probe thread takes the clouds through rcl with the GIL
released.  Reported: the publish call and the latency from its start to the probe's take
returning (median / p99), and, measured in the same run, one single-threaded copy of the
cloud's bytes (``numpy.copyto`` between two warm buffers), so ``latency / copy`` says how many
copies' worth the middleware takes.
"""
import argparse
import json
import os
import platform
import sys
import threading
import time

import numpy as np
import rclpy
from rclpy.context import Context
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import PointCloud2

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from hair_tracking import executable  # noqa: E402

executable.use_numba_cache()    # before numba loads: the cache make install fills

from bench_latency import copy_ms, stamp_of, stats  # noqa: E402  (scripts/bench_latency.py)
from hair_tracking.core.param_table import CLOUD_FIELDS  # noqa: E402
from hair_tracking.evaluation.provenance import command_line, provenance  # noqa: E402
from hair_tracking.ros.topics import output_qos  # noqa: E402
from msg_adapters.pointcloud import CloudBuffer, pack_rgb_u32  # noqa: E402
from msg_adapters.rcl_serialized import SerializedPublisher, unusable_reason  # noqa: E402
from rcl_take import SerializedTaker, SerializedWaiter  # noqa: E402  (scripts/rcl_take.py)


def run_case(strands, points, fields, through_rcl, args, domain_id):
    ctx = Context()
    rclpy.init(context=ctx, domain_id=domain_id)
    node = rclpy.create_node('transport_pub', context=ctx)
    probe = rclpy.create_node('transport_probe', context=ctx)
    pub = node.create_publisher(PointCloud2, 'hair/points', output_qos(2))
    raw = SerializedPublisher(pub, direct=through_rcl)
    arrived = {}
    sub = probe.create_subscription(PointCloud2, 'hair/points', lambda m: None,
                                    QoSProfile(depth=5, reliability=ReliabilityPolicy.RELIABLE),
                                    raw=True)
    taker = SerializedTaker(sub, 4 << 20)
    waiter = SerializedWaiter(ctx, {sub: None})
    stop = threading.Event()

    def spin_probe():
        while not stop.is_set() and ctx.ok():
            for _ in waiter.wait(0.05):
                while (msg := taker.take()) is not None:
                    arrived.setdefault(stamp_of(msg), time.perf_counter())
    thread = threading.Thread(target=spin_probe, daemon=True)
    thread.start()
    deadline = time.monotonic() + 20.0
    while time.monotonic() < deadline and pub.get_subscription_count() == 0:
        time.sleep(0.01)

    rng = np.random.default_rng(0)
    x = rng.normal(scale=0.1, size=(strands, points, 3)).astype(np.float32)

    def write_once(words, stride):
        words.reshape(-1, stride)[:, :3] = x.reshape(-1, 3)
        return True
    buf = CloudBuffer()
    rgb = pack_rgb_u32(rng.random((strands, 4))) if 'rgb' in fields else None
    encode = dict(frame_id='world', packed_rgb=rgb, strand_field='strand' in fields)
    msg = buf.encode(strands, points, write_once, stamp_ns=1, **encode)
    sent, publish = {}, []
    period = 1.0 / args.rate
    start = time.perf_counter() + 0.2
    for k in range(int(args.seconds * args.rate)):
        while (left := start + k * period - time.perf_counter()) > 0:
            time.sleep(min(left, 0.002))
        stamp = 1_000_000_000 + k * 1_000_000
        msg = buf.encode(strands, points, lambda words, stride: True, stamp_ns=stamp, **encode)
        t0 = time.perf_counter()
        raw.publish(msg)
        t1 = time.perf_counter()
        sent[stamp] = t0
        publish.append((t1 - t0) * 1e3)
    time.sleep(0.5)
    stop.set()
    thread.join(2.0)
    taker.close()
    skip = int(args.warmup_s * args.rate)
    stamps = sorted(sent)[skip:]
    lat = [(arrived[t] - sent[t]) * 1e3 for t in stamps if t in arrived]
    result = {'strands': strands, 'points': points, 'cloud_fields': fields,
              'bytes': int(msg.size), 'through_rcl': bool(raw.direct),
              'publish': stats(publish[skip:]), 'latency': stats(lat),
              'lost': sum(1 for t in stamps if t not in arrived),
              'copy_ms': copy_ms(int(msg.size))}
    node.destroy_node()
    probe.destroy_node()
    rclpy.shutdown(context=ctx)
    return result


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--ghosts', type=int, nargs='+', default=[10000, 100000])
    ap.add_argument('--points', type=int, default=16, help='points per strand')
    ap.add_argument('--fields', nargs='+', default=['xyz_strand_rgb', 'xyz'],
                    choices=CLOUD_FIELDS, help='cloud_fields values to compare')
    ap.add_argument('--paths', nargs='+', default=['rclpy', 'rcl'], choices=['rclpy', 'rcl'],
                    help="publish paths: rclpy's Publisher.publish, rcl's serialized publish")
    ap.add_argument('--rate', type=float, default=60.0, help='clouds per second')
    ap.add_argument('--seconds', type=float, default=6.0, help='stream length per case')
    ap.add_argument('--warmup-s', type=float, default=1.0, help='first seconds not counted')
    ap.add_argument('--domain-id', type=int, default=78)
    ap.add_argument('--json', metavar='PATH', help='also write the results as JSON')
    executable.add_arguments(ap, omp_wait_policy=None, gc_freeze=False)
    args = ap.parse_args(argv)
    for line in executable.apply(args):     # as hair_sim_node's main() does
        print(line)
    if 'rcl' in args.paths and unusable_reason() is not None:
        print(f'rcl path unusable here ({unusable_reason()}); measuring rclpy only')
        args.paths = ['rclpy']
    print(f'one cloud through DDS in one process ({os.cpu_count()} CPUs), {args.rate:g} Hz, '
          'median / p99 ms')
    print(f"{'ghosts':>7} {'fields':>15} {'MB':>6} {'path':>6} | {'publish':>15} | "
          f"{'publish -> take':>17} | {'one copy':>8} | latency / copy")
    results = []
    domain = args.domain_id
    for ghosts in args.ghosts:
        for fields in args.fields:
            for path in args.paths:
                r = run_case(ghosts, args.points, fields, path == 'rcl', args, domain)
                domain += 1
                results.append(r)
                p, lat = r['publish'], r['latency']
                ratio = lat['median_ms'] / r['copy_ms'] if lat['n'] else float('nan')
                print(f"{ghosts:>7} {fields:>15} {r['bytes'] / 1e6:6.1f} {path:>6} | "
                      f"{p['median_ms']:6.2f} {p['p99_ms']:7.2f} | "
                      f"{lat['median_ms']:7.2f} {lat['p99_ms']:8.2f} | "
                      f"{r['copy_ms']:8.2f} | {ratio:.1f}"
                      + (f"; {r['lost']} clouds not taken" if r['lost'] else ''), flush=True)
    if args.json:
        os.makedirs(os.path.dirname(os.path.abspath(args.json)), exist_ok=True)
        with open(args.json, 'w', encoding='utf-8') as f:
            json.dump({'provenance': provenance(command_line('python scripts/bench_transport.py',
                                                             argv)),
                       'machine': {'platform': platform.platform()},
                       'rate_hz': args.rate, 'seconds': args.seconds, 'results': results},
                      f, indent=1)
    return 0


if __name__ == '__main__':
    sys.exit(main())
