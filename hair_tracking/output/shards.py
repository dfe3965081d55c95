"""Ghost shards: the ghost strands split over processes (``hair_sim_ghosts``), each placing its
share from the guides' state that the ``hair_sim`` node publishes (docs/ros.md).

What crosses the wire, and what each side does with it (no ROS here; the nodes wire it):

* the node's settings, once and whenever they change, as YAML text (:func:`settings_text`),
  with a 64-bit fingerprint of that text (:func:`fingerprint`): a shard builds the same groom
  and encodes with the same settings (:func:`settings_from_text`);
* per frame the guides' state (hair_tracking_msgs/GuideState, :mod:`msg_adapters.guide_state`):
  the stamp, the head pose (float64, exact) and the guide positions in float32.  The node that
  publishes it places its own ghosts from the guides rounded to float32 too
  (``HairSimulator.guides_as_float32``), so every process places the same ghosts to the bit;
* each shard places a contiguous run of ghost strands (:func:`shard_rows`; the groom numbers
  strands so that neighbours on the scalp are near in number) with the blend or the turn
  tracker, which keep no state from frame to frame: a shard started late places the next frame
  as if it had been there all along.  The turn tracker places strands in blocks by guide: a
  shard places every block that holds one of its strands and writes its own strands only.

A guides message that is not after the last one used (its sequence, RFC 1982 serial number
arithmetic) is late or out of order: it is dropped and counted, never applied
(:class:`SequenceGate`).
"""
from dataclasses import dataclass
import hashlib
from typing import Dict, Optional

import numpy as np
import yaml

from msg_adapters.guide_state import guide_state_cdr

from hair_tracking.core.head_track import head_pose
from hair_tracking.core.params import ParamError
from hair_tracking.core.point_records import points_to_records
from hair_tracking.ghosts.blend import STRAND_BLOCK
from hair_tracking.ghosts.interface import TrackStep
from hair_tracking.output.frame_encoder import FrameEncoder
from hair_tracking.output.settings import make_settings, Settings
from hair_tracking.simulator import HairSimulator

#: The trackers whose ghosts a shard can place: stateless per frame, any run of strands placed
#: alone (``rows_positions``, ``write_rows`` of
#: :class:`~hair_tracking.ghosts.stateless.StatelessTracker`).
SHARDABLE = ('blend', 'turn')


class ShardError(ValueError):
    """A shard that cannot be set up, or a guides message it cannot use (the message says
    what and why)."""


def shard_rows(count: int, shard: int, shards: int) -> slice:
    """The ghost strands of shard ``shard`` of ``shards`` among ``count``: a contiguous run
    whose ends are multiples of :data:`~hair_tracking.ghosts.blend.STRAND_BLOCK` (so each
    shard's blocks are those of a whole placement), about ``count / shards`` strands each; the
    shards together are every strand once, in order."""
    shard, shards = int(shard), int(shards)
    if not 0 <= shard < shards:
        raise ShardError(f'shard {shard} of {shards} does not exist (0 <= shard < shards)')
    blocks = -(-int(count) // STRAND_BLOCK)

    def edge(k):
        return min(int(count), blocks * k // shards * STRAND_BLOCK)
    return slice(edge(shard), edge(shard + 1))


def _plain(value):
    if isinstance(value, tuple):
        return [_plain(v) for v in value]
    return value


def settings_text(settings: Settings) -> str:
    """The node's settings (every parameter, the scene's included) as YAML text."""
    values = {k: _plain(v) for k, v in settings.values().items()}
    return yaml.safe_dump(values, sort_keys=False)


def settings_from_text(text: str) -> Settings:
    """The settings of :func:`settings_text`; ShardError if they are not a node's."""
    try:
        values = yaml.safe_load(text)
        if not isinstance(values, dict):
            raise ParamError('settings', 'not a mapping of parameters')
        return make_settings(values)
    except (yaml.YAMLError, ParamError, ValueError) as exc:
        raise ShardError(f'the scene sent by the guides node is unusable: {exc}') from None


def fingerprint(text: str) -> int:
    """64-bit fingerprint of settings text (the first 8 bytes of its SHA-256)."""
    return int.from_bytes(hashlib.sha256(text.encode('utf-8')).digest()[:8], 'little')


def serial_after(a: int, b: int, bits: int = 32) -> bool:
    """Whether sequence number ``a`` comes after ``b`` (RFC 1982 serial number arithmetic:
    wraps at ``2 ** bits``)."""
    half = 1 << (bits - 1)
    d = (int(a) - int(b)) % (1 << bits)
    return 0 < d < half


class SequenceGate:
    """Lets through the messages whose sequence comes after the last one let through;
    ``dropped`` counts the others (late, repeated or out of order)."""

    def __init__(self):
        self.last: Optional[int] = None
        self.dropped = 0

    def accept(self, sequence: int) -> bool:
        if self.last is not None and not serial_after(sequence, self.last):
            self.dropped += 1
            return False
        self.last = int(sequence)
        return True

    def restart(self) -> None:
        """A new publisher (new settings): the next message is accepted whatever its number."""
        self.last = None


@dataclass
class ShardCounters:
    applied: int = 0             # guides messages placed
    refused: int = 0             # guides messages of another scene or size


def guide_state_bytes(sim, frame_id: str, stamp_ns: int, scene_fingerprint: int,
                      sequence: int) -> bytes:
    """The serialized GuideState of ``sim``'s guides and head pose now (a
    :class:`~hair_tracking.simulator.HairSimulator`), positions in ``frame_id``."""
    head = sim.head
    return guide_state_cdr(sim.guides.x, frame_id=frame_id, head_position=head.position,
                           head_quaternion=head.quaternion, scene_fingerprint=scene_fingerprint,
                           sequence=sequence, stamp_ns=stamp_ns)


class GhostShard:
    """Shard ``shard`` of ``shards`` of the ghosts of ``settings_text`` (the guides node's,
    :func:`settings_text`): the same groom, the same guides among the strands, the scene's
    tracker (blend or turn) over all strands of which this shard places its rows
    (:func:`shard_rows`).
    ShardError when the scene's tracker cannot be sharded or the groom has no ghosts."""

    def __init__(self, text: str, shard: int, shards: int):
        self.settings = settings = settings_from_text(text)
        self.fingerprint = fingerprint(text)
        scene = settings.scene
        if scene.tracking.mode not in SHARDABLE:
            raise ShardError(
                f'tracking.mode {scene.tracking.mode}: ghost shards place the ghosts of the '
                f'{" and ".join(SHARDABLE)} trackers only (the paper\'s tracker integrates '
                'every ghost over every substep); run the single-process node')
        self.sim = HairSimulator(scene)
        if self.sim.ghost_tracker is None:
            raise ShardError('the scene has no ghost strands to shard (groom.ghosts is 0)')
        self.tracker = self.sim.ghost_tracker
        self.total = self.sim.ghosts.count
        self.rows = shard_rows(self.total, shard, shards)
        self.shard, self.shards = int(shard), int(shards)
        self.encoder = FrameEncoder(settings)
        self.counters = ShardCounters()
        self.head = None
        self.stamp_ns = 0

    @property
    def count(self) -> int:
        """Ghost strands of this shard."""
        return self.rows.stop - self.rows.start

    def check(self, sample) -> None:
        """ShardError unless ``sample`` (a
        :class:`~msg_adapters.guide_state.GuideStateSample`) is the guides of this scene."""
        guides = self.sim.guides
        if sample.scene_fingerprint != self.fingerprint:
            raise ShardError(f'guides of another scene (fingerprint {sample.scene_fingerprint:x}'
                             f', this shard\'s {self.fingerprint:x}): refused')
        if sample.positions.shape != guides.x.shape:
            raise ShardError(f'guides of {sample.positions.shape[0]} x '
                             f'{sample.positions.shape[1]} nodes, this shard\'s groom has '
                             f'{guides.x.shape[0]} x {guides.x.shape[1]}: refused')

    def apply(self, sample) -> None:
        """Place this shard's ghosts from ``sample`` (checked with :meth:`check`)."""
        self.check(sample)
        self.head = head_pose(tuple(sample.head_position.tolist()),
                              tuple(sample.head_quaternion.tolist()))
        guide_x = sample.positions.astype(np.float64)
        self.tracker.step(TrackStep(0.0, 1, None, guide_x, self.head))
        self.stamp_ns = sample.t_ns
        self.counters.applied += 1

    def frame_id(self, pose_frame: str) -> str:
        """The frame of the shard's outputs: the guides' (the pose's) or ``head_frame``."""
        s = self.settings
        if s.output_frame == 'head':
            return s.head_frame or 'head'
        return pose_frame or s.fixed_frame or 'world'

    def encode(self, keys, frame_id: str) -> Dict[str, object]:
        """The messages ``keys`` (``points``, ``markers``) of this shard's strands after the
        last :meth:`apply`, as the guides node encodes the whole hair's
        (:class:`~hair_tracking.output.frame_encoder.FrameEncoder`): rows numbered and coloured
        as the whole hair's.  Returns key -> CDR bytes (the cloud's valid until the next)."""
        head_frame = self.settings.output_frame == 'head'
        rot = origin = None
        if head_frame:
            rot, origin = self.head.rotation.T, self.head.position
        tracker, rows = self.tracker, self.rows
        n = self.sim.ghosts.rest.shape[1]
        out = {}
        x = None
        if 'markers' in keys:
            x = tracker.rows_positions(rows)
            strands = self.head.to_head(x) if head_frame else x
            out['markers'] = self.encoder.markers(strands, frame_id, self.stamp_ns).data
        if 'points' in keys:
            if x is None:
                def write(words, stride):
                    return tracker.write_rows(rows, words, stride, rot, origin)
            else:
                def write(words, stride):
                    return points_to_records(words, stride, x, rot, origin)
            out['points'] = self.encoder.cloud(self.count, n, write, frame_id, self.stamp_ns,
                                               first=rows.start, total=self.total)
        return out
