"""``hair_sim_bag render``: pictures of a hair output bag that people can look at.

Reads the hair from ``/hair/points`` (organized PointCloud2, one row per strand) or, failing
that, ``/hair/markers`` (MarkerArray LINE_LIST / LINE_STRIP), the head from ``/head_pose`` and
the health from ``/diagnostics``, and writes into a new folder:

* ``hair.gif``: the strands over time (``--fps`` pictures per second of recording, at most
  ``--max-frames``), seen from the side (x forward, z up) and/or the front (y left, z up);
* ``hair.png``: six moments side by side (always);
* ``frames/frame_NNNNN.png``: every picture as a PNG (``--png``);
* ``diagnostics.png``: every numeric diagnostic value over time (max stretch, penetration,
  substeps, rejected poses, timings ...), when the bag has ``/diagnostics``.

With ``--frame head`` (default) the hair is drawn in the head frame (REP-103: x forward, y left,
z up), with the head collider outline (from the node's ``/hair/head`` marker when the bag has
it), so the motion of the hair relative to the head is what moves; the head pose at each
picture is the newest ``/head_pose`` at or before its stamp.  With
``--frame world`` the view follows the hair's centre.  Units on the axes: metres.
Rendering uses matplotlib's Agg backend (no display needed) and Pillow for the GIF.
"""
import os
from pathlib import Path
import secrets
import shutil
from typing import Dict, List, Optional, Tuple

import numpy as np

from hair_tracking.bags import io as bag_io
from hair_tracking.bags.io import BagError, EXIT_CONTENT, EXIT_OK, EXIT_OUTPUT, EXIT_USAGE
from hair_tracking.core.transforms import quat_to_matrix

VIEWS = {'side': (0, 2, 'x forward [m]', 'z up [m]'),
         'front': (1, 2, 'y left [m]', 'z up [m]'),
         'top': (0, 1, 'x forward [m]', 'y left [m]')}
HAIR_COLOR = '#6b4423'
HEAD_MARKER_TOPIC = '/hair/head'
DEFAULT_HEAD_RADII = (0.095, 0.08, 0.105)     # the default scene's collider [m]


def _topic(infos, name):
    for i in infos:
        if i.topic == name or i.topic == '/' + name.lstrip('/'):
            return i
    return None


def _stamp(header, log_ns):
    t = int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)
    return t if t > 0 else int(log_ns)


def _marker_segments(msg) -> np.ndarray:
    """(K, 2, 3) line segments of a MarkerArray's LINE_LIST / LINE_STRIP markers."""
    segs = []
    for m in msg.markers:
        if int(m.action) != 0 or not len(m.points):
            continue
        pts = np.array([[p.x, p.y, p.z] for p in m.points], dtype=np.float64)
        if int(m.type) == 5:                     # LINE_LIST: pairs
            n = len(pts) // 2 * 2
            segs.append(pts[:n].reshape(-1, 2, 3))
        elif int(m.type) == 4:                   # LINE_STRIP: consecutive points
            segs.append(np.stack([pts[:-1], pts[1:]], axis=1))
    return np.concatenate(segs) if segs else np.zeros((0, 2, 3))


def load_hair(path, topic: Optional[str] = None, max_frames: Optional[int] = None,
              fps: Optional[float] = None):
    """Hair frames of a bag: list of ``(t_ns, frame_id, segments (K, 2, 3), strands)``.

    ``strands`` is the (S, N, 3) array for a cloud, None for markers.  Frames are thinned to
    at most ``fps`` per second of recording and at most ``max_frames`` (evenly spread).
    """
    from msg_adapters.pointcloud import pointcloud2_to_strands

    with bag_io.open_bag(path) as reader:
        infos = bag_io.topics(reader)
        if topic:
            info = _topic(infos, topic)
            if info is None:
                raise BagError(f'{path}: no topic {topic!r}; its topics:\n'
                               + bag_io.format_topics(infos), EXIT_CONTENT)
        else:
            info = _topic(infos, '/hair/points') or _topic(infos, '/hair/markers')
            if info is None:
                cands = [i for i in infos if i.msgtype in ('sensor_msgs/msg/PointCloud2',
                                                           'visualization_msgs/msg/MarkerArray')]
                if len(cands) != 1:
                    raise BagError(f'{path}: no hair topic (/hair/points or /hair/markers); '
                                   f'choose one with --topic; its topics:\n'
                                   + bag_io.format_topics(infos), EXIT_CONTENT)
                info = cands[0]
        if info.msgtype not in ('sensor_msgs/msg/PointCloud2',
                                'visualization_msgs/msg/MarkerArray'):
            raise BagError(f'{path}: {info.topic} is a {info.msgtype}, not PointCloud2 or '
                           f'MarkerArray', EXIT_CONTENT)
        conns = [c for c in reader.connections if c.topic == info.topic]
        # choose which messages to decode from their log times first (decoding is the cost)
        logs = [t for _, t, _ in bag_io.messages(reader, conns)]
        if not logs:
            raise BagError(f'{path}: {info.topic} has no messages', EXIT_CONTENT)
        keep = _thin(np.array(logs, dtype=np.int64), max_frames, fps)
        frames = []
        for k, (conn, t, raw) in enumerate(bag_io.messages(reader, conns)):
            if k not in keep:
                continue
            msg = bag_io.deserialize(reader, raw, conn.msgtype, conn.topic)
            if conn.msgtype.endswith('PointCloud2'):
                try:
                    strands = pointcloud2_to_strands(msg)[0]
                except ValueError as exc:
                    raise BagError(f'{path}: {info.topic}: {exc}', EXIT_CONTENT) from None
                if strands.shape[1] < 2:
                    raise BagError(f'{path}: {info.topic} is not a cloud of strands (width '
                                   f'{strands.shape[1]})', EXIT_CONTENT)
                segs = np.stack([strands[:, :-1], strands[:, 1:]], axis=2).reshape(-1, 2, 3)
                frames.append((_stamp(msg.header, t), str(msg.header.frame_id), segs, strands))
            else:
                if not msg.markers or all(int(m.action) != 0 for m in msg.markers):
                    continue
                m0 = next(m for m in msg.markers if int(m.action) == 0)
                frames.append((_stamp(m0.header, t), str(m0.header.frame_id),
                               _marker_segments(msg), None))
        return info.topic, frames


def _thin(log_ns: np.ndarray, max_frames: Optional[int], fps: Optional[float]) -> set:
    """Indices of the frames nearest to a grid of ``fps`` per second (then at most
    ``max_frames`` of them, evenly spread).

    Only the grid points next to a frame are looked at (the nearest frame of any grid point
    is the nearest of the grid point next to it on the way to that frame), so the work and
    the memory are those of the frames, whatever gaps their times have."""
    idx = np.arange(len(log_ns))
    if fps and len(log_ns) > 1:
        step_ns = 1e9 / fps
        last = int((log_ns[-1] - log_ns[0]) / step_ns)
        at = (log_ns - log_ns[0]) / step_ns
        near = np.unique(np.clip(np.concatenate([np.floor(at), np.ceil(at)]), 0, last))
        grid = log_ns[0] + near * step_ns
        right = np.clip(np.searchsorted(log_ns, grid), 1, len(log_ns) - 1)
        left = right - 1
        nearest = np.where(grid - log_ns[left] <= log_ns[right] - grid, left, right)
        idx = np.unique(nearest)
    if max_frames and len(idx) > max_frames:
        idx = idx[np.round(np.linspace(0, len(idx) - 1, max_frames)).astype(int)]
    return set(int(i) for i in idx)


def load_head(path):
    """(t_ns, position (F, 3), quaternion (F, 4)) of /head_pose, or None if absent."""
    with bag_io.open_bag(path) as reader:
        infos = bag_io.topics(reader)
    info = _topic(infos, '/head_pose')
    if info is None or info.msgtype not in bag_io.POSE_MSGTYPES:
        return None
    hp = bag_io.read_head_poses(path, topic=info.topic)
    order = np.argsort(hp.t_ns, kind='stable')
    return hp.t_ns[order], hp.position[order], hp.quaternion[order]


def load_head_shape(path) -> Optional[Tuple[float, float, float]]:
    """Semi-axes [m] of the head collider from the first SPHERE marker the node published on
    ``/hair/head`` (its ``scale`` is the full axes), or None when the bag has none."""
    with bag_io.open_bag(path) as reader:
        conns = [c for c in reader.connections if c.topic == HEAD_MARKER_TOPIC
                 and c.msgtype == 'visualization_msgs/msg/Marker']
        for conn, _, raw in bag_io.messages(reader, conns):
            msg = bag_io.deserialize(reader, raw, conn.msgtype, conn.topic)
            if msg.action == 0 and msg.type == 2:          # ADD, SPHERE
                return (0.5 * msg.scale.x, 0.5 * msg.scale.y, 0.5 * msg.scale.z)
    return None


def load_diagnostics(path) -> Tuple[Dict[str, List[Tuple[float, float]]], str]:
    """{key: [(t_s, value)]} of every numeric value in /diagnostics, and the status name."""
    series: Dict[str, List[Tuple[float, float]]] = {}
    name = ''
    with bag_io.open_bag(path) as reader:
        conns = [c for c in reader.connections
                 if c.msgtype == 'diagnostic_msgs/msg/DiagnosticArray']
        for conn, t, raw in bag_io.messages(reader, conns):
            msg = bag_io.deserialize(reader, raw, conn.msgtype, conn.topic)
            ts = _stamp(msg.header, t) * 1e-9
            for st in msg.status:
                if 'hair' not in str(st.name) and len(msg.status) > 1:
                    continue
                name = name or str(st.name)
                series.setdefault('level', []).append((ts, float(int(st.level))))
                for kv in st.values:
                    try:
                        v = float(kv.value)
                    except ValueError:
                        continue
                    if np.isfinite(v):
                        series.setdefault(str(kv.key), []).append((ts, v))
    return series, name


# ================================================================ drawing
def _polyline(segs2):
    """(K, 2, 2) segments -> x, y arrays of one polyline with NaN breaks (fast to draw)."""
    k = len(segs2)
    xy = np.full((k, 3, 2), np.nan)
    xy[:, :2] = segs2
    xy = xy.reshape(-1, 2)
    return xy[:, 0], xy[:, 1]


class _Canvas:
    """One reusable matplotlib figure: a NaN-broken line per view.

    With fixed limits the static parts (axes, ticks, head outline) are drawn once and each
    picture only redraws the hair and the title on top of a saved background (blitting).
    """

    def __init__(self, views, limits, head_radii=None, dpi=90):
        import matplotlib
        matplotlib.use('Agg')
        import matplotlib.pyplot as plt

        self.plt = plt
        self.views = views
        self.fig, axes = plt.subplots(1, len(views), figsize=(4.2 * len(views), 4.6),
                                      dpi=dpi, squeeze=False)
        self.axes = axes[0]
        self.lines = []
        for ax, v in zip(self.axes, views):
            a, b, xl, yl = VIEWS[v]
            (line,) = ax.plot([], [], color=HAIR_COLOR, lw=0.6, alpha=0.7, animated=True)
            self.lines.append(line)
            if head_radii is not None:
                th = np.linspace(0, 2 * np.pi, 120)
                ax.plot(head_radii[a] * np.cos(th), head_radii[b] * np.sin(th), color='k',
                        lw=1.0)
            ax.set_aspect('equal')
            ax.set_xlabel(xl, fontsize=8)
            ax.set_ylabel(yl, fontsize=8)
            ax.tick_params(labelsize=7)
            ax.set_title(v, fontsize=9)
            if limits is not None:
                ax.set_xlim(*limits[v][0])
                ax.set_ylim(*limits[v][1])
        self.fixed = limits is not None
        self.title = self.fig.text(0.5, 0.97, '', ha='center', va='top', fontsize=10,
                                   animated=True)
        self.fig.subplots_adjust(left=0.1 / len(views), right=1 - 0.03 / len(views), bottom=0.1,
                                 top=0.88, wspace=0.3)
        self.background = None
        if self.fixed:
            self.fig.canvas.draw()
            self.background = self.fig.canvas.copy_from_bbox(self.fig.bbox)

    def draw(self, segs, title, center=None, half=None):
        canvas = self.fig.canvas
        for ax, line, v in zip(self.axes, self.lines, self.views):
            a, b = VIEWS[v][:2]
            line.set_data(*_polyline(segs[:, :, [a, b]]))
            if center is not None:
                ax.set_xlim(center[a] - half, center[a] + half)
                ax.set_ylim(center[b] - half, center[b] + half)
        self.title.set_text(title)
        if self.fixed:
            canvas.restore_region(self.background)
        else:
            for line in self.lines:
                line.set_animated(False)
            self.title.set_animated(False)
            canvas.draw()
        for ax, line in zip(self.axes, self.lines):
            ax.draw_artist(line)
        self.fig.draw_artist(self.title)
        buf = np.asarray(canvas.buffer_rgba())
        return buf[:, :, :3].copy()

    def close(self):
        self.plt.close(self.fig)


def head_limits(points: np.ndarray, head_radii) -> Dict[str, tuple]:
    """Axis limits of every view for hair ``points`` (P, 3) in the head frame: the head and
    the hair (0.1-99.9 percentiles) with 3 cm around."""
    lo = np.minimum(np.percentile(points, 0.1, axis=0), -np.asarray(head_radii)) - 0.03
    hi = np.maximum(np.percentile(points, 99.9, axis=0), np.asarray(head_radii)) + 0.03
    return {v: ((lo[VIEWS[v][0]], hi[VIEWS[v][0]]), (lo[VIEWS[v][1]], hi[VIEWS[v][1]]))
            for v in VIEWS}


def picture(strands: np.ndarray, path, title: str, head_radii=DEFAULT_HEAD_RADII,
            max_strands: int = 600, views=('front', 'side')) -> None:
    """A PNG of ``strands`` (S, N, 3, head frame [m]) seen from ``views`` with the head
    outline, drawn as :func:`render` draws a frame (at most ``max_strands`` strands, evenly
    picked)."""
    from PIL import Image

    segs = _subsample(None, strands, max_strands)
    canvas = _Canvas(list(views), head_limits(strands.reshape(-1, 3), head_radii), head_radii)
    try:
        Image.fromarray(canvas.draw(segs, title)).save(path)
    finally:
        canvas.close()


def _subsample(segs, strands, max_strands, rng_seed=0):
    if strands is not None:
        s = strands.shape[0]
        if s > max_strands or segs is None:
            pick = np.linspace(0, s - 1, min(s, max_strands)).round().astype(int)
            sub = strands[pick]
            return np.stack([sub[:, :-1], sub[:, 1:]], axis=2).reshape(-1, 2, 3)
        return segs
    if len(segs) > max_strands * 15:
        step = int(np.ceil(len(segs) / (max_strands * 15)))
        return segs[::step]
    return segs


def _head_at(head, t_ns):
    """Head (p, R) at ``t_ns``: the newest pose at or before it (the first one before all)."""
    t, p, q = head
    i = int(np.searchsorted(t, t_ns, side='right')) - 1
    i = min(max(i, 0), len(t) - 1)
    return p[i], quat_to_matrix(q[i] / np.linalg.norm(q[i]))


def render(path, output, *, gif: bool = True, png: bool = False, fps: float = 10.0,
           max_frames: int = 120, max_strands: int = 600, view: str = 'both',
           frame: str = 'head', topic: Optional[str] = None, overwrite: bool = False,
           head_radii=None) -> Dict[str, object]:
    """Render ``path`` into the new folder ``output``; returns what was written.

    See the module doc.  BagError for a missing/unreadable bag, no hair topic or an existing
    output.  ``head_radii`` [m] is the head outline drawn in the head frame; by default the
    collider of the node's head marker (``/hair/head``) when the bag has it, else the default
    scene's collider.
    """
    from PIL import Image

    if not fps > 0 or max_frames < 1 or max_strands < 1:
        raise BagError('--fps must be > 0, --max-frames and --max-strands >= 1', EXIT_USAGE)
    out = bag_io.check_output_path(output, overwrite)
    bag_io.bag_kind(path)
    hair_topic, frames = load_hair(path, topic, max_frames, fps)
    if not frames:
        raise BagError(f'{path}: {hair_topic} holds no hair to draw', EXIT_CONTENT)
    head = load_head(path)
    if head_radii is None:
        head_radii = load_head_shape(path) or DEFAULT_HEAD_RADII
    notes = []
    in_head = frame == 'head'
    already_head = in_head and head is None and all(
        'head' in f[1].lower() or 'face' in f[1].lower() for f in frames)
    if in_head and head is None and not already_head:
        notes.append('no /head_pose in the bag: drawn in the world frame')
        in_head = False
    views = ['side', 'front'] if view == 'both' else [view]

    # express every frame's segments in the drawing frame
    drawn = []
    for t, fid, segs, strands in frames:
        segs = _subsample(segs, strands, max_strands)
        if in_head and not already_head:
            p, r = _head_at(head, t)
            segs = (segs - p) @ r
        drawn.append((t, fid, segs))
    t0 = frames[0][0]

    limits = None
    half = None
    if in_head:
        limits = head_limits(np.concatenate([d[2].reshape(-1, 3) for d in drawn]), head_radii)
    else:
        ext = max(float(np.max(np.abs(d[2].reshape(-1, 3) - d[2].reshape(-1, 3).mean(0))))
                  for d in drawn if len(d[2]))
        half = ext + 0.05

    parent = out.parent if str(out.parent) else Path('.')
    parent.mkdir(parents=True, exist_ok=True)
    # a folder of the usual mode (tempfile.mkdtemp's is 0700, and the rename keeps it)
    tmp = parent / f'.{out.name}.partial-{secrets.token_hex(6)}'
    tmp.mkdir()
    written: Dict[str, object] = {'topic': hair_topic, 'frames': len(drawn), 'notes': notes,
                                  'head_radii': tuple(float(r) for r in head_radii)}
    try:
        canvas = _Canvas(views, limits, head_radii if in_head else None)
        images = []
        if png:
            (tmp / 'frames').mkdir()
        try:
            for k, (t, fid, segs) in enumerate(drawn):
                center = None
                if not in_head:
                    pts = segs.reshape(-1, 3)
                    center = pts.mean(axis=0) if len(pts) else np.zeros(3)
                title = (f't = {(t - t0) * 1e-9:6.2f} s   ({"head frame" if in_head else fid})'
                         f'   {hair_topic}')
                img = canvas.draw(segs, title, center, half)
                images.append(Image.fromarray(img))
                if png:
                    images[-1].save(tmp / 'frames' / f'frame_{k:05d}.png')
        finally:
            canvas.close()
        if gif:
            pal = [im.convert('P', palette=Image.ADAPTIVE, colors=64) for im in images]
            pal[0].save(tmp / 'hair.gif', save_all=True, append_images=pal[1:],
                        duration=max(20, int(round(1000 / fps))), loop=0, optimize=False)
            written['gif'] = str(out / 'hair.gif')
        _contact_sheet(drawn, tmp / 'hair.png', views, limits, half, in_head, head_radii, t0,
                       hair_topic)
        written['png'] = str(out / 'hair.png')
        if png:
            written['png_frames'] = str(out / 'frames')
        series, name = load_diagnostics(path)
        if series:
            _plot_diagnostics(series, name, tmp / 'diagnostics.png', t0 * 1e-9)
            written['diagnostics'] = str(out / 'diagnostics.png')
        else:
            notes.append('no /diagnostics in the bag: no diagnostics plot')
        if out.exists() or out.is_symlink():
            if not overwrite:
                raise BagError(f'{output}: output appeared while rendering', EXIT_OUTPUT)
            bag_io.remove_path(out)
        os.replace(tmp, out)
    except OSError as exc:
        raise BagError(f'{output}: cannot write: {exc.strerror or exc}', EXIT_OUTPUT) from None
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return written


def _contact_sheet(drawn, path, views, limits, half, in_head, head_radii, t0, topic):
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    n = min(6, len(drawn))
    pick = np.round(np.linspace(0, len(drawn) - 1, n)).astype(int)
    fig, axes = plt.subplots(len(views), n, figsize=(2.6 * n, 2.8 * len(views)), dpi=100,
                             squeeze=False)
    for j, k in enumerate(pick):
        t, fid, segs = drawn[k]
        for r, v in enumerate(views):
            a, b, xl, yl = VIEWS[v]
            ax = axes[r, j]
            ax.plot(*_polyline(segs[:, :, [a, b]]), color=HAIR_COLOR, lw=0.5, alpha=0.7)
            if in_head:
                th = np.linspace(0, 2 * np.pi, 120)
                ax.plot(head_radii[a] * np.cos(th), head_radii[b] * np.sin(th), 'k', lw=0.8)
                ax.set_xlim(*limits[v][0])
                ax.set_ylim(*limits[v][1])
            else:
                c = segs.reshape(-1, 3).mean(axis=0)
                ax.set_xlim(c[a] - half, c[a] + half)
                ax.set_ylim(c[b] - half, c[b] + half)
            ax.set_aspect('equal')
            ax.tick_params(labelsize=6)
            ax.locator_params(nbins=4)
            ax.set_title(f'{v}, t = {(t - t0) * 1e-9:.2f} s', fontsize=8)
    fig.suptitle(f'{topic} ({"head frame" if in_head else "world frame"})', fontsize=10)
    fig.subplots_adjust(left=0.05, right=0.99, bottom=0.08, top=0.86, wspace=0.35,
                        hspace=0.45)
    fig.savefig(path)
    plt.close(fig)


#: diagnostic keys not worth a plot (constants and identifiers)
_SKIP_KEYS = ('sim_time_ns', 'sim_time_s', 'guides', 'ghosts')


def _plot_diagnostics(series, name, path, t0_s):
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    keys = [k for k in series if k not in _SKIP_KEYS and len(series[k]) > 0]
    order = ['max_stretch', 'penetration_m', 'substeps', 'substeps_dropped', 'poses_rejected',
             'hair_resets', 'resets', 'step_ms_last', 'publish_ms_last', 'level']
    keys.sort(key=lambda k: (order.index(k) if k in order else len(order), k))
    keys = keys[:12]
    cols = 3
    rows = (len(keys) + cols - 1) // cols
    height = 2.3 * rows + 0.6
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, height), dpi=100,
                             squeeze=False)
    for ax in axes.ravel()[len(keys):]:
        ax.axis('off')
    for ax, k in zip(axes.ravel(), keys):
        data = np.array(series[k])
        ax.plot(data[:, 0] - t0_s, data[:, 1], lw=1.0, marker='.' if len(data) < 40 else None)
        ax.set_title(k, fontsize=9)
        ax.tick_params(labelsize=7)
        ax.set_xlabel('t [s]', fontsize=7)
        ax.grid(alpha=0.3)
    fig.suptitle(f'diagnostics: {name or "?"}', fontsize=10)
    fig.subplots_adjust(left=0.06, right=0.98, bottom=0.5 / height, top=1 - 0.65 / height,
                        wspace=0.3, hspace=0.8)
    fig.savefig(path)
    plt.close(fig)


def main_render(args) -> int:
    """``hair_sim_bag render`` (arguments from :mod:`hair_tracking.bags.cli`)."""
    gif = args.gif or not args.png
    result = render(args.bag, args.output, gif=gif, png=args.png, fps=args.fps,
                    max_frames=args.max_frames, max_strands=args.max_strands, view=args.view,
                    frame=args.frame, topic=args.topic, overwrite=args.overwrite)
    for note in result['notes']:
        print(f'note: {note}')
    print(f'rendered {result["frames"]} pictures of {result["topic"]} into {args.output}:')
    for key in ('gif', 'png', 'png_frames', 'diagnostics'):
        if key in result:
            print(f'  {result[key]}')
    return EXIT_OK
