"""``hair_sim``: the ROS 2 node that makes hair follow a head pose stream.

    ros2 run hair_tracking hair_sim_node --ros-args --params-file config/hair_sim.yaml
    hair_sim_node --ros-args -p groom.guides:=32 -r head_pose:=/face/pose

Inputs (all remappable): ``head_pose`` (geometry_msgs/PoseStamped) and ``head_transform``
(geometry_msgs/TransformStamped), the head in a fixed frame, ``p_fixed = position + R(q) @
p_head``, subscribed with the sensor-data QoS so reliable and best-effort publishers both
connect; with ``use_tf``, the transform on ``/tf`` whose child frame is ``head_frame`` or, with
``head_frame_prefix``, the first child frame starting with it (REP-155 face trackers publish
``face_<id>``), kept until it goes stale (:mod:`hair_tracking.ros.pose_intake`).  The header
stamp drives the simulation; a stamp older than the last one resets the hair (a looping bag).

TF: one tree of ``/tf_static`` and ``/tf`` for everything that reads it (the head,
``gravity_frame``, ``body.frame``, the collider slots' frames, the people's faces) and the head
pose broadcast on ``/tf`` (``publish_tf``): :mod:`hair_tracking.ros.frames`.

Outputs, each advertised only while its feature is on and built only when somebody subscribes:
``hair/points`` (organized PointCloud2, one row per strand, x y z float32, ``strand`` index,
packed ``rgb``), ``hair/markers`` (MarkerArray, ``line_list`` or ``line_strips``),
``hair/guides/points`` and ``hair/guides/markers`` (``publish_guides``), the head collider on
``hair/head`` (``head_marker``), the body's bust and the collider slots on ``hair/colliders``,
the guides' state and the settings for ghost shards (``shards``, ``publish_guide_state``):
:mod:`hair_tracking.ros.publishing`; ``/diagnostics``: :mod:`hair_tracking.ros.health`; with
``people.source: hri`` every tracked face's hair: :mod:`hair_tracking.ros.faces`.

Service ``~/reset`` (std_srvs/Trigger): hair back to its rest shape at the current head pose.

Parameters: one per row of the parameter table (:mod:`hair_tracking.core.param_table`), declared
and validated by :mod:`hair_tracking.ros.parameters`; an accepted change is a frozen
:class:`~hair_tracking.output.settings.Settings` snapshot that the next step applies (a groom
change rebuilds the hair at the current head pose).

Everything runs in one thread (a SingleThreadedExecutor), so callbacks never race.
"""
import argparse
import sys
import time
from typing import Callable, Dict, List, Optional

from geometry_msgs.msg import PoseStamped, TransformStamped
import numba
from rclpy.exceptions import ParameterException
from rclpy.node import Node
from rclpy.parameter import Parameter
from std_srvs.srv import Trigger

from hair_tracking import executable
from hair_tracking.bags.warmup import warm_up
from hair_tracking.core.param_table import NODE_NAME
from hair_tracking.core.params import ParamError
from hair_tracking.core.scene import SceneError
from hair_tracking.grooms.polylines import GroomFileError
from hair_tracking.output.params_check import params_files_problem, rcl_arguments_problem
from hair_tracking.ros.faces import FaceHair
from hair_tracking.ros.frames import Frames, SceneFrames
from hair_tracking.ros.health import NodeHealth
from hair_tracking.ros.load_shedding import LoadShedder
from hair_tracking.ros.parameters import NodeParameters
from hair_tracking.ros.pose_intake import PoseIntake
from hair_tracking.ros.publishing import Publishing
from hair_tracking.ros.spin_node import spin_node
from hair_tracking.ros.topics import pose_qos
from hair_tracking.simulator import HairSimulator


class HairSimNode(Node):
    """The ``hair_sim`` node (see the module docstring): the wiring of its parts.

    ``context``, ``parameter_overrides`` and ``cli_args`` are passed to :class:`rclpy.node.Node`
    so tests and benchmarks can run it in-process; ``work_clock()`` [s] times the work of each
    step and publication that load shedding weighs (tests inject a deterministic one).
    Construction declares the parameters, builds the simulator, warms up the kernels
    (``warmup``) and only then subscribes.  Invalid start parameters raise
    :class:`~hair_tracking.core.params.ParamError` naming the parameter.

    Parts: :attr:`parameters` (:class:`~hair_tracking.ros.parameters.NodeParameters`),
    :attr:`frames` and :attr:`scene_frames` (:mod:`~hair_tracking.ros.frames`), :attr:`intake`
    (:class:`~hair_tracking.ros.pose_intake.PoseIntake`), :attr:`publishing`
    (:class:`~hair_tracking.ros.publishing.Publishing`), :attr:`health`
    (:class:`~hair_tracking.ros.health.NodeHealth`), :attr:`faces`
    (:class:`~hair_tracking.ros.faces.FaceHair`, ``people.source: hri``; else None).
    """

    #: The pose intake's class (a benchmark's subclass marks its stages).
    intake_type = PoseIntake

    def __init__(self, node_name: str = NODE_NAME, *, context=None,
                 parameter_overrides: Optional[List[Parameter]] = None,
                 cli_args: Optional[List[str]] = None, namespace: Optional[str] = None,
                 work_clock: Callable[[], float] = time.perf_counter):
        super().__init__(node_name, context=context, cli_args=cli_args, namespace=namespace,
                         parameter_overrides=parameter_overrides)
        self.parameters = NodeParameters(self, self._on_params_changed)
        settings = self._settings = self.parameters.pending
        self._apply_threads(settings.numba_threads)
        self.shedder = LoadShedder(settings.load_shedding_budget)
        self.work_clock = work_clock     # times the step and publish work (load shedding)
        try:
            self.sim = HairSimulator(settings.scene, clock=work_clock)
        except GroomFileError as e:
            raise ParamError('groom.file', str(e)) from None
        if self.sim.groom_note:
            self.get_logger().info(self.sim.groom_note)
        if settings.warmup:
            secs = warm_up(settings.scene, self.sim.parallel)
            self.get_logger().info(f'kernels and encoders ready in {secs:.2f} s')
        self.rebuilds = 0
        self.intake = self.intake_type(self)
        self.frames = Frames(self)
        self.frames.broadcasting(settings.publish_tf)
        self.scene_frames = SceneFrames(self, self.frames, lambda: self.sim,
                                        lambda: self._settings, self.intake.pose_frame)
        self.scene_frames.watch()
        self.frames.listeners.append(self._on_tf)
        self.publishing = Publishing(self)
        self.health = NodeHealth(self)
        self.create_service(Trigger, '~/reset', self._on_reset)
        period = settings.publish_period
        self._publish_timer = self.create_timer(period, self.publishing.on_timer)
        self._idle_timer = self.create_timer(period, self.intake.on_idle)
        self._diag_timer = self.create_timer(1.0 / settings.diagnostics_rate_hz,
                                             self.health.on_timer)
        qos = pose_qos(settings.pose_queue_depth)
        self.create_subscription(PoseStamped, 'head_pose', self.intake.on_pose, qos)
        self.create_subscription(TransformStamped, 'head_transform', self.intake.on_pose, qos)
        self._subscribe_tf()
        scene = settings.scene
        #: people.source hri: every tracked face's hair (ros/faces.py); None for one head
        self.faces = FaceHair(self, lambda: self.parameters.pending, self.frames,
                              self.publishing.encoder) \
            if scene.people.source == 'hri' else None
        ghosts = self.sim.ghosts.count if self.sim.ghosts is not None else 0
        self.get_logger().info(
            f'ready: {self.sim.guides.count} guides ({scene.groom.guide_nodes} nodes), '
            f'{ghosts} ghosts ({scene.groom.ghost_nodes} nodes), solver {scene.solver.type}, '
            f'publishing at {settings.publish_rate_hz:g} Hz')

    # ================================================================ state
    @property
    def settings(self):
        """The settings the node runs with now (a frozen
        :class:`~hair_tracking.output.settings.Settings`)."""
        return self._settings

    @property
    def outputs(self):
        """The strand outputs advertised now, by key (:mod:`hair_tracking.ros.publishing`)."""
        return self.publishing.outputs

    @property
    def rejected(self) -> int:
        """Head poses dropped so far (malformed, NaN, zero quaternion ...)."""
        return self.intake.rejected

    @property
    def frames_built(self) -> int:
        """Frames the simulator built for publishing markers."""
        return self.publishing.frames_built

    def output_frame_id(self) -> str:
        """frame_id of the published hair (see ``output_frame``)."""
        return self.publishing.output_frame_id()

    def diagnostics(self):
        """The node's health now (one DiagnosticStatus)."""
        return self.health.status()

    # ================================================================ TF
    def _subscribe_tf(self) -> None:
        """/tf and /tf_static once the head (use_tf) or the scene's frames read them (at
        start or when a parameter change sets one)."""
        if self._settings.use_tf or self.scene_frames.needs_tf():
            self.frames.subscribe('use_tf, gravity_frame, body.frame or a collider on a TF '
                                  'frame (head_pose and head_transform are subscribed)')

    def _on_tf(self, msg, static: bool) -> None:
        """A message stored in the tree: gravity follows ``gravity_frame``, the head comes
        from /tf with ``use_tf``."""
        if self._settings.gravity_frame and self.intake.has_pose:
            self.scene_frames.update_gravity()
        if self._settings.use_tf:
            self.intake.on_tf(msg, static)

    # ================================================================ parameters
    def _on_params_changed(self, old, new) -> None:
        """An accepted change: timers, threads and publishers are not part of a step, they
        follow at once (the rest waits for the next step, :meth:`apply_pending`)."""
        if new.publish_rate_hz != old.publish_rate_hz:
            period_ns = int(round(1e9 / new.publish_rate_hz))
            self._publish_timer.timer_period_ns = period_ns
            self._idle_timer.timer_period_ns = period_ns
        if new.diagnostics_rate_hz != old.diagnostics_rate_hz:
            self._diag_timer.timer_period_ns = int(round(1e9 / new.diagnostics_rate_hz))
        if new.numba_threads != old.numba_threads:
            self._apply_threads(new.numba_threads)
        self.publishing.sync(new)
        self.frames.broadcasting(new.publish_tf)

    def _apply_threads(self, wanted: int) -> None:
        """Threads of numba's parallel kernels (0 = all it was started with)."""
        most = numba.config.NUMBA_NUM_THREADS
        n = most if wanted <= 0 else min(wanted, most)
        if wanted > most:
            self.get_logger().warn(f'numba_threads {wanted} > NUMBA_NUM_THREADS {most}: '
                                   f'using {most}')
        numba.set_num_threads(n)
        self.numba_threads = n

    def apply_pending(self) -> None:
        """Adopt the pending snapshot (start of every step/publication); rebuild if needed."""
        new = self.parameters.pending
        if new is self._settings:
            return
        old, self._settings = self._settings, new
        if new.scene != old.scene:
            try:
                rebuilt = self.sim.update_scene(new.scene)
            except GroomFileError as e:      # the file changed since the change was checked
                self.get_logger().error(f'groom.file: {e}; the hair is kept')
                self._settings = old
                self.parameters.keep(old)
                return
            if rebuilt:
                self.shedder.reset()
                self.rebuilds += 1
                self.get_logger().info(
                    f'groom changed: hair rebuilt ({self.sim.guides.count} guides, '
                    f'{self.sim.ghosts.count if self.sim.ghosts is not None else 0} ghosts)'
                    + (f'; {self.sim.groom_note}' if self.sim.groom_note else ''))
            self.scene_frames.scene_changed()
            self._subscribe_tf()
        self.publishing.publish_scene()
        self.publishing.invalidate()

    # ================================================================ service
    def _on_reset(self, request, response):
        self.apply_pending()
        self.sim.reset()
        self.publishing.invalidate()
        response.success = True
        response.message = 'hair reset to its rest shape at the current head pose'
        self.get_logger().info(response.message)
        return response

    def warn_unknown_parameters(self, argv: List[str]) -> Dict[str, List[str]]:
        """:meth:`~hair_tracking.ros.parameters.NodeParameters.warn_unknown`."""
        return self.parameters.warn_unknown(argv)


# ==================================================================== executable
def make_parser() -> argparse.ArgumentParser:
    """The command line of ``hair_sim_node`` in front of ``--ros-args``."""
    parser = argparse.ArgumentParser(
        prog='hair_sim_node',
        description='ROS 2 node that makes hair follow a head-pose stream: subscribes '
                    'head_pose (PoseStamped) and head_transform (TransformStamped), with use_tf '
                    '/tf and /tf_static (TFMessage); publishes hair/points (PointCloud2), '
                    'hair/markers (MarkerArray), hair/head (Marker, the head collider), '
                    'hair/colliders (MarkerArray, the body\'s bust, body.bust), /tf (the '
                    'head pose, publish_tf), /diagnostics, with publish_guides '
                    'hair/guides/points and hair/guides/markers, and with shards or '
                    'publish_guide_state hair/guides/state (GuideState) and hair/scene (the '
                    'settings, latched) for hair_sim_ghosts; offers ~/reset. Every setting '
                    'is a ROS parameter (see config/hair_sim.yaml and docs/node.md).',
        epilog='ROS arguments follow --ros-args, e.g. hair_sim_node --ros-args '
               '--params-file config/hair_sim.yaml -p scene_file:=long_hair '
               '-r head_pose:=/face/pose')
    executable.add_arguments(parser)
    return parser


def main(args=None) -> int:
    """Console entry point ``hair_sim_node``: init, spin until a stop is asked for, clean up.

    ``args`` is the whole command line (``sys.argv`` by default): the options before
    ``--ros-args`` are this executable's (``--help``, the process settings of
    :mod:`hair_tracking.executable`), the rest goes to rclpy.  Returns 0 once stopped (SIGINT or
    SIGTERM, in any state: :mod:`hair_tracking.shutdown`), 2 when the start parameters are
    invalid (the message names the parameter and the allowed values).
    """
    argv = list(sys.argv if args is None else args)
    split = argv.index('--ros-args') if '--ros-args' in argv else len(argv)
    options = make_parser().parse_args(argv[1:split])
    problem = params_files_problem(argv)      # before rcl, whose parse error is a traceback
    if problem:
        print(f'[hair_sim] {problem}', file=sys.stderr)
        return 2
    with executable.started() as stop:
        try:
            done = executable.apply(options)
        except ValueError as e:
            print(f'[hair_sim] {e}', file=sys.stderr)
            return 2

        def make_node() -> HairSimNode:
            node = HairSimNode()
            node.warn_unknown_parameters(argv)
            return node

        def user_error(e: Exception) -> Optional[str]:
            if isinstance(e, (ParamError, SceneError, ParameterException)):
                return f'[hair_sim] invalid parameters: {e}'
            if isinstance(e, RuntimeError):  # rcl refused the ROS arguments that
                problem = rcl_arguments_problem(e)     # params_files_problem passed
                return None if problem is None else f'[hair_sim] {problem}'
            return None

        return spin_node(NODE_NAME, make_node, argv[:1] + argv[split:], stop, done,
                         options.gc_freeze, user_error)


if __name__ == '__main__':
    sys.exit(main())
