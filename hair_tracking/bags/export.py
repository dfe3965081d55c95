"""``hair_sim_bag export``: a run's hair as an animated USD ``BasisCurves`` file.

Every ``sensor_msgs/PointCloud2`` of the hair topic (default ``/hair/points``; one row per
strand, as the node and ``hair_sim_bag run`` write it) becomes one time sample of the points of
the linear BasisCurves prim ``/groom/hair`` (:class:`hair_tracking.grooms.usd.AnimatedCurves`):
time code ``k`` is the ``k``-th cloud, ``timeCodesPerSecond`` and ``framesPerSecond`` the clouds'
median rate, so the animation plays at the recording's pace in Blender, Omniverse or Unreal.  The
curve vertex counts are time-sampled too when the hair changes shape (a rebuilt groom); the
first cloud is also the attributes' default value, so a reader of still grooms
(``groom.file``) takes the file as the hair's first frame.  Units metres, z up (REP-103), in the
clouds' frame (``frame_id``, said in the summary).  Clouds are read one at a time.
"""
from pathlib import Path
from typing import Dict

import numpy as np

from hair_tracking.bags import io as bag_io
from hair_tracking.bags.io import BagError, EXIT_CONTENT, EXIT_USAGE

USD_EXTENSIONS = ('.usd', '.usda', '.usdc')
CLOUD_TYPE = 'sensor_msgs/msg/PointCloud2'


def export_usd(path, output, topic: str = '/hair/points', overwrite: bool = False) -> Dict:
    """Write the clouds of ``topic`` in the bag ``path`` to the USD file ``output`` (see the
    module docstring); returns a summary: frames, strands, points per strand, rate, frame id."""
    from msg_adapters.pointcloud import pointcloud2_to_strands
    from hair_tracking.grooms.usd import AnimatedCurves

    out = Path(output)
    if out.suffix.lower() not in USD_EXTENSIONS:
        raise BagError(f'{output}: the output must be a USD file '
                       f'({", ".join(USD_EXTENSIONS)})', EXIT_USAGE)
    bag_io.check_output_path(output, overwrite)
    tmp = out.with_name(f'.{out.stem}.partial{out.suffix}')
    summary: Dict[str, object] = {'frame_id': ''}
    stamps = []
    try:
        with bag_io.open_bag(path) as reader:
            info = next((i for i in bag_io.topics(reader) if i.topic == topic), None)
            if info is None:
                raise BagError(f'{path}: no topic {topic!r}; its topics:\n'
                               + bag_io.format_topics(bag_io.topics(reader)), EXIT_CONTENT)
            if info.msgtype != CLOUD_TYPE:
                raise BagError(f'{path}: {topic} is a {info.msgtype}, not a PointCloud2',
                               EXIT_CONTENT)
        usd = AnimatedCurves(str(tmp))
        try:
            for t_ns, msg in bag_io.cloud_messages(path, topic):
                strands = pointcloud2_to_strands(msg)[0]
                if not stamps:
                    summary['frame_id'] = str(msg.header.frame_id)
                    summary['strands'], summary['points_per_strand'] = strands.shape[:2]
                usd.add(strands)
                stamps.append(t_ns)
        except ValueError as exc:                  # a cloud that is no strands, a bad stamp
            raise BagError(f'{path}: {topic}: {exc}', EXIT_CONTENT) from None
        if not stamps:
            raise BagError(f'{path}: {topic} has no messages', EXIT_CONTENT)
        steps = np.diff(np.asarray(stamps, dtype=np.int64))
        steps = steps[steps > 0]
        rate = round(1e9 / float(np.median(steps)), 3) if steps.size else 1.0
        usd.save(rate)
        tmp.replace(out)
    finally:
        if tmp.exists():
            tmp.unlink()
    summary.update(frames=len(stamps), rate_hz=rate,
                   duration_s=(stamps[-1] - stamps[0]) * 1e-9)
    return summary


def add_command(sub, finish_parser) -> None:
    """The ``export`` sub-command of ``hair_sim_bag`` (``sub``: its sub-parsers)."""
    p = sub.add_parser('export', help="a run's hair as an animated USD BasisCurves file")
    p.add_argument('bag', help='an output bag of hair_sim_bag run or of the node')
    p.add_argument('-o', '--output', required=True, help='the .usd / .usda / .usdc to write')
    p.add_argument('--topic', default='/hair/points', help='the hair cloud topic')
    p.add_argument('--overwrite', action='store_true', help='replace an existing output')
    finish_parser(p, main_export, 'no summary line')


def main_export(args) -> int:
    """``hair_sim_bag export``: 0 when the file is written."""
    s = export_usd(args.bag, args.output, args.topic, args.overwrite)
    if not args.quiet:
        print(f'wrote {args.output}: {s["frames"]} frames of {s["strands"]} strands x '
              f'{s["points_per_strand"]} points at {s["rate_hz"]:g} frames a second '
              f'({s["duration_s"]:.2f} s; metres, z up, frame {s["frame_id"]!r})')
    return bag_io.EXIT_OK
