"""scripts/bench_latency.py end to end on a small groom: it runs, counts every pose it sent,
and with --stages reports every stage of the chain (a smoke test of the benchmark itself: the
structure of its report is checked, never what the numbers say about speed, which depends on
the machine; speed is measured by running it, not in tests)."""
import json
import os
import subprocess
import sys

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def test_latency_benchmark_times_every_stage_of_a_short_stream(tmp_path):
    out = tmp_path / 'lat.json'
    proc = subprocess.run(
        [sys.executable, os.path.join(ROOT, 'scripts', 'bench_latency.py'), '--ghosts', '128',
         '--modes', 'on_pose', '--seconds', '2', '--warmup-s', '0.5', '--stages',
         '--domain-id', '74', '--json', str(out)],
        capture_output=True, text=True, timeout=300,
        env=dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST'))
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert 'stages, median / p99 ms: pickup' in proc.stdout
    (r,) = json.loads(out.read_text())['results']
    assert r['probe'] == 'rcl' and r['publish_through_rcl'] is False     # rclpy's publish
    assert r['ghosts'] == 128 and r['mode'] == 'on_pose'
    # every counted pose (2 s at 60 Hz, less 0.5 s of warm-up) is accounted for either way
    assert r['latency']['n'] + r['poses_without_cloud'] == 90
    assert r['latency_every_pose']['n'] + r['poses_never_shown'] == 90
    stages = r['stages']
    for name in ('latency', 'latency_every_pose', 'step', 'publish'):
        _assert_stats(r[name], name)
    for name in ('pickup', 'step', 'cloud', 'publish', 'delivery', 'probe_take'):
        _assert_stats(stages[name], name)
    assert 0.0 <= stages['share_arriving_busy'] <= 1.0


def _assert_stats(s, name):
    """A block of timings: a count, and order statistics in order when there is any."""
    assert set(s) >= {'n', 'median_ms', 'p90_ms', 'p99_ms', 'max_ms'}, name
    assert isinstance(s['n'], int) and s['n'] >= 1, name
    assert 0.0 <= s['median_ms'] <= s['p90_ms'] <= s['p99_ms'] <= s['max_ms'], name


def test_a_pose_without_a_cloud_of_its_own_counts_until_the_next_cloud_shows_it():
    sys.path.insert(0, os.path.join(ROOT, 'scripts'))
    from bench_latency import shown_latency
    sent = {10: 0.000, 20: 0.010, 30: 0.020, 40: 0.030}
    received = {10: 0.005, 30: 0.040}          # pose 20 was replaced by 30 in the queue
    lat, left_out = shown_latency(sent, received, [10, 20, 30, 40])
    assert lat == pytest.approx([5.0, 30.0, 20.0])
    assert left_out == 1                          # no cloud came after pose 40
    # a later-stamped cloud that arrived earlier shows the pose first
    lat, _ = shown_latency({10: 0.0}, {20: 0.003, 30: 0.002}, [10])
    assert lat == pytest.approx([2.0])
