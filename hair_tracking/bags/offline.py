"""Offline runs: head poses from a bag -> the hair -> a new bag, much faster than real time.

The engine behind ``hair_sim_bag run``.  It drives the same :class:`HairSimulator` and the same
:mod:`msg_adapters` encoders as the ``hair_sim`` node, at the recorded timestamps:

* every head pose of the bag (log-time order) is pushed with its header stamp and the hair is
  advanced to that stamp (fixed-dt substeps, integer nanoseconds);
* the outputs follow the node's schedule on the bag's clock: ``hair/points`` (PointCloud2) and
  ``hair/markers`` (MarkerArray) at ``publish_rate_hz``, ``diagnostics`` (DiagnosticArray) at
  ``diagnostics_rate_hz``, or after every pose with ``every_pose``;
* each output message is stamped with the stamp of the pose the hair was advanced to and
  logged at that pose's record time, so the output bag lines up with the input.

Nothing depends on the wall clock inside the messages (timings go to the summary only), so the
same bag and settings give byte-identical output messages.  Settings come from a scene (YAML
or preset name) and/or a ROS 2 params file of the node (``hair_sim: ros__parameters: ...``) and
``name=value`` overrides, validated by :mod:`hair_tracking.output.settings`.
"""
from dataclasses import dataclass, field
import functools
import math
import os
import struct
import sys
import time
from typing import Callable, Dict, List, Optional, Sequence

import numpy as np
import yaml

from hair_tracking.bags import io as bag_io
from hair_tracking.bags.io import BagError, EXIT_CONTENT, EXIT_FAILURE, EXIT_INPUT, EXIT_USAGE
from hair_tracking.core.param_table import NODE_NAME
from hair_tracking.core.params import ParamError
from hair_tracking.core.scene import Scene, SceneError
from hair_tracking.output.params_check import load_params_file, node_parameters, ParamsFileError
from hair_tracking.output.settings import check_groom_file, make_settings, Settings
from hair_tracking.output.diagnostics import HairHealth, HARDWARE_ID, make_status, status_name
from hair_tracking.output.frame_encoder import FrameEncoder

POINTS_TOPIC = '/hair/points'
MARKERS_TOPIC = '/hair/markers'
DIAGNOSTICS_TOPIC = '/diagnostics'
HEAD_POSE_TOPIC = '/head_pose'
GUIDE_POINTS_TOPIC = '/hair/guides/points'
GUIDE_MARKERS_TOPIC = '/hair/guides/markers'
#: The topic of each message of a frame (:data:`hair_tracking.output.frame_encoder.OUTPUTS`).
TOPICS = {'points': POINTS_TOPIC, 'markers': MARKERS_TOPIC, 'guide_points': GUIDE_POINTS_TOPIC,
          'guide_markers': GUIDE_MARKERS_TOPIC}
DIAGNOSTIC_NAME = status_name(NODE_NAME)


# ================================================================ settings
def read_params_file(path: str, node_name: str = NODE_NAME) -> Dict[str, object]:
    """Flat ``{name: value}`` of a ROS 2 params file for ``node_name``: the sections that apply
    to ``/node_name`` as rcl matches them (``/**``, ``node_name``, ``/node_name`` ...; nested
    keys become dotted names), read by the node's own reader
    (:func:`hair_tracking.output.params_check.load_params_file`)."""
    try:
        data = load_params_file(path)
    except ParamsFileError as exc:
        raise BagError(str(exc), EXIT_USAGE) from None
    values = node_parameters(data, '/' + node_name)
    if values is None:
        raise BagError(f'{path}: no "{node_name}: ros__parameters:" (or "/**") section; '
                       f'sections: {", ".join(map(str, data)) or "none"}', EXIT_USAGE)
    return values


def parse_overrides(items: Sequence[str]) -> Dict[str, object]:
    """``name=value`` strings -> dict (values parsed as YAML: 8, 8.0, true, [0, 0, -9.81])."""
    out = {}
    for item in items:
        if '=' not in item:
            raise BagError(f'--set {item!r}: expected name=value', EXIT_USAGE)
        name, text = item.split('=', 1)
        try:
            out[name.strip()] = yaml.safe_load(text)
        except yaml.YAMLError as exc:
            raise BagError(f'--set {item!r}: bad value: {exc}', EXIT_USAGE) from None
    return out


def load_settings(scene: Optional[str] = None, params_file: Optional[str] = None,
                  overrides: Optional[Dict[str, object]] = None) -> Settings:
    """Validated node settings: ``scene`` (YAML path or preset) as the base scene, then the
    params file's values, then ``overrides``; BagError (EXIT_USAGE) naming the bad entry, or
    (EXIT_INPUT) saying why a groom file (``groom.file``) cannot be imported."""
    from hair_tracking.resources import config_path

    values: Dict[str, object] = {}
    if params_file:
        values.update(read_params_file(params_file))
    values.update(overrides or {})
    base_name = scene or values.get('scene_file') or None
    base = None
    try:
        if base_name:
            try:
                path = config_path(str(base_name))
            except FileNotFoundError as exc:
                raise BagError(str(exc), EXIT_USAGE) from None
            base = Scene.from_yaml(path)
        settings = make_settings(values, base)
    except (SceneError, ParamError) as exc:
        raise BagError(f'bad settings: {exc}', EXIT_USAGE) from None
    try:
        check_groom_file(settings.scene)
    except ParamError as exc:
        raise BagError(str(exc), EXIT_INPUT) from None
    return settings


# ================================================================ encoding
def diagnostics_bytes(stamp_ns: int, level: int, message: str, values: Dict[str, str]) -> bytes:
    """A serialized diagnostic_msgs/DiagnosticArray with one status named DIAGNOSTIC_NAME."""
    ts = bag_io.typestore()
    t = ts.types
    sec, nanosec = divmod(int(stamp_ns), 1_000_000_000)
    status = t['diagnostic_msgs/msg/DiagnosticStatus'](
        level=level, name=DIAGNOSTIC_NAME, message=message, hardware_id=HARDWARE_ID,
        values=[t['diagnostic_msgs/msg/KeyValue'](key=k, value=v) for k, v in values.items()])
    arr = t['diagnostic_msgs/msg/DiagnosticArray'](
        header=t['std_msgs/msg/Header'](stamp=t['builtin_interfaces/msg/Time'](
            sec=sec, nanosec=nanosec), frame_id=''), status=[status])
    return bytes(ts.serialize_cdr(arr, 'diagnostic_msgs/msg/DiagnosticArray'))


def pose_stamped_bytes(t_ns, position, quaternion, frame_id) -> bytes:
    """A serialized geometry_msgs/PoseStamped (byte-identical to the rosbags serializer,
    tested; no message objects are built): one ``struct`` pack of a layout made once per frame
    name (:func:`_pose_stamped_layout`)."""
    layout, head, frame = _pose_stamped_layout(frame_id)
    sec, nanosec = bag_io.stamp_parts(t_ns)
    px, py, pz = position
    qx, qy, qz, qw = quaternion
    return layout.pack(head, sec, nanosec, frame, float(px), float(py), float(pz), float(qx),
                       float(qy), float(qz), float(qw))


@functools.lru_cache(maxsize=16)
def _pose_stamped_layout(frame_id: str):
    """``(struct, encapsulation, frame bytes)`` of a PoseStamped in ``frame_id``: the frame
    name as a CDR string with the padding that aligns the seven float64 after it (laid out by
    :class:`msg_adapters.cdr.CdrWriter`)."""
    from msg_adapters.cdr import CdrWriter, ENCAPSULATION_LE
    w = CdrWriter()
    w.time(0, 0)
    w.string(frame_id)
    w.align(8)
    frame = w.template()[8:]
    return struct.Struct(f'<4siI{len(frame)}s7d'), ENCAPSULATION_LE, frame


# ================================================================ schedule
class Schedule:
    """Periodic ticks on the bag's clock: ``due(t)`` is True once per period at the first
    time at or after each tick of the grid ``t_first + k * period`` (missed ticks are skipped,
    like an rcl timer on a jumping sim clock)."""

    def __init__(self, period_ns: int):
        self.period_ns = max(1, int(period_ns))
        self.next_ns: Optional[int] = None

    def due(self, t_ns: int) -> bool:
        if self.next_ns is None:
            self.next_ns = t_ns + self.period_ns
            return True
        if t_ns < self.next_ns - self.period_ns:        # time went backwards: restart grid
            self.next_ns = t_ns + self.period_ns
            return True
        if t_ns >= self.next_ns:
            k = (t_ns - self.next_ns) // self.period_ns + 1
            self.next_ns += k * self.period_ns
            return True
        return False


# ================================================================ the run
@dataclass
class RunOptions:
    """What to read and write besides the settings (see ``hair_sim_bag run --help``)."""

    topic: Optional[str] = None
    head_frame: Optional[str] = None
    fixed_frame: Optional[str] = None
    start_offset_s: float = 0.0
    duration_s: Optional[float] = None
    storage: Optional[str] = None
    overwrite: bool = False
    compress: bool = False
    points: bool = True
    markers: bool = True
    diagnostics: bool = True
    head_pose: bool = True
    every_pose: bool = False


@dataclass
class RunSummary:
    input: str
    output: str
    source_topic: str
    poses: int = 0               # poses read (valid messages)
    rejected: int = 0            # invalid pose messages + poses the head track rejected
    resets: int = 0
    frames: int = 0              # hair frames written (points and/or markers)
    substeps: int = 0
    substeps_dropped: int = 0
    bag_duration_s: float = 0.0
    setup_s: float = 0.0         # hair build + kernel compile/cache load
    loop_s: float = 0.0          # simulate + encode + write
    sim_ms: List[float] = field(default_factory=list)
    max_stretch: float = 0.0
    max_penetration_m: float = 0.0
    topics: Dict[str, int] = field(default_factory=dict)
    strands: int = 0
    nodes: int = 0
    finite: bool = True
    groom: str = ''              # an imported groom's report line ('' for the procedural one)
    stopped_after: Optional[int] = None   # poses run when a stop was asked for (else None)
    run_duration_s: float = 0.0  # the stamps' span of the poses run (all but after a stop)

    @property
    def ms_per_pose(self) -> float:
        return self.loop_s * 1e3 / max(1, self.poses)

    @property
    def realtime_factor(self) -> float:
        """Seconds of recording run (:attr:`run_duration_s`) per second of the loop."""
        return self.run_duration_s / self.loop_s if self.loop_s > 0 else math.inf

    def text(self) -> str:
        sim = np.asarray(self.sim_ms) if self.sim_ms else np.zeros(1)
        lines = [
            f'input:  {self.input} ({self.source_topic}, {self.poses} poses, '
            f'{self.bag_duration_s:.2f} s)',
            f'output: {self.output}',
            '  ' + ', '.join(f'{t}: {n}' for t, n in self.topics.items()),
        ] + ([self.groom] if self.groom else []) + [
            f'hair: {self.strands} strands x {self.nodes} points; frames written: {self.frames}'
            + (f' ({self.loop_s * 1e3 / self.frames:.2f} ms of the loop per frame)'
               if self.frames else ''),
            f'time: setup {self.setup_s:.2f} s (build + kernels); loop {self.loop_s:.2f} s = '
            f'{self.ms_per_pose:.2f} ms per pose (simulation median {np.median(sim):.2f} ms, '
            f'p95 {np.percentile(sim, 95):.2f} ms)',
            f'real-time factor: {self.realtime_factor:.1f}x '
            f'({self.run_duration_s:.2f} s of recording in {self.loop_s:.2f} s)',
            f'max stretch: {self.max_stretch * 100:.4f} %; deepest head penetration: '
            f'{self.max_penetration_m * 1e3:.3f} mm',
            f'poses rejected: {self.rejected}; resets: {self.resets}; substeps: {self.substeps} '
            f'run, {self.substeps_dropped} dropped',
        ]
        if self.stopped_after is not None:
            lines.append(f'stopped after {self.stopped_after} of {self.poses} poses; the output '
                         f'holds what was written until then')
        if not self.finite:
            lines.append('ERROR: the hair became non-finite')
        return '\n'.join(lines)


class Progress:
    """A one-line progress bar on a terminal (nothing when ``stream`` is not a TTY)."""

    def __init__(self, total: int, stream=None, label: str = 'run'):
        self.total = max(1, total)
        self.stream = stream if stream is not None else sys.stderr
        self.enabled = bool(getattr(self.stream, 'isatty', lambda: False)())
        self.label = label
        self._last = 0.0
        self._start = time.perf_counter()

    def update(self, done: int, force: bool = False) -> None:
        if not self.enabled:
            return
        now = time.perf_counter()
        if not force and now - self._last < 0.1:
            return
        self._last = now
        frac = min(1.0, done / self.total)
        width = 30
        bar = '#' * int(frac * width) + '-' * (width - int(frac * width))
        rate = done / max(1e-9, now - self._start)
        self.stream.write(f'\r{self.label} [{bar}] {frac * 100:5.1f}% {done}/{self.total} '
                          f'({rate:.0f}/s)')
        self.stream.flush()

    def close(self) -> None:
        if self.enabled:
            self.update(self.total, force=True)
            self.stream.write('\n')
            self.stream.flush()


def progress_bar(label: str, quiet: bool = False):
    """``(progress(done, total), close())`` of a command's progress line: a :class:`Progress`
    labelled ``label``, made at the first call (so a command that fails before any work draws
    none), or nothing at all when ``quiet``."""
    bar = None

    def progress(done: int, total: int) -> None:
        nonlocal bar
        if quiet:
            return
        if bar is None:
            bar = Progress(total, label=label)
        bar.update(done)

    def close() -> None:
        if bar is not None:
            bar.close()
    return progress, close


def run_bag(input_path: str, output_path: str, settings: Settings,
            options: Optional[RunOptions] = None,
            progress: Optional[Callable[[int, int], None]] = None,
            after_setup: Optional[Callable[[], None]] = None,
            should_stop: Optional[Callable[[], bool]] = None) -> RunSummary:
    """Simulate the hair on the head poses of ``input_path`` and write ``output_path``.

    Returns the summary; raises BagError for unusable input or output (nothing is left at the
    output path then).  ``progress(done, total)`` is called as poses are processed,
    ``after_setup()`` once the hair is built and the kernels are loaded, before the loop (the
    ``hair_sim_bag run`` executable freezes its start-up objects there); ``should_stop()``
    before each pose: when it says so the run ends there and the output is closed as it is (a
    complete bag of the poses run, ``summary.stopped_after``).
    """
    from hair_tracking.core.head_track import PoseResult
    from hair_tracking.simulator import HairSimulator, warm_up

    opt = options or RunOptions()
    scene = settings.scene
    fixed_frame = opt.fixed_frame
    poses = bag_io.read_head_poses(input_path, topic=opt.topic, head_frame=opt.head_frame,
                                   fixed_frame=fixed_frame, start_offset_s=opt.start_offset_s,
                                   duration_s=opt.duration_s)
    if not (opt.points or opt.markers or opt.diagnostics or opt.head_pose):
        raise BagError('nothing to write: every output topic is switched off', EXIT_USAGE)
    summary = RunSummary(input=str(input_path), output=str(output_path),
                         source_topic=f'{poses.topic} [{poses.msgtype.split("/")[-1]}]'
                         + (f' frame {poses.child_frame_id}' if poses.child_frame_id else ''))
    summary.poses = len(poses)
    summary.rejected = poses.invalid
    summary.bag_duration_s = poses.duration_s

    world = poses.frame_id or settings.fixed_frame
    head_name = poses.child_frame_id or settings.head_frame
    head_out = settings.output_frame == 'head'
    out_frame = head_name if head_out else world
    if not out_frame:
        raise BagError('the output frame is empty (set fixed_frame / head_frame)', EXIT_CONTENT)

    t_setup = time.perf_counter()
    sim = HairSimulator(scene)  # the groom read and built once
    tiny = warm_up(scene, sim.parallel)   # every kernel compiled or loaded here, not in the loop
    if opt.points:              # and the clouds' point writers, on the tiny copy's hair
        warm = FrameEncoder(settings)
        for guides, ns in ((False, 'hair'), (True, 'guides')):
            warm.cloud(*tiny.record_writer(guides, head_out), 'warmup', 1, ns)
    summary.groom = sim.groom_note
    enc = FrameEncoder(settings)
    if after_setup is not None:
        after_setup()
    summary.setup_s = time.perf_counter() - t_setup

    custom = {'hair_tracking.input': os.path.basename(str(input_path)),
              'hair_tracking.source_topic': poses.topic}
    writer = bag_io.BagWriter(output_path, storage=opt.storage, overwrite=opt.overwrite,
                              custom_data=custom, compress=opt.compress)
    try:
        qos = bag_io.qos_profile(reliable=True, depth=1)
        if opt.head_pose:
            writer.add_topic(HEAD_POSE_TOPIC, 'geometry_msgs/msg/PoseStamped',
                             bag_io.qos_profile(reliable=True, depth=10))
        if opt.points:
            writer.add_topic(POINTS_TOPIC, 'sensor_msgs/msg/PointCloud2', qos)
        if opt.markers:
            writer.add_topic(MARKERS_TOPIC, 'visualization_msgs/msg/MarkerArray', qos)
        guides = bool(settings.publish_guides)
        keys = [k for k, on in (('points', opt.points), ('markers', opt.markers),
                                ('guide_points', guides and opt.points),
                                ('guide_markers', guides and opt.markers)) if on]
        if guides and opt.points:
            writer.add_topic(GUIDE_POINTS_TOPIC, 'sensor_msgs/msg/PointCloud2', qos)
        if guides and opt.markers:
            writer.add_topic(GUIDE_MARKERS_TOPIC, 'visualization_msgs/msg/MarkerArray', qos)
        if opt.diagnostics:
            writer.add_topic(DIAGNOSTICS_TOPIC, 'diagnostic_msgs/msg/DiagnosticArray',
                             bag_io.qos_profile(reliable=True, depth=10))

        publish = Schedule(int(round(settings.publish_period * 1e9)))
        diag = Schedule(int(round(1e9 / settings.diagnostics_rate_hz)))
        diag_state = _Diagnostics()
        total = len(poses)
        worst_stretch = worst_depth = 0.0
        t_loop = time.perf_counter()
        for i in range(total):
            if should_stop is not None and should_stop():
                summary.stopped_after = i
                break
            t = int(poses.t_ns[i])
            log_t = int(poses.log_ns[i])
            p, q = poses.position[i], poses.quaternion[i]
            measure = False
            stretch = depth = None
            s0 = time.perf_counter()
            res = sim.push_pose(t, p, q)
            sim.advance_to(t)
            summary.sim_ms.append((time.perf_counter() - s0) * 1e3)
            if opt.head_pose and res is not PoseResult.REJECTED:
                writer.write(HEAD_POSE_TOPIC, log_t, pose_stamped_bytes(t, p, q, world))
            if (opt.points or opt.markers) and (opt.every_pose or publish.due(t)):
                frame = sim.frame(head_frame=head_out, copy=False)
                strands = frame.strands
                if not np.all(np.isfinite(strands)):
                    summary.finite = False
                    raise BagError(f'the hair became non-finite at t = {t * 1e-9:.6f} s '
                                   f'(pose {i}); no output written', EXIT_FAILURE)
                stamp = frame.t_ns              # the time the hair state is at (node: same)
                for key, msg in enc.frame(sim, keys, out_frame, stamp, head_out, frame).items():
                    writer.write(TOPICS[key], log_t, msg.data)
                summary.frames += 1
                measure = True
            if opt.diagnostics and diag.due(t):
                stretch, depth = sim.max_stretch(), sim.penetration()
                writer.write(DIAGNOSTICS_TOPIC, log_t,
                             diag_state.message(sim, log_t, poses.invalid, stretch, depth,
                                                out_frame))
                measure = True
            if measure or i == total - 1:       # worst values over the written frames
                if stretch is None:
                    stretch, depth = sim.max_stretch(), sim.penetration()
                worst_stretch = max(worst_stretch, stretch)
                worst_depth = max(worst_depth, depth)
            if progress is not None:
                progress(i + 1, total)
        summary.loop_s = time.perf_counter() - t_loop
        run = total if summary.stopped_after is None else summary.stopped_after
        if run > 1:
            summary.run_duration_s = float(poses.t_ns[run - 1] - poses.t_ns[0]) * 1e-9
        summary.max_stretch = worst_stretch
        summary.max_penetration_m = worst_depth
        summary.rejected = poses.invalid + sim.track.counters['rejected']
        summary.resets = sim.counters.resets
        summary.substeps = sim.counters.substeps
        summary.substeps_dropped = sim.counters.substeps_dropped
        final = sim.frame(copy=False).strands
        summary.strands, summary.nodes = int(final.shape[0]), int(final.shape[1])
        summary.topics = dict(writer.counts)
        writer.close()
    except BaseException:
        writer.abort()
        raise
    return summary


class _Diagnostics:
    """The node's diagnostic status without its wall-clock timings (so runs are repeatable):
    same name, keys and levels (:mod:`hair_tracking.output.diagnostics`)."""

    def __init__(self):
        self.health = HairHealth()

    def message(self, sim, stamp_ns, invalid, stretch, depth, frame_id) -> bytes:
        rejected = invalid + sim.track.counters['rejected']
        problems = self.health.problems(sim, rejected)
        values = HairHealth.values(sim, stretch, depth, rejected, 0)
        values['output_frame'] = frame_id
        status = make_status(1 if problems else 0, problems, values)
        return diagnostics_bytes(stamp_ns, status.level, status.message, status.values)
