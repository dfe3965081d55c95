"""A bag made by ``hair_sim_bag import`` plays into the node with no remapping, in either
message form: PoseStamped on /head_pose and TransformStamped on /head_transform (the node's
default inputs), played over DDS by the package's player.  Domain ids 58-59.
"""
import threading

import numpy as np
import pytest

from hair_tracking.bags.cli import main as bag_main
from hair_tracking.bags.io import read_head_poses
from hair_tracking.ros.bag_play import BagPlayer

from test_node import Harness

WAIT_S = 30.0
N = 24


def _table(path):
    t = np.arange(N) / 60.0
    rows = ['t_s,px,py,pz,qx,qy,qz,qw']
    for k, tk in enumerate(t):
        a = 0.02 * k
        rows.append(f'{tk:.6f},{0.001 * k:.6f},0.0,1.6,0.0,0.0,{np.sin(a / 2):.9f},'
                    f'{np.cos(a / 2):.9f}')
    path.write_text('\n'.join(rows) + '\n')


@pytest.mark.parametrize('kind,topic,domain', [('pose', '/head_pose', 58),
                                               ('transform', '/head_transform', 59)])
def test_imported_bag_plays_into_the_node_without_remapping(tmp_path, kind, topic, domain):
    table = tmp_path / 'poses.csv'
    _table(table)
    bag = tmp_path / f'{kind}.mcap'
    assert bag_main(['import', str(table), '-o', str(bag), '--message', kind,
                     '--time-column', 't_s', '--position-columns', 'px,py,pz',
                     '--quat-columns', 'qx,qy,qz,qw']) == 0
    assert read_head_poses(bag).topic == topic
    h = Harness(domain_id=domain)
    player = None
    try:
        player = BagPlayer(h.probe, bag, clock=False, log=lambda text: None)
        assert list(player.publishers) == [topic]
        assert player.wait_for_subscribers(WAIT_S) == [], 'the node does not take ' + topic
        counters = h.node.sim.track.counters
        bag_positions = np.stack([0.001 * np.arange(N), np.zeros(N), np.full(N, 1.6)], axis=1)

        def a_bag_pose_arrived():
            p = h.node.sim.track.latest().position
            return counters['accepted'] > 0 and \
                bool(np.any(np.all(np.abs(bag_positions - p) < 1e-9, axis=1)))

        th = threading.Thread(target=player.play)
        th.start()
        # poses go best effort (sensor-data QoS): a loaded machine may drop some of the burst
        h.spin_until(lambda: not th.is_alive() and a_bag_pose_arrived(), timeout=WAIT_S,
                     what='a pose from the bag')
        th.join(WAIT_S)
        assert h.node.rejected == 0
        assert h.node.output_frame_id() == 'world'
    finally:
        if player is not None:
            player.destroy()
        h.close()
