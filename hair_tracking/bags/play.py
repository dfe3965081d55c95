"""The bag side of ``hair_sim_bag play``: a bag's messages on the wall-clock schedule of their log
times (ROS-free; :class:`hair_tracking.ros.bag_play.BagPlayer` publishes them).

:class:`Playback` opens and checks a bag, picks its topics and the time slice, and hands every
message, in log-time order, to a ``send(topic, log time [ns], CDR bytes)`` callable when its
time has come on the wall clock (scaled by ``rate``).  ROS 1 bags are converted to CDR on the
fly (rosbags).  Stopping (:meth:`Playback.stop` from another thread, :meth:`Playback.interrupt`
from a signal handler) is seen between messages and at least every 0.1 s while waiting.
"""
from dataclasses import dataclass, field
import sys
import threading
import time
from typing import Callable, Dict, List, Optional, Sequence

from hair_tracking.bags import io as bag_io
from hair_tracking.bags.io import BagError, EXIT_CONTENT, EXIT_USAGE


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


class Playback:
    """One bag's messages on a wall-clock schedule (see module doc).

    ``rate`` > 0 speed factor; ``loop`` play again until stopped; ``start_offset_s`` /
    ``duration_s`` [s] select a slice from the bag start; ``topics`` a subset (names as in the
    bag); ``remap`` {bag topic: published topic} (counted under the published name).  Opening
    checks the bag and these (BagError).  ``infos`` are the topics chosen, ``qos_of`` {topic:
    the rosbags QoS profiles the bag recorded}.  ``now()`` [s] is the monotonic clock the
    schedule runs on (a test injects one).
    """

    def __init__(self, bag, *, rate: float = 1.0, loop: bool = False,
                 start_offset_s: float = 0.0, duration_s: Optional[float] = None,
                 topics: Optional[Sequence[str]] = None, remap: Optional[Dict[str, str]] = None,
                 log: Optional[Callable[[str], None]] = None,
                 now: Callable[[], float] = time.monotonic):
        self.now = now
        if not (rate > 0 and rate < float('inf')):
            raise BagError(f'--rate must be > 0, got {rate}', EXIT_USAGE)
        if start_offset_s < 0 or (duration_s is not None and not duration_s > 0):
            raise BagError('--start-offset must be >= 0 and --duration > 0', EXIT_USAGE)
        self.bag = str(bag)
        self.rate = float(rate)
        self.loop = loop
        self.log = log or (lambda text: print(text, file=sys.stderr))
        self.remap = dict(remap or {})
        self.stats = PlayStats()
        self._stop = threading.Event()
        self._interrupted = False        # set by a signal handler (see interrupt)
        with bag_io.open_bag(self.bag) as reader:
            self.is_ros1 = not reader.is2
            self.all_infos = bag_io.topics(reader)
            start = reader.start_time if reader.message_count else 0
            self.qos_of = {c.topic: getattr(getattr(c, 'ext', None), 'offered_qos_profiles',
                                            None)
                           for c in reader.connections}
        names = {i.topic for i in self.all_infos}
        want = None
        if topics:
            want = {'/' + t.lstrip('/') for t in topics}
            missing = sorted(want - names)
            if missing:
                raise BagError(f'{self.bag}: no topic(s) {", ".join(missing)} in the bag; its '
                               f'topics:\n{bag_io.format_topics(self.all_infos)}', EXIT_CONTENT)
        unknown = sorted(set(self.remap) - names)
        if unknown:
            self.log(f'warning: --remap of topic(s) not in the bag: {", ".join(unknown)}')
        self.infos = [i for i in self.all_infos if want is None or i.topic in want]
        self.start_ns = start + int(round(start_offset_s * 1e9))
        self.stop_ns = (self.start_ns + int(round(duration_s * 1e9))
                        if duration_s is not None else None)

    # ------------------------------------------------------------------ control
    def stop(self) -> None:
        """Ask a running :meth:`replay` (in another thread) to stop soon."""
        self._stop.set()

    def interrupt(self) -> None:
        """Ask :meth:`replay` to stop from a signal handler in its own thread: sets a flag only
        (an Event takes a lock the interrupted code may hold), seen between messages and at
        least every 0.1 s while waiting."""
        self._interrupted = True

    def stopping(self) -> bool:
        return self._interrupted or self._stop.is_set()

    def sleep(self, seconds: float) -> bool:
        """Wait ``seconds`` unless asked to stop first; returns whether asked."""
        deadline = self.now() + seconds
        while not self.stopping():
            left = deadline - self.now()
            if left <= 0:
                return False
            self._stop.wait(min(left, 0.1))
        return True

    # ------------------------------------------------------------------ playing
    def replay(self, send: Callable[[str, int, bytes], None], topics: Sequence[str],
               progress: Optional[Callable[[int, int], None]] = None) -> PlayStats:
        """``send(topic, t_ns, data)`` every message of ``topics`` when its time comes (once,
        or until :meth:`stop` with ``loop``); returns the stats."""
        st = self.stats
        wall0 = self.now()
        while not self.stopping():
            st.loops += 1
            self._replay_once(send, set(topics), progress)
            if not self.loop:
                break
        st.wall_s = self.now() - wall0
        st.interrupted = self.stopping()
        return st

    def _replay_once(self, send, topics, progress) -> None:
        st = self.stats
        with bag_io.open_bag(self.bag) as reader:
            conns = [c for c in reader.connections if c.topic in topics]
            total = sum(int(c.msgcount or 0) for c in conns)
            first = None
            wall0 = self.now()
            done = 0
            for conn, t_ns, raw in bag_io.messages(reader, conns, self.start_ns, self.stop_ns):
                if self.stopping():
                    return
                if first is None:
                    first = t_ns
                due = wall0 + (t_ns - first) * 1e-9 / self.rate
                if self.sleep(due - self.now()):
                    return
                st.max_lag_ms = max(st.max_lag_ms, (self.now() - due) * 1e3)
                data = raw
                if self.is_ros1:
                    data = reader.typestore.ros1_to_cdr(raw, conn.msgtype)
                send(conn.topic, t_ns, bytes(data))
                out = self.remap.get(conn.topic, conn.topic)
                st.published[out] = st.published.get(out, 0) + 1
                st.bag_s = max(st.bag_s, (t_ns - first) * 1e-9)
                done += 1
                if progress is not None:
                    progress(done, total)
