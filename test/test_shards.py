"""Ghost shards (hair_tracking.output.shards, hair_sim_ghosts): the split, the settings that
cross the wire, the rows a shard places against the cloud of all strands, late and
out-of-order guides."""
import numpy as np
import pytest

from msg_adapters.guide_state import guide_state_from_cdr

from hair_tracking.ghosts.blend import STRAND_BLOCK
from hair_tracking.output.frame_encoder import FrameEncoder
from hair_tracking.output.settings import make_settings
from hair_tracking.output.shards import fingerprint, GhostShard, guide_state_bytes, \
    SequenceGate, serial_after, settings_from_text, settings_text, shard_rows, ShardError
from hair_tracking.simulator import HairSimulator

SMALL = {'groom.guides': 12, 'groom.ghosts_per_guide': 7, 'groom.ghost_nodes': 8,
         'groom.guide_nodes': 8}


def walk(k):
    """Head pose ``k`` of a small nodding walk: (stamp [ns], position, quaternion)."""
    a = 0.3 * np.sin(0.4 * k)
    return (10_000_000 * (k + 1), np.array([0.01 * k, 0.0, 0.002 * k]),
            np.array([0.0, np.sin(a / 2), 0.0, np.cos(a / 2)]))


@pytest.mark.parametrize('count,shards', [(84, 1), (84, 2), (84, 3), (85, 4), (7, 2), (0, 2),
                                          (100_000, 4)])
def test_shard_rows_are_contiguous_block_aligned_and_cover_every_strand(count, shards):
    rows = [shard_rows(count, k, shards) for k in range(shards)]
    assert rows[0].start == 0 and rows[-1].stop == count
    for a, b in zip(rows, rows[1:]):
        assert a.stop == b.start and a.stop % STRAND_BLOCK == 0
    sizes = [r.stop - r.start for r in rows]
    assert max(sizes) - min(sizes) <= STRAND_BLOCK + count % STRAND_BLOCK


def test_a_shard_that_does_not_exist_is_refused():
    with pytest.raises(ShardError, match='shard 2 of 2 does not exist'):
        shard_rows(10, 2, 2)


def test_settings_cross_as_text_and_come_back_equal():
    settings = make_settings({**SMALL, 'cloud_fields': 'xyz_rgb', 'output_frame': 'head'})
    text = settings_text(settings)
    assert settings_from_text(text) == settings
    assert fingerprint(text) == fingerprint(settings_text(settings_from_text(text)))
    assert fingerprint(text) != fingerprint(settings_text(make_settings(SMALL)))
    with pytest.raises(ShardError, match='unusable'):
        settings_from_text('groom.guides: -3\n')


def test_trackers_that_cannot_shard_are_refused_with_a_reason():
    text = settings_text(make_settings({**SMALL, 'tracking.mode': 'paper'}))
    with pytest.raises(ShardError, match='tracking.mode paper: ghost shards place the ghosts '
                       'of the blend and turn trackers only'):
        GhostShard(text, 0, 2)


@pytest.mark.parametrize('changes', [{}, {'output_frame': 'head'}, {'cloud_fields': 'xyz'},
                                     {'body.bust': True}, {'tracking.mode': 'turn'},
                                     {'tracking.mode': 'turn', 'output_frame': 'head'},
                                     {'tracking.mode': 'turn', 'body.bust': True}])
def test_shards_rows_concatenated_are_the_rows_of_the_cloud_of_all(changes, one_numba_thread):
    """The node's cloud (its ghosts placed from the guides as sent) against the shards' clouds
    of the same frames, byte for byte after the header; markers alike."""
    settings = make_settings({**SMALL, **changes})
    text = settings_text(settings)
    sim = HairSimulator(settings.scene)
    sim.guides_as_float32 = True
    enc = FrameEncoder(settings)
    shards = [GhostShard(text, k, 3) for k in range(3)]
    head_frame = settings.output_frame == 'head'
    frame_id = 'head' if head_frame else 'world'
    step = 12 + 4 * settings.cloud_rgb + 4 * settings.cloud_strand    # bytes a point
    compared = 0
    for k in range(12):
        t, p, q = walk(k)
        sim.push_pose(t, p, q)
        sim.advance_to(t)
        if not sim.ghost_tracker.from_step:
            continue                     # a carried hair: no guides are sent for it
        data = guide_state_bytes(sim, 'world', t, fingerprint(text), k + 1)
        whole = enc.frame(sim, ['points'], frame_id, t, head_frame)['points'].data
        parts = []
        for shard in shards:
            shard.apply(guide_state_from_cdr(data))
            parts.append(shard.encode(['points'], frame_id)['points'].copy())
        n = sim.ghosts.rest.shape[1]

        def data(cloud, strands):      # the point records, right before is_dense
            return bytes(cloud[-(1 + strands * n * step):-1])
        assert b''.join(data(c, s.count) for c, s in zip(parts, shards)) == \
            data(whole, sim.ghosts.count)
        assert all(c[-1] == whole[-1] == 1 for c in parts)      # is_dense
        for shard in shards:             # the markers of the shard's strands
            x = shard.tracker.rows_positions(shard.rows)
            np.testing.assert_array_equal(x, sim.frame(copy=False).strands[shard.rows])
        compared += 1
    assert compared >= 10


def test_the_first_frame_after_a_reset_is_not_sent():
    """A hair carried rigidly (the first pose, a jump) is not placed from the guides: nothing
    a shard could place from them."""
    sim = HairSimulator(make_settings(SMALL).scene)
    t, p, q = walk(0)
    sim.push_pose(t, p, q)
    assert not sim.ghost_tracker.from_step
    t, p, q = walk(1)
    sim.push_pose(t, p, q)
    sim.advance_to(t)
    assert sim.ghost_tracker.from_step


def test_guides_of_other_settings_or_size_are_refused():
    text = settings_text(make_settings(SMALL))
    shard = GhostShard(text, 0, 2)
    sim = HairSimulator(make_settings(SMALL).scene)
    t, p, q = walk(1)
    sim.push_pose(t, p, q)
    with pytest.raises(ShardError, match='guides of another scene'):
        shard.check(guide_state_from_cdr(guide_state_bytes(sim, 'world', t, 7, 1)))
    other = HairSimulator(make_settings({**SMALL, 'groom.guides': 13}).scene)
    with pytest.raises(ShardError, match='guides of 13 x 8 nodes, this shard\'s groom has 12'):
        shard.check(guide_state_from_cdr(guide_state_bytes(other, 'world', t,
                                                           shard.fingerprint, 1)))


def test_the_sequence_gate_drops_late_repeated_and_out_of_order_messages():
    gate = SequenceGate()
    assert [gate.accept(s) for s in (5, 6, 6, 4, 8, 7, 9)] == \
        [True, True, False, False, True, False, True]
    assert gate.dropped == 3
    assert serial_after(0, 2 ** 32 - 1) and not serial_after(2 ** 32 - 1, 0)
    gate.restart()
    assert gate.accept(1)


def test_the_viewer_joins_the_shards_newest_clouds_and_leaves_out_a_stopped_one():
    from msg_adapters.pointcloud import strands_to_pointcloud2
    from hair_tracking.ros.view_geometry import ShardClouds

    def cloud(first, count, t_ns):
        x = np.arange(count * 2 * 3, dtype=np.float64).reshape(count, 2, 3) + 100 * first
        return strands_to_pointcloud2(x, frame_id='world', stamp_ns=t_ns,
                                      strand_ids=np.arange(first, first + count))
    join = ShardClouds(2)
    one = join.add(0, cloud(0, 3, 10))
    assert one.height == 3
    both = join.add(1, cloud(3, 2, 10))
    assert both.height == 5 and bytes(both.data) == \
        bytes(cloud(0, 3, 10).data) + bytes(cloud(3, 2, 10).data)
    later = join.add(0, cloud(0, 3, 10 + 2_000_000_000))        # shard 1 stopped
    assert later.height == 3
