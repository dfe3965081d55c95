"""``hair_sim_bag play``: publish a bag live, as ``ros2 bag play --clock`` does.

For every message, in log-time order: wait until its time has come on the wall clock (scaled
by ``rate``), publish ``rosgraph_msgs/Clock`` with the message's log time on ``/clock``, then
publish the message's raw serialized bytes on its topic (possibly remapped).  A node with
``use_sim_time:=true`` therefore sees the bag's own times, and each message arrives with the
clock already at its log time.  ROS 1 bags are converted to CDR on the fly (rosbags).

Publishers use the QoS recorded in the bag (``offered_qos_profiles``: reliability, durability,
depth) when present, else reliable / volatile / depth 100.  ``/clock`` is published reliable,
keep-last 10: rclpy's time source subscribes best effort (which a reliable publisher serves),
and a recorder, which matches the publisher's reliability, then loses no clock message.  Types
that the installed rclpy message packages
lack (e.g. ``tf2_msgs`` here) cannot be published: those topics are skipped with a warning.

:class:`BagPlayer` works on any rclpy node (publishing needs no spinning), so tests and the
live demo play a bag in-process from a thread while an executor spins the node under test.
"""
from dataclasses import dataclass, field
import importlib
import sys
import threading
import time
from typing import Callable, Dict, List, Optional, Sequence

from hair_tracking.bags import io as bag_io
from hair_tracking.bags.io import BagError, EXIT_CONTENT, EXIT_OK, EXIT_USAGE

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


@dataclass
class PlayStats:
    published: Dict[str, int] = field(default_factory=dict)
    clock: int = 0
    loops: int = 0
    skipped_topics: List[str] = field(default_factory=list)
    wall_s: float = 0.0
    bag_s: float = 0.0
    max_lag_ms: float = 0.0          # worst lateness of a message against its schedule
    interrupted: bool = False

    def text(self) -> str:
        total = sum(self.published.values())
        lines = [f'played {total} messages ({self.clock} /clock) in {self.wall_s:.2f} s '
                 f'({self.bag_s:.2f} s of bag'
                 + (f', {self.loops} loops' if self.loops > 1 else '')
                 + f'); worst lateness {self.max_lag_ms:.1f} ms'
                 + ('; interrupted' if self.interrupted else '')]
        for t, n in sorted(self.published.items()):
            lines.append(f'  {t}: {n}')
        for t in self.skipped_topics:
            lines.append(f'  skipped {t}')
        return '\n'.join(lines)


class BagPlayer:
    """Publishes one bag through ``node`` (see module doc).

    ``rate`` > 0 speed factor; ``start_offset_s`` / ``duration_s`` [s] select a slice from the
    bag start; ``topics`` a subset (names as in the bag); ``remap`` {bag topic: published
    topic}; ``clock`` publish /clock before each message.  Opening checks the bag (BagError).
    """

    def __init__(self, node, bag, *, rate: float = 1.0, loop: bool = False,
                 start_offset_s: float = 0.0, duration_s: Optional[float] = None,
                 topics: Optional[Sequence[str]] = None, remap: Optional[Dict[str, str]] = None,
                 clock: bool = True, log: Optional[Callable[[str], None]] = None):
        from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
        from rosgraph_msgs.msg import Clock

        if not (rate > 0 and rate < float('inf')):
            raise BagError(f'--rate must be > 0, got {rate}', EXIT_USAGE)
        if start_offset_s < 0 or (duration_s is not None and not duration_s > 0):
            raise BagError('--start-offset must be >= 0 and --duration > 0', EXIT_USAGE)
        self.node = node
        self.bag = str(bag)
        self.rate = float(rate)
        self.loop = loop
        self.clock = clock
        self.log = log or (lambda text: print(text, file=sys.stderr))
        self.remap = dict(remap or {})
        self.stats = PlayStats()
        self._stop = threading.Event()
        self._interrupted = False        # set by a signal handler (see interrupt)
        with bag_io.open_bag(self.bag) as reader:
            self.is_ros1 = not reader.is2
            infos = bag_io.topics(reader)
            start = reader.start_time if reader.message_count else 0
            qos_of = {c.topic: getattr(getattr(c, 'ext', None), 'offered_qos_profiles', None)
                      for c in reader.connections}
        names = {i.topic for i in infos}
        want = None
        if topics:
            want = {'/' + t.lstrip('/') for t in topics}
            missing = sorted(want - names)
            if missing:
                raise BagError(f'{self.bag}: no topic(s) {", ".join(missing)} in the bag; its '
                               f'topics:\n{bag_io.format_topics(infos)}', EXIT_CONTENT)
        unknown = sorted(set(self.remap) - names)
        if unknown:
            self.log(f'warning: --remap of topic(s) not in the bag: {", ".join(unknown)}')
        self.start_ns = start + int(round(start_offset_s * 1e9))
        self.stop_ns = (self.start_ns + int(round(duration_s * 1e9))
                        if duration_s is not None else None)
        self.publishers = {}
        self.msgtypes = {}
        for info in infos:
            if want is not None and info.topic not in want:
                continue
            cls = message_class(info.msgtype)
            if cls is None:
                self.stats.skipped_topics.append(
                    f'{info.topic} ({info.msgtype}: message package not installed for rclpy)')
                self.log(f'warning: skipping {info.topic}: {info.msgtype} is not available '
                         f'to rclpy here')
                continue
            out = self.remap.get(info.topic, info.topic)
            self.publishers[info.topic] = node.create_publisher(
                cls, out, _qos_from_bag(qos_of.get(info.topic)))
            self.msgtypes[info.topic] = info.msgtype
        if not self.publishers:
            raise BagError(f'{self.bag}: nothing to play (no topic with an installed message '
                           f'type); its topics:\n{bag_io.format_topics(infos)}', EXIT_CONTENT)
        self._clock_cls = Clock
        self.clock_pub = None
        if clock:
            self.clock_pub = node.create_publisher(
                Clock, CLOCK_TOPIC, QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10,
                                               reliability=ReliabilityPolicy.RELIABLE))

    # ------------------------------------------------------------------ control
    def stop(self) -> None:
        """Ask a running :meth:`play` (in another thread) to stop soon."""
        self._stop.set()

    def interrupt(self) -> None:
        """Ask :meth:`play` to stop from a signal handler in its own thread: sets a flag only
        (an Event takes a lock the interrupted code may hold), seen between messages and at
        least every 0.1 s while waiting."""
        self._interrupted = True

    def stopping(self) -> bool:
        return self._interrupted or self._stop.is_set()

    def sleep(self, seconds: float) -> bool:
        """Wait ``seconds`` unless asked to stop first; returns whether asked."""
        deadline = time.monotonic() + seconds
        while not self.stopping():
            left = deadline - time.monotonic()
            if left <= 0:
                return False
            self._stop.wait(min(left, 0.1))
        return True

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

    def play(self, progress: Optional[Callable[[int, int], None]] = None) -> PlayStats:
        """Publish the bag (once, or until :meth:`stop` with ``loop``); returns the stats."""
        st = self.stats
        wall0 = time.monotonic()
        while not self.stopping():
            st.loops += 1
            self._play_once(progress)
            if not self.loop:
                break
        st.wall_s = time.monotonic() - wall0
        st.interrupted = self.stopping()
        return st

    def _play_once(self, progress) -> None:
        st = self.stats
        with bag_io.open_bag(self.bag) as reader:
            conns = [c for c in reader.connections if c.topic in self.publishers]
            total = sum(int(c.msgcount or 0) for c in conns)
            first = None
            wall0 = time.monotonic()
            done = 0
            for conn, t_ns, raw in bag_io.messages(reader, conns, self.start_ns, self.stop_ns):
                if self.stopping():
                    return
                if first is None:
                    first = t_ns
                due = wall0 + (t_ns - first) * 1e-9 / self.rate
                if self.sleep(due - time.monotonic()):
                    return
                st.max_lag_ms = max(st.max_lag_ms, (time.monotonic() - due) * 1e3)
                if self.clock_pub is not None:
                    self.clock_pub.publish(self._clock_msg(t_ns))
                    st.clock += 1
                data = raw
                if self.is_ros1:
                    data = reader.typestore.ros1_to_cdr(raw, conn.msgtype)
                self.publishers[conn.topic].publish(bytes(data))
                out = self.remap.get(conn.topic, conn.topic)
                st.published[out] = st.published.get(out, 0) + 1
                st.bag_s = max(st.bag_s, (t_ns - first) * 1e-9)
                done += 1
                if progress is not None:
                    progress(done, total)

    def destroy(self) -> None:
        for p in list(self.publishers.values()) + ([self.clock_pub] if self.clock_pub else []):
            self.node.destroy_publisher(p)
        self.publishers.clear()
        self.clock_pub = None


# ================================================================ command line
def main_play(args) -> int:
    """``hair_sim_bag play`` (arguments from :mod:`hair_tracking.bags.cli`; ``args.stop`` the
    process's :class:`~hair_tracking.shutdown.StopRequest`): 0 when the bag was played or a
    stop was asked for."""
    import rclpy
    from rclpy.signals import SignalHandlerOptions

    from hair_tracking.bags.offline import Progress

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
    bar = None
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

        def progress(done, total):
            nonlocal bar
            if args.quiet:
                return
            if bar is None:
                bar = Progress(total, label='play')
            bar.update(done)

        stats = player.play(progress)
        if bar is not None:
            bar.close()
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
