"""The live path in-process, over real DDS: play a bag with /clock into the hair_sim node
(use_sim_time), record its output, and compare with the offline ``run`` of the same bag.

What must agree, and why exactly: both paths push the same poses with the same integer-ns
stamps into the same HairSimulator code and advance it to those stamps, so the fixed-dt substep
schedule, the head samples and therefore every strand coordinate are the same computation.  The
node publishes one new frame per pose here (``publish_on_pose`` with a publishing period far
below the pose spacing); its timer may additionally resend the unchanged last frame (same
stamp, same bytes, by design: it keeps rviz markers alive), so live frames are counted by
distinct header stamp.  Tolerance on the hair: 1e-6 m.  The clouds carry float32 coordinates,
whose spacing near 1-3 m is 1.2e-7..2.4e-7 m, so 1e-6 m allows a few float32 steps; anything
beyond it would mean the two paths simulated different things (a lost or reordered pose, a
different substep schedule).  In practice the clouds are bit-identical.
"""
import struct
import threading
import time

import numpy as np
import pytest
import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter

from msg_adapters.pointcloud import pointcloud2_to_strands

from hair_tracking.bags import io as bag_io
from hair_tracking.bags.offline import run_bag, RunOptions
from hair_tracking.output.settings import make_settings
from hair_tracking.ros.bag_play import BagPlayer
from hair_tracking.ros.bag_record import BagRecorder
from hair_tracking.ros.node import HairSimNode

DOMAIN = 55
WAIT_S = 30.0
TOLERANCE_M = 1e-6
SMALL = {'groom.guides': 5, 'groom.ghosts_per_guide': 2, 'groom.guide_nodes': 7,
         'groom.ghost_nodes': 7, 'solver.settle_time': 0.05, 'stale_timeout': 30.0,
         'publish_on_pose': True, 'publish_rate_hz': 1000.0,
         # no pose and no frame may be lost when the test machine is busy
         'pose_queue_depth': 1000, 'output_queue_depth': 1000,
         'load_shedding': False}     # hair_sim_bag run never sheds: the same schedule


@pytest.fixture(autouse=True)
def one_numba_thread():
    import numba
    before = numba.get_num_threads()
    numba.set_num_threads(1)
    yield
    numba.set_num_threads(before)


def _stamp(cdr: bytes) -> int:
    """Header stamp [ns] of a serialized message whose first field is a std_msgs/Header."""
    sec, nanosec = struct.unpack_from('<iI', cdr, 4)
    return sec * 10 ** 9 + nanosec


def _clouds(path):
    """{stamp: strands} of /hair/points (first message of each stamp) and the message count."""
    out, n = {}, 0
    for stamp, msg in bag_io.cloud_messages(path):
        n += 1
        if stamp not in out:
            out[stamp] = pointcloud2_to_strands(msg)[0]
    return out, n


def test_play_into_node_record_compare_with_offline(tmp_path):
    src = tmp_path / 'walk_1s.mcap'
    hp = bag_io.read_head_poses(bag_io.bundled_bag(), start_offset_s=2.0, duration_s=1.0)
    bag_io.write_head_pose_bag(src, hp.t_ns, hp.position, hp.quaternion)
    live = tmp_path / 'live.mcap'

    ctx = Context()
    rclpy.init(context=ctx, domain_id=DOMAIN)
    sim_time = Parameter('use_sim_time', value=True)
    node = rec_node = play_node = player = None
    try:
        node = HairSimNode(context=ctx, parameter_overrides=[sim_time] + [
            Parameter(k, value=v) for k, v in SMALL.items()])
        rec_node = rclpy.create_node('recorder', context=ctx, parameter_overrides=[sim_time])
        play_node = rclpy.create_node('player', context=ctx)
        recorder = BagRecorder(rec_node, live, ['/hair/points', '/hair/markers',
                                                '/diagnostics'])
        stamps = set()
        recorder.on_message = (lambda topic, t, data: stamps.add(_stamp(data))
                               if topic == '/hair/points' else None)
        player = BagPlayer(play_node, src, rate=0.5)
        ex = SingleThreadedExecutor(context=ctx)
        ex.add_node(node)
        ex.add_node(rec_node)

        def spin_until(cond, timeout=WAIT_S):
            end = time.monotonic() + timeout
            while not cond() and time.monotonic() < end:
                ex.spin_once(timeout_sec=0.02)
            return cond()
        assert spin_until(lambda: not recorder.missing()), recorder.missing()
        assert spin_until(lambda: node.outputs['points'].wanted()
                          and node.outputs['markers'].wanted())
        assert not player.wait_for_subscribers(WAIT_S)
        th = threading.Thread(target=player.play)
        th.start()
        spin_until(lambda: not th.is_alive() and len(stamps) >= len(hp))
        th.join(WAIT_S)
        spin_until(lambda: False, timeout=0.3)          # let the last resends arrive
        recorder.close()
        rejected = node.rejected
    finally:
        if player is not None:
            player.destroy()
        for n in (node, rec_node, play_node):
            if n is not None:
                n.destroy_node()
        rclpy.try_shutdown(context=ctx)

    settings = make_settings(SMALL)
    off = tmp_path / 'offline.mcap'
    summary = run_bag(src, off, settings, RunOptions(every_pose=True))
    live_frames, live_msgs = _clouds(live)
    off_frames, off_msgs = _clouds(off)

    assert rejected == 0 and summary.rejected == 0
    assert summary.frames == off_msgs == len(off_frames) == len(hp) >= 100
    assert len(live_frames) == len(off_frames)               # same number of frames
    assert sorted(live_frames) == sorted(off_frames)         # at the same stamps
    assert live_msgs >= len(live_frames)
    diffs = [float(np.max(np.abs(live_frames[t] - off_frames[t]))) for t in sorted(off_frames)]
    assert diffs[-1] <= TOLERANCE_M                          # the final hair
    assert max(diffs) <= TOLERANCE_M                         # ... and every frame on the way
    last = off_frames[max(off_frames)]
    assert np.ptp(last[:, :, 2]) > 0.05                      # a real head of hair, not zeros


def test_live_demo_runs_end_to_end_and_ends_by_itself(tmp_path):
    """``make demo`` in small: node process + play + record + render + summary, exit 0."""
    import os
    import subprocess
    import sys
    from pathlib import Path
    root = Path(__file__).resolve().parents[1]
    env = dict(os.environ, PYTHONPATH=str(root), ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST')
    out = tmp_path / 'demo'
    proc = subprocess.run(
        [sys.executable, '-m', 'hair_tracking.ros.live_demo', '--out', str(out), '--domain-id',
         '57', '--duration', '1.0', '--max-frames', '6', '--param', 'groom.guides:=6',
         '--param', 'groom.ghosts_per_guide:=2', '--param', 'solver.settle_time:=0.05'],
        capture_output=True, text=True, timeout=300, cwd=root, env=env)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    assert 'hair frames' in proc.stdout and '12 strands' in proc.stdout
    assert (out / 'hair_output.mcap').is_file()
    assert (out / 'pictures' / 'hair.gif').is_file()
    assert (out / 'pictures' / 'diagnostics.png').is_file()
    info = bag_io.bag_info(out / 'hair_output.mcap')
    counts = {i.topic: i.count for i in info['topics']}
    played = len(bag_io.read_head_poses(bag_io.bundled_bag(), duration_s=1.0))
    # the node publishes at 30 Hz of sim time at most; how many of the 30 a loaded machine
    # manages is not this test's business
    assert counts['/head_pose'] == played and 1 <= counts['/hair/points'] <= 31
