"""The bag side of ``hair_sim_bag record``: raw messages into a new bag as they arrive (ROS-free;
:class:`hair_tracking.ros.bag_record.BagRecorder` subscribes to the topics).

:class:`Recording` writes through :class:`~hair_tracking.bags.io.BagWriter` (a temporary name,
moved into place by :meth:`Recording.close`; nothing is left at the output path after
:meth:`Recording.abort`) and counts what it wrote and what it skipped, for the summary.
"""
import sys
import time
from typing import Callable, Dict, List, Optional, Sequence

from hair_tracking.bags import io as bag_io


class Recording:
    """A bag being recorded: the ``wanted`` topics (absolute names), written to ``output``.

    :meth:`add_topic` registers a topic once its type is known, :meth:`write` appends one raw
    message; ``counts``, ``skipped``, ``messages``, ``first_ns`` and ``last_arrival``
    (``time.monotonic()`` of the last message) describe the recording so far; ``on_message
    (topic, t_ns, data)``, when set, sees every message written.
    """

    def __init__(self, output, wanted: Sequence[str] = (), *, storage: Optional[str] = None,
                 overwrite: bool = False, compress: bool = False,
                 log: Optional[Callable[[str], None]] = None):
        self.wanted = list(wanted)
        self.log = log or (lambda text: print(text, file=sys.stderr))
        self.writer = bag_io.BagWriter(output, storage=storage, overwrite=overwrite,
                                       compress=compress,
                                       custom_data={'hair_tracking.recorder': 'hair_sim_bag'})
        self.counts: Dict[str, int] = {}
        self.skipped: Dict[str, str] = {}
        self.messages = 0
        self.first_ns: Optional[int] = None
        self.last_arrival = None          # time.monotonic() of the last message
        self.on_message: Optional[Callable[[str, int, bytes], None]] = None

    def missing(self) -> List[str]:
        """Wanted topics neither added nor skipped yet."""
        return [t for t in self.wanted if t not in self.counts and t not in self.skipped]

    def add_topic(self, topic: str, msgtype: str, qos=None) -> None:
        """Record ``topic`` of ``msgtype`` from now on (``qos``: the rosbags QoS it was
        offered with, stored for a later ``ros2 bag play``)."""
        self.writer.add_topic(topic, msgtype, qos)
        self.counts[topic] = 0

    def skip(self, topic: str, why: str) -> None:
        """Leave ``topic`` out, with a warning and a line in the summary."""
        self.skipped[topic] = why
        self.log(f'warning: not recording {topic}: {why}')

    def write(self, topic: str, t_ns: int, data: bytes) -> None:
        """Append one raw message of a registered topic, logged at ``t_ns`` [ns]."""
        self.writer.write(topic, t_ns, data)
        self.counts[topic] += 1
        self.messages += 1
        if self.first_ns is None:
            self.first_ns = t_ns
        self.last_arrival = time.monotonic()
        if self.on_message is not None:
            self.on_message(topic, t_ns, data)

    def close(self):
        """Move the bag into place; returns its path."""
        return self.writer.close()

    def abort(self) -> None:
        """Leave nothing behind."""
        self.writer.abort()

    def summary(self) -> str:
        lines = [f'recorded {self.messages} messages on {len(self.counts)} topic(s)']
        for t in sorted(self.counts):
            lines.append(f'  {t}: {self.counts[t]}')
        for t, why in sorted(self.skipped.items()):
            lines.append(f'  skipped {t}: {why}')
        for t in self.missing():
            lines.append(f'  never appeared: {t}')
        return '\n'.join(lines)
