#!/usr/bin/env python3
"""Benchmark: strands -> MarkerArray / PointCloud2 bytes, object path vs numpy CDR fast path.

Object path = build the message objects + rclpy.serialization.serialize_message.
Fast path   = msg_adapters CDR encoder (bytes ready for Publisher.publish).
Prints medians [ms] and ratios measured in this run; ``--json PATH`` writes them too.
Run from the repository root: ``.venv/bin/python scripts/bench_msgs.py``.
"""
import argparse
import json
import os
import platform
import statistics
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from hair_tracking.executable import use_numba_cache  # noqa: E402
use_numba_cache()      # before numba loads: the cache make install fills
import numpy as np  # noqa: E402
from rclpy.serialization import deserialize_message, serialize_message  # noqa: E402
from sensor_msgs.msg import PointCloud2  # noqa: E402
from visualization_msgs.msg import MarkerArray  # noqa: E402

from msg_adapters.marker_cdr import strands_to_marker_array_cdr  # noqa: E402
from msg_adapters.markers import strands_to_marker_array  # noqa: E402
from hair_tracking.core.point_records import points_to_records  # noqa: E402
from hair_tracking.evaluation.provenance import command_line, provenance  # noqa: E402
from msg_adapters.pointcloud import (CloudBuffer, pack_rgb_u32,  # noqa: E402
                                     strands_to_pointcloud2, strands_to_pointcloud2_cdr)


def median_ms(fn, reps, best=None):
    """Median wall time [ms] of ``reps`` calls after one warm-up; ``best`` (a list) gets the
    minimum, a steadier figure on a busy machine."""
    fn()                                        # warm-up
    times = []
    for _ in range(reps):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    if best is not None:
        best.append(1e3 * min(times))
    return 1e3 * statistics.median(times)


def strands(n_strands, n_points, seed=0):
    rng = np.random.default_rng(seed)
    steps = rng.normal(scale=0.005, size=(n_strands, n_points, 3))
    return np.cumsum(steps, axis=1), rng


def bench_markers(n_strands, n_points, style, colors_mode, reps_fast, reps_obj):
    x, rng = strands(n_strands, n_points)
    colors = {'none': None, 'strand': rng.random((n_strands, 4)),
              'point': rng.random((n_strands, n_points, 4))}[colors_mode]
    kw = dict(frame_id='head', stamp_ns=1_700_000_000_000_000_000, ns='hair', style=style,
              colors=colors, lifetime_ns=300_000_000)
    fast = strands_to_marker_array_cdr(x, **kw)
    obj = strands_to_marker_array(x, **kw)
    assert deserialize_message(fast, MarkerArray) == obj, 'fast path differs'
    del obj
    t_build = median_ms(lambda: strands_to_marker_array(x, **kw), reps_obj)
    msg = strands_to_marker_array(x, **kw)
    t_ser = median_ms(lambda: serialize_message(msg), reps_obj)
    best = []
    t_fast = median_ms(lambda: strands_to_marker_array_cdr(x, **kw), reps_fast, best)
    t_obj = t_build + t_ser
    return dict(kind='MarkerArray', style=style, colors=colors_mode, strands=n_strands,
                points=n_points, bytes=len(fast), object_build_ms=t_build,
                object_serialize_ms=t_ser, object_total_ms=t_obj, fast_ms=t_fast,
                fast_min_ms=best[0], speedup=t_obj / t_fast, reps_fast=reps_fast,
                reps_object=reps_obj)


def bench_cloud(n_strands, n_points, reps):
    x, rng = strands(n_strands, n_points)
    kw = dict(frame_id='head', stamp_ns=5, colors=rng.random((n_strands, 3)))
    fast = strands_to_pointcloud2_cdr(x, **kw)
    assert deserialize_message(fast, PointCloud2) == strands_to_pointcloud2(x, **kw)
    t_build = median_ms(lambda: strands_to_pointcloud2(x, **kw), reps)
    msg = strands_to_pointcloud2(x, **kw)
    t_ser = median_ms(lambda: serialize_message(msg), reps)
    best = []
    t_fast = median_ms(lambda: strands_to_pointcloud2_cdr(x, **kw), reps, best)
    # as the node and hair_sim_bag run publish: the colours packed once and cached
    packed = dict(frame_id='head', stamp_ns=5, packed_rgb=pack_rgb_u32(kw['colors']))
    assert strands_to_pointcloud2_cdr(x, **packed) == fast
    t_packed = median_ms(lambda: strands_to_pointcloud2_cdr(x, **packed), reps)
    # as the node publishes now: one kept buffer, coordinates written into it in place
    buf = CloudBuffer()

    def write(words, stride):
        return points_to_records(words, stride, x)

    def kept():
        return buf.encode(n_strands, n_points, write, **packed)
    assert kept().tobytes() == fast
    t_kept = median_ms(kept, reps)
    return dict(kind='PointCloud2', strands=n_strands, points=n_points, bytes=len(fast),
                object_build_ms=t_build, object_serialize_ms=t_ser,
                object_total_ms=t_build + t_ser, fast_ms=t_fast, fast_min_ms=best[0],
                fast_packed_ms=t_packed, kept_buffer_ms=t_kept,
                speedup=(t_build + t_ser) / t_fast, reps_fast=reps, reps_object=reps)


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--points', type=int, default=16, help='points per strand')
    ap.add_argument('--colors', choices=['none', 'strand', 'point'], default='strand')
    ap.add_argument('--reps', type=int, default=20, help='fast-path repetitions')
    ap.add_argument('--json', metavar='PATH', help='also write the results as JSON')
    ap.add_argument('--quick', action='store_true', help='small sizes (smoke test)')
    args = ap.parse_args(argv)

    marker_sizes = [(100, 5, 2)] if args.quick else [(1000, 5, args.reps), (10000, 3, args.reps)]
    cloud_strands = [1000] if args.quick else [10_000, 100_000]
    results = []
    for n_strands, reps_obj, reps_fast in marker_sizes:
        for style in ('line_list', 'line_strips'):
            results.append(bench_markers(n_strands, args.points, style, args.colors, reps_fast,
                                         reps_obj))
    for n_strands in cloud_strands:
        results.append(bench_cloud(n_strands, args.points,
                                   args.reps if n_strands <= 10_000 else max(3, args.reps // 4)))

    env = dict(machine=platform.machine(),
               ROS_PYTHON_CHECK_FIELDS=os.environ.get('ROS_PYTHON_CHECK_FIELDS', ''),
               loadavg_1min=round(os.getloadavg()[0], 2))
    print(f'# {env}')
    print(f'{"message":<28}{"strands":>8}{"pts":>5}{"MB":>7}{"build":>10}{"serial.":>10}'
          f'{"object":>10}{"fast":>9}{"ratio":>8}{"fast min":>10}   (medians, ms)')
    for r in results:
        name = r['kind'] + (f' {r["style"]}' if 'style' in r else '')
        print(f'{name:<28}{r["strands"]:>8}{r["points"]:>5}{r["bytes"] / 1e6:>7.2f}'
              f'{r["object_build_ms"]:>10.2f}{r["object_serialize_ms"]:>10.2f}'
              f'{r["object_total_ms"]:>10.2f}{r["fast_ms"]:>9.3f}{r["speedup"]:>7.1f}x'
              f'{r["fast_min_ms"]:>10.3f}'
              + (f'   packed colours {r["fast_packed_ms"]:.3f}, kept buffer '
                 f'{r["kept_buffer_ms"]:.3f}' if 'fast_packed_ms' in r else ''))
    if args.json:
        record = provenance(command_line('python scripts/bench_msgs.py', argv))
        with open(args.json, 'w') as f:
            json.dump(dict(provenance=record, env=env, results=results), f, indent=2)
    return 0


if __name__ == '__main__':
    sys.exit(main())
