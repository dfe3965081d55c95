"""``hair_sim_bag record``: subscribe to topics and write their raw messages to a bag.

For users without ``ros2 bag``.  Topics are discovered on the ROS graph (their type from
``get_topic_names_and_types``) and subscribed with ``raw=True``, so the serialized CDR bytes
go into the bag untouched.  The subscription QoS adapts to the publishers, as ``ros2 bag
record`` does: reliable only if every publisher is reliable, transient-local only if every
publisher is; the publishers' QoS is stored as the topic's ``offered_qos_profiles`` so a later
``ros2 bag play`` offers the same.  Messages are logged at the node clock's time on arrival
(``use_sim_time``: the ``/clock`` time).  Under ``use_sim_time`` nothing is logged before the
first ``/clock`` message: messages that arrive earlier are held (at most
:data:`MAX_HELD_BEFORE_CLOCK`) and logged at the first clock time, in their order, and the
summary says how many (a time-0 message would make a bag a billion seconds long).

The bag is written under a temporary name and moved into place when recording stops (duration,
message count, idle timeout, Ctrl-C or SIGTERM); nothing is left at the output path if
recording fails (the bag side is :class:`hair_tracking.bags.record.Recording`).
:class:`BagRecorder` works on any node spun by the caller's executor, so tests and the live
demo record in-process.
"""
import sys
import time
from typing import Callable, Dict, List, Optional, Sequence, Tuple

from hair_tracking.bags import io as bag_io
from hair_tracking.bags.cli import finish_parser
from hair_tracking.bags.io import BagError, EXIT_OK, EXIT_USAGE
from hair_tracking.bags.record import Recording
from hair_tracking.ros.bag_play import check_topic_name, message_class

#: never recorded with --all (rosout is noise; parameter events are per node)
_SKIP_ALL = ('/rosout', '/parameter_events')
#: Messages held, under ``use_sim_time``, until the first ``/clock`` gives them a time; later
#: ones are dropped (and counted) until it comes.
MAX_HELD_BEFORE_CLOCK = 1000


def _subscription_qos(infos):
    """(rclpy QoSProfile, rosbags Qos list) compatible with every publisher in ``infos``."""
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
    reliable = bool(infos) and all(
        i.qos_profile.reliability == ReliabilityPolicy.RELIABLE for i in infos)
    transient = bool(infos) and all(
        i.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL for i in infos)
    depth = 100
    qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth,
                     reliability=(ReliabilityPolicy.RELIABLE if reliable
                                  else ReliabilityPolicy.BEST_EFFORT),
                     durability=(DurabilityPolicy.TRANSIENT_LOCAL if transient
                                 else DurabilityPolicy.VOLATILE))
    offered = []
    for i in infos[:1]:
        p = i.qos_profile
        offered.append(bag_io.qos_profile(
            reliable=p.reliability == ReliabilityPolicy.RELIABLE,
            depth=max(1, int(p.depth or 1)),
            transient_local=p.durability == DurabilityPolicy.TRANSIENT_LOCAL))
    return qos, offered


class BagRecorder(Recording):
    """Records ``topics`` (or every topic with ``all_topics``) seen by ``node`` into ``output``.

    Call :meth:`discover` periodically (a timer does it every ``discover_period_s``), spin the
    node, then :meth:`close` (moves the bag into place, returns its path) or :meth:`abort`.
    """

    def __init__(self, node, output, topics: Sequence[str] = (), *, all_topics: bool = False,
                 storage: Optional[str] = None, overwrite: bool = False,
                 compress: bool = False, discover_period_s: float = 0.2,
                 log: Optional[Callable[[str], None]] = None):
        if not topics and not all_topics:
            raise BagError('name the topics to record, or pass --all', EXIT_USAGE)
        super().__init__(output, [check_topic_name(t, 'record') for t in topics],
                         storage=storage, overwrite=overwrite, compress=compress, log=log)
        self.node = node
        self.all_topics = all_topics
        self.subs: Dict[str, object] = {}
        #: messages that arrived before the first /clock (use_sim_time), waiting for a time
        self.held: List[Tuple[str, bytes]] = []
        self.held_total = 0           # messages logged at the first clock time
        self.dropped_before_clock = 0
        from rclpy.clock import Clock, ClockType
        # steady clock: with use_sim_time a ROS-time timer would not run before /clock does
        self._timer = node.create_timer(discover_period_s, self.discover,
                                        clock=Clock(clock_type=ClockType.STEADY_TIME))
        self.discover()

    @property
    def topics(self) -> List[str]:
        return sorted(self.subs)

    def discover(self) -> None:
        """Subscribe to wanted topics that have appeared on the graph."""
        graph = dict(self.node.get_topic_names_and_types())
        names = list(self.wanted)
        if self.all_topics:
            names += [t for t in graph if t not in names and t not in _SKIP_ALL]
        for topic in names:
            if topic in self.subs or topic in self.skipped or topic not in graph:
                continue
            types = graph[topic]
            if len(types) != 1:
                self.skip(topic, f'several types on the graph: {", ".join(types)}')
                continue
            msgtype = types[0]
            cls = message_class(msgtype)
            if cls is None:
                self.skip(topic, f'{msgtype} is not available to rclpy here')
                continue
            if msgtype not in bag_io.typestore().types:
                self.skip(topic, f'{msgtype} is unknown to the rosbags Jazzy typestore')
                continue
            infos = self.node.get_publishers_info_by_topic(topic)
            if not infos:
                continue                 # wait for a publisher to choose a compatible QoS
            qos, offered = _subscription_qos(infos)
            self.add_topic(topic, msgtype, offered[0] if offered else None)
            self.subs[topic] = self.node.create_subscription(
                cls, topic, self._callback(topic), qos, raw=True)

    def _callback(self, topic: str):
        def on_message(data: bytes) -> None:
            self.arrived(topic, self.node.get_clock().now().nanoseconds, data)
        return on_message

    def arrived(self, topic: str, t_ns: int, data: bytes) -> None:
        """Log a message that arrived at the node clock's ``t_ns``; a clock at 0 under
        ``use_sim_time`` has not started (no ``/clock`` yet): the message is held for it."""
        if t_ns <= 0 and self.node.get_clock().ros_time_is_active:
            if len(self.held) < MAX_HELD_BEFORE_CLOCK:
                self.held.append((topic, data))
            else:
                self.dropped_before_clock += 1
            return
        if self.held:
            held, self.held = self.held, []
            self.held_total += len(held)
            for t, d in held:
                self.write(t, t_ns, d)
        self.write(topic, t_ns, data)

    def summary(self) -> str:
        lines = [super().summary()]
        if self.held_total:
            lines.append(f'  {self.held_total} messages arrived before the first /clock: '
                         f'logged at its time')
        if self.held or self.dropped_before_clock:
            lines.append(f'  {len(self.held) + self.dropped_before_clock} messages arrived '
                         f'before any /clock and were not logged (use_sim_time: is /clock '
                         f'published?)')
        return '\n'.join(lines)

    def _teardown(self) -> None:
        for sub in self.subs.values():
            self.node.destroy_subscription(sub)
        self.subs = {}
        if self._timer is not None:
            self.node.destroy_timer(self._timer)
            self._timer = None

    def close(self):
        """Stop recording and move the bag into place; returns its path."""
        self._teardown()
        return super().close()

    def abort(self) -> None:
        """Stop recording and leave nothing behind."""
        self._teardown()
        super().abort()


def add_command(sub) -> None:
    """The ``record`` sub-command of ``hair_sim_bag`` (``sub``: its sub-parsers)."""
    p = sub.add_parser('record', help='subscribe to topics (raw) and write a bag')
    p.add_argument('topics', nargs='*', metavar='TOPIC', help='topics to record')
    p.add_argument('-a', '--all', action='store_true', help='record every topic that appears')
    p.add_argument('-o', '--output', required=True,
                   help='bag to create: NAME.mcap / NAME.db3 or a folder name')
    p.add_argument('--storage', choices=bag_io.STORAGES, help='mcap (default) or sqlite3')
    p.add_argument('--compress', action='store_true', help='zstd-compress (MCAP chunks)')
    p.add_argument('--duration', type=float, help='stop after this many seconds')
    p.add_argument('--max-messages', type=int, help='stop after this many messages')
    p.add_argument('--idle-timeout', type=float,
                   help='stop when nothing arrived for this many seconds (after the first '
                        'message)')
    p.add_argument('--use-sim-time', action='store_true',
                   help='log messages at /clock time instead of the wall clock')
    p.add_argument('--domain-id', type=int, help='ROS_DOMAIN_ID to use')
    p.add_argument('--overwrite', action='store_true', help='replace an existing output')
    finish_parser(p, main_record, 'no progress line')


def main_record(args) -> int:
    """``hair_sim_bag record`` (arguments from :func:`add_command`; ``args.stop`` the process's
    :class:`~hair_tracking.shutdown.StopRequest`): 0 when recording ended, by its limits or a
    stop request (the bag is complete either way)."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter
    from rclpy.signals import SignalHandlerOptions

    for name in ('duration', 'idle_timeout'):
        v = getattr(args, name)
        if v is not None and not v > 0:
            raise BagError(f'--{name.replace("_", "-")} must be > 0, got {v}', EXIT_USAGE)
    if args.max_messages is not None and args.max_messages < 1:
        raise BagError('--max-messages must be >= 1', EXIT_USAGE)
    if not args.topics and not args.all:
        raise BagError('name the topics to record, or pass --all', EXIT_USAGE)
    for t in args.topics:
        check_topic_name(t, 'record')
    bag_io.check_output_path(args.output, args.overwrite)
    bag_io.output_storage(args.output, args.storage)

    stop = args.stop
    kwargs = {} if args.domain_id is None else {'domain_id': args.domain_id}
    # no rclpy signal handler (it would shut the context down under a take in progress): the
    # loop below ends at the stop request, within one wait of the executor
    rclpy.init(args=None, signal_handler_options=SignalHandlerOptions.NO, **kwargs)
    node = rec = None
    try:
        overrides = [Parameter('use_sim_time', Parameter.Type.BOOL, True)] \
            if args.use_sim_time else []
        node = rclpy.create_node('hair_sim_bag_recorder', parameter_overrides=overrides)
        rec = BagRecorder(node, args.output, args.topics, all_topics=args.all,
                          storage=args.storage, overwrite=args.overwrite,
                          compress=args.compress)
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        start = time.monotonic()
        last_print = 0.0
        if not args.quiet:
            print(f'recording to {args.output} (Ctrl-C to stop)', file=sys.stderr)
        while not stop.requested:
            executor.spin_once(timeout_sec=0.05)     # steady-clock timeout, /clock or not
            now = time.monotonic()
            if args.duration is not None and now - start >= args.duration:
                break
            if args.max_messages is not None and rec.messages >= args.max_messages:
                break
            if args.idle_timeout is not None and rec.last_arrival is not None \
                    and now - rec.last_arrival >= args.idle_timeout:
                break
            if not args.quiet and sys.stderr.isatty() and now - last_print > 0.5:
                last_print = now
                sys.stderr.write(f'\r{rec.messages} messages on {len(rec.subs)} topic(s)')
                sys.stderr.flush()
        if not args.quiet and sys.stderr.isatty():
            sys.stderr.write('\n')
        path = rec.close()
        print(rec.summary())
        print(f'wrote {path}')
        if stop.requested and not args.quiet:
            print(f'stopped by {stop.signal_name}; the bag is complete', file=sys.stderr)
        return EXIT_OK
    except BaseException:
        if rec is not None:
            rec.abort()
        raise
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
