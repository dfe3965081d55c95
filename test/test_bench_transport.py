"""scripts/bench_transport.py end to end on small clouds: every case runs, every cloud sent is
counted, and the sizes are the node's layouts (a smoke test of the benchmark itself: its
timings and losses depend on the machine and are not checked here)."""
import json
import os
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def test_transport_benchmark_moves_every_cloud_of_each_layout_and_path(tmp_path):
    out = tmp_path / 'transport.json'
    proc = subprocess.run(
        [sys.executable, os.path.join(ROOT, 'scripts', 'bench_transport.py'), '--ghosts', '200',
         '--points', '5', '--seconds', '1.5', '--warmup-s', '0.5', '--rate', '40',
         '--domain-id', '75', '--json', str(out)],
        capture_output=True, text=True, timeout=300,
        env=dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST'))
    assert proc.returncode == 0, proc.stdout + proc.stderr
    results = json.loads(out.read_text())['results']
    cases = {(r['cloud_fields'], r['through_rcl']) for r in results}
    assert cases == {('xyz_strand_rgb', False), ('xyz_strand_rgb', True), ('xyz', False),
                     ('xyz', True)}
    for r in results:
        step = 20 if r['cloud_fields'] == 'xyz_strand_rgb' else 12
        assert 200 * 5 * step < r['bytes'] < 200 * 5 * step + 300      # data + header
        assert r['latency']['n'] + r['lost'] == 40                     # 1 s counted at 40 Hz
        assert r['latency']['n'] >= 1 and r['publish']['n'] >= 1
        assert 0.0 < r['publish']['median_ms'] <= r['publish']['p99_ms']
        assert r['copy_ms'] > 0.0
