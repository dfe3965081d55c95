"""``hair_sim_bag play``: publish a bag live, as ``ros2 bag play --clock`` does.

For every message, in log-time order: wait until its time has come on the wall clock (scaled
by ``rate``), publish ``rosgraph_msgs/Clock`` with the message's log time on ``/clock``, then
publish the message's raw serialized bytes on its topic (possibly remapped).  A node with
``use_sim_time:=true`` therefore sees the bag's own times, and each message arrives with the
clock already at its log time.  The bag side (reading, the schedule, stopping) is
:class:`hair_tracking.bags.play.Playback`; this module adds the rclpy publishers.

Publishers use the QoS recorded in the bag (``offered_qos_profiles``: reliability, durability,
depth) when present, else reliable / volatile / depth 100.  ``/clock`` is published reliable,
keep-last 10: rclpy's time source subscribes best effort (which a reliable publisher serves),
and a recorder, which matches the publisher's reliability, then loses no clock message.  Types
that the installed rclpy message packages
lack (e.g. ``tf2_msgs`` here) cannot be published: those topics are skipped with a warning.

:class:`BagPlayer` works on any rclpy node (publishing needs no spinning), so tests and the
live demo play a bag in-process from a thread while an executor spins the node under test.
"""
import importlib
import sys
import time
from typing import Callable, Dict, List, Optional, Sequence

from hair_tracking.bags import io as bag_io
from hair_tracking.bags.cli import finish_parser
from hair_tracking.bags.io import BagError, EXIT_CONTENT, EXIT_OK, EXIT_USAGE
from hair_tracking.bags.play import Playback

CLOCK_TOPIC = '/clock'


def message_class(msgtype: str):
    """The rclpy message class of 'pkg/msg/Type' (None when not installed)."""
    parts = msgtype.split('/')
    if len(parts) == 2:
        parts = [parts[0], 'msg', parts[1]]
    if len(parts) != 3:
        return None
    try:
        module = importlib.import_module(f'{parts[0]}.{parts[1]}')
        return getattr(module, parts[2])
    except (ImportError, AttributeError):
        return None


def check_topic_name(name: str, what: str) -> str:
    """``name`` made absolute, or BagError (EXIT_USAGE) saying why it is not a topic name."""
    from rclpy.exceptions import InvalidTopicNameException
    from rclpy.validate_full_topic_name import validate_full_topic_name
    full = '/' + name.strip().lstrip('/')
    try:
        validate_full_topic_name(full)
    except InvalidTopicNameException as exc:
        reason = str(exc).splitlines()[0].split(': ', 1)[-1].rstrip(':')
        raise BagError(f'{what}: {name!r} is not a valid topic name ({reason})',
                       EXIT_USAGE) from None
    return full


def parse_remaps(items: Sequence[str]) -> Dict[str, str]:
    """``['/a:=/b', ...]`` -> {'/a': '/b'} (names made absolute and validated)."""
    out = {}
    for item in items or ():
        if ':=' not in item:
            raise BagError(f'--remap {item!r}: expected FROM:=TO', EXIT_USAGE)
        a, b = item.split(':=', 1)
        out[check_topic_name(a, '--remap')] = check_topic_name(b, '--remap')
    return out


def _qos_from_bag(conn_qos):
    """rclpy QoSProfile from a rosbags Qos list (first profile), or the default."""
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
    reliable, transient, depth = True, False, 100
    if conn_qos:
        q = conn_qos[0]
        reliable = q.reliability.name != 'BEST_EFFORT'
        transient = q.durability.name == 'TRANSIENT_LOCAL'
        if q.history.name == 'KEEP_LAST' and q.depth > 0:
            depth = max(int(q.depth), 10)
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth,
                      reliability=(ReliabilityPolicy.RELIABLE if reliable
                                   else ReliabilityPolicy.BEST_EFFORT),
                      durability=(DurabilityPolicy.TRANSIENT_LOCAL if transient
                                  else DurabilityPolicy.VOLATILE))


class BagPlayer(Playback):
    """Publishes one bag through ``node`` (see module doc and :class:`Playback` for ``rate``,
    ``loop``, ``start_offset_s``, ``duration_s``, ``topics``, ``remap``); ``clock`` publish
    /clock before each message.  Topics whose message type rclpy lacks here are skipped with a
    warning.  Opening checks the bag (BagError).
    """

    def __init__(self, node, bag, *, rate: float = 1.0, loop: bool = False,
                 start_offset_s: float = 0.0, duration_s: Optional[float] = None,
                 topics: Optional[Sequence[str]] = None, remap: Optional[Dict[str, str]] = None,
                 clock: bool = True, log: Optional[Callable[[str], None]] = None,
                 now: Callable[[], float] = time.monotonic):
        from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
        from rosgraph_msgs.msg import Clock

        super().__init__(bag, rate=rate, loop=loop, start_offset_s=start_offset_s,
                         duration_s=duration_s, topics=topics, remap=remap, log=log, now=now)
        self.node = node
        self.clock = clock
        self.publishers = {}
        self.msgtypes = {}
        for info in self.infos:
            cls = message_class(info.msgtype)
            if cls is None:
                self.stats.skipped_topics.append(
                    f'{info.topic} ({info.msgtype}: message package not installed for rclpy)')
                self.log(f'warning: skipping {info.topic}: {info.msgtype} is not available '
                         f'to rclpy here')
                continue
            out = self.remap.get(info.topic, info.topic)
            self.publishers[info.topic] = node.create_publisher(
                cls, out, _qos_from_bag(self.qos_of.get(info.topic)))
            self.msgtypes[info.topic] = info.msgtype
        if not self.publishers:
            raise BagError(f'{self.bag}: nothing to play (no topic with an installed message '
                           f'type); its topics:\n{bag_io.format_topics(self.all_infos)}',
                           EXIT_CONTENT)
        self._clock_cls = Clock
        self.clock_pub = None
        if clock:
            self.clock_pub = node.create_publisher(
                Clock, CLOCK_TOPIC, QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10,
                                               reliability=ReliabilityPolicy.RELIABLE))

    def wait_for_subscribers(self, timeout_s: float, topics: Optional[Sequence[str]] = None
                             ) -> List[str]:
        """Wait up to ``timeout_s`` until each publisher has a subscriber; returns the topics
        still without one."""
        deadline = time.monotonic() + max(0.0, timeout_s)
        pubs = {t: p for t, p in self.publishers.items() if topics is None or t in topics}
        while True:
            lonely = [t for t, p in pubs.items() if p.get_subscription_count() == 0]
            if not lonely or time.monotonic() >= deadline or self.stopping():
                return lonely
            time.sleep(0.02)

    # ------------------------------------------------------------------ playing
    def _clock_msg(self, t_ns: int):
        from builtin_interfaces.msg import Time
        sec, nanosec = divmod(int(t_ns), 1_000_000_000)
        return self._clock_cls(clock=Time(sec=sec, nanosec=nanosec))

    def _publish(self, topic: str, t_ns: int, data: bytes) -> None:
        if self.clock_pub is not None:
            self.clock_pub.publish(self._clock_msg(t_ns))
            self.stats.clock += 1
        self.publishers[topic].publish(data)

    def play(self, progress: Optional[Callable[[int, int], None]] = None):
        """Publish the bag (once, or until :meth:`stop` with ``loop``); returns the stats."""
        return self.replay(self._publish, list(self.publishers), progress)

    def destroy(self) -> None:
        for p in list(self.publishers.values()) + ([self.clock_pub] if self.clock_pub else []):
            self.node.destroy_publisher(p)
        self.publishers.clear()
        self.clock_pub = None


# ================================================================ command line
def add_command(sub) -> None:
    """The ``play`` sub-command of ``hair_sim_bag`` (``sub``: its sub-parsers)."""
    p = sub.add_parser('play', help='publish a bag live with /clock (ros2 bag play --clock)')
    p.add_argument('bag', nargs='?', help='bag (default: the bundled walk sample)')
    p.add_argument('-r', '--rate', type=float, default=1.0, help='playback speed factor')
    p.add_argument('-l', '--loop', action='store_true', help='play again and again (Ctrl-C)')
    p.add_argument('--start-offset', type=float, default=0.0,
                   help='start this many seconds into the bag')
    p.add_argument('--duration', type=float, help='play this many seconds of the bag')
    p.add_argument('--topics', nargs='+', metavar='TOPIC', help='play only these topics')
    p.add_argument('--remap', nargs='+', default=[], metavar='FROM:=TO',
                   help='rename topics, e.g. --remap /head_pose:=/face/pose')
    p.add_argument('--no-clock', action='store_true', help='do not publish /clock')
    p.add_argument('--wait-for-subscribers', type=float, default=2.0, metavar='SECONDS',
                   help='wait up to this long for every topic to have a subscriber (default 2)')
    p.add_argument('--delay', type=float, default=0.0, help='sleep this long before playing')
    p.add_argument('--domain-id', type=int, help='ROS_DOMAIN_ID to use')
    finish_parser(p, main_play, 'no progress line')


def main_play(args) -> int:
    """``hair_sim_bag play`` (arguments from :func:`add_command`; ``args.stop`` the process's
    :class:`~hair_tracking.shutdown.StopRequest`): 0 when the bag was played or a stop was
    asked for."""
    import rclpy
    from rclpy.signals import SignalHandlerOptions

    from hair_tracking.bags.offline import progress_bar

    bag = args.bag or bag_io.bundled_bag()
    bag_io.bag_kind(bag)
    remap = parse_remaps(args.remap)
    if args.delay < 0 or args.wait_for_subscribers < 0:
        raise BagError('--delay and --wait-for-subscribers must be >= 0', EXIT_USAGE)
    kwargs = {} if args.domain_id is None else {'domain_id': args.domain_id}
    stop = args.stop
    # no rclpy signal handler: it would shut the context down under a publish in progress;
    # the stop request stops the player between messages (and wakes its waits) instead
    rclpy.init(args=None, signal_handler_options=SignalHandlerOptions.NO, **kwargs)
    node = player = None
    forget = None
    try:
        node = rclpy.create_node('hair_sim_bag_player')
        player = BagPlayer(node, bag, rate=args.rate, loop=args.loop,
                           start_offset_s=args.start_offset, duration_s=args.duration,
                           topics=args.topics, remap=remap, clock=not args.no_clock)
        forget = stop.on_request(player.stop)
        if args.wait_for_subscribers > 0:
            lonely = player.wait_for_subscribers(args.wait_for_subscribers)
            if lonely and not player.stopping():
                print(f'note: no subscriber yet on {", ".join(lonely)}; playing anyway',
                      file=sys.stderr)
        if args.delay > 0:
            player.sleep(args.delay)
        if not args.quiet:
            print(f'playing {bag}{" in a loop" if args.loop else ""} (Ctrl-C to stop)',
                  file=sys.stderr, flush=True)
        progress, close = progress_bar('play', args.quiet)
        stats = player.play(progress)
        close()
        print(stats.text())
        return EXIT_OK
    finally:
        if forget is not None:
            forget()
        if player is not None:
            player.destroy()
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
