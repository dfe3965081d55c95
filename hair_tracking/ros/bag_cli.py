"""``hair_sim_bag``, the executable: the offline sub-commands of :mod:`hair_tracking.bags.cli`
(info, import, run, render) and the two that join a ROS graph, ``play``
(:mod:`hair_tracking.ros.bag_play`) and ``record`` (:mod:`hair_tracking.ros.bag_record`).

rclpy is imported only when ``play`` or ``record`` runs: the offline sub-commands need no ROS
installation.
"""
import sys
from typing import List, Optional

from hair_tracking.bags import cli
from hair_tracking.ros import bag_play, bag_record

#: The sub-commands added to the offline ones, in the order of the help.
LIVE = (bag_play.add_command, bag_record.add_command)


def build_parser():
    """The ``hair_sim_bag`` parser with every sub-command."""
    return cli.build_parser(LIVE)


def main(argv: Optional[List[str]] = None) -> int:
    """Console entry point ``hair_sim_bag``; returns the exit code (see
    :mod:`hair_tracking.bags.cli`)."""
    return cli.main(argv, LIVE)


if __name__ == '__main__':
    sys.exit(main())
