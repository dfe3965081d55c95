"""Real recorded head motion: BVH motion capture and pose tables -> head poses.

Everything here produces a :class:`HeadMotion`: integer nanosecond times, head positions [m] and
unit quaternions (x, y, z, w) in the REP-103 conventions of the project (world z up; head frame x
forward out of the face, y to the person's left, z up through the top of the head when the person
stands upright looking ahead).  A pose maps head-frame points to the world,
``p_world = position + R(q) @ p_head`` (see ``model.HeadPose``).  The quaternion stream is
normalised and sign-continuous (consecutive dot products >= 0), so interpolation never takes the
long way round.

Sources
-------
* BVH (Biovision Hierarchy) files: :func:`read_bvh` parses HIERARCHY and MOTION, keeping every
  joint's CHANNELS order as written (it differs between joints in the CMU conversion), and
  :meth:`Bvh.forward_kinematics` evaluates the chain.  :func:`load_bvh_head_motion` turns one joint
  into a head-pose stream.  BVH semantics follow Meredith & Maddock (2001), "Motion capture file
  formats explained" (University of Sheffield, CS-01-11): a joint's local transform is
  ``T(OFFSET + position channels) * R_c1(a1) * R_c2(a2) * R_c3(a3)`` with the rotation channels
  multiplied in the order they are listed, angles in degrees, and the global transform is the
  product down the chain from the root.
* Pose tables (CSV or whitespace text with a header line): :func:`read_pose_table`, with
  :func:`read_vr360` for the ``timestamp viewpoint w x y z`` head-mounted-display traces of
  Corbillon et al. (2017/2018) and :func:`read_pose_csv`/:func:`write_pose_csv` for the project's
  own compact format (``t_s,px,py,pz,qx,qy,qz,qw``).
* :func:`load_bundled_walk` reads ``data/cmu_131_01_walk_head.csv`` shipped with the package
  (CMU Graphics Lab Motion Capture Database, subject 131 trial 01, via the bvh11 repository; see
  ``data/ATTRIBUTION.md``), made by ``scripts/make_head_motion_data.py``.

Frames of the CMU skeleton (determined from the data, see :func:`infer_head_axes`)
-------------------------------------------------------------------------------
BVH worlds are y up.  :data:`BVH_TO_WORLD` is the proper rotation (a cyclic permutation of the
axes) taking BVH world coordinates to the project's z-up world: BVH +y -> world +z (up),
BVH +z -> world +x, BVH +x -> world +y.

The CMU skeleton is built in a rest pose standing upright along +y, facing +z, with its left side
on +x (the LeftHip OFFSET has x > 0, the toe End Sites point along +z).  Every joint's local axes
coincide with the BVH world axes in that rest pose, so in the Head joint's local frame the face
points along local +z, the person's left is local +x and the top of the head is local +y.
:data:`CMU_HEAD_AXES` holds these three directions as columns (the head-joint coordinates of the
REP-103 head x, y and z axes), so that ``R_world_head = BVH_TO_WORLD @ R_bvh_joint @
CMU_HEAD_AXES``.  Checked on CMU 131_01 (walk): over the walking part (t = 4.1-6.3 s, see
:func:`walking_direction`) the head's x axis follows the horizontal walking direction with a
mean cosine of 0.97, and its z axis has a mean cosine of 0.99 with world up (0.95 over the whole
clip, which includes bending down at t = 2.5-3.5 s); :func:`infer_head_axes` recovers the same
mapping from the motion alone, and the tests check both.  The reported head origin is the head
centre (middle of the Head bone, see :func:`load_bvh_head_motion`).

The VR360 quaternions need no remapping: their world is z up and their head frame z up too
(user1: the head z axis has a mean cosine of 0.97 with world z, and 63 % of the turning is about
world z, i.e. yaw).  x is taken as the viewing direction, as we read Corbillon et al. (2017):
the stored rotation turns the reference direction (1, 0, 0) into the viewing direction (not
checked against the videos).
"""
from dataclasses import dataclass, field
import decimal
import math
import os
import re

import numpy as np

from hair_tracking.core.model import HeadPose
from hair_tracking.core.transforms import matrices_to_quats, quat_to_matrix
from hair_tracking.resources import data_path

#: metres per BVH length unit for the CMU conversions (README of the data set: 0.056444).
CMU_SCALE_M = 0.056444

#: BVH (y up) world coordinates -> project world coordinates (z up, REP-103): ``p = M @ p_bvh``.
#: BVH +z -> world +x, BVH +x -> world +y, BVH +y -> world +z (a proper rotation, det = +1).
BVH_TO_WORLD = np.array([[0.0, 0.0, 1.0],
                         [1.0, 0.0, 0.0],
                         [0.0, 1.0, 0.0]])

#: Head-joint local coordinates of the REP-103 head axes, as columns: x forward = local +z,
#: y left = local +x, z up = local +y (CMU rest pose faces +z, left on +x, up +y; see module doc).
CMU_HEAD_AXES = np.array([[0.0, 1.0, 0.0],
                          [0.0, 0.0, 1.0],
                          [1.0, 0.0, 0.0]])

DATA_DIR = data_path('')
BUNDLED_WALK_CSV = os.path.join(DATA_DIR, 'cmu_131_01_walk_head.csv')

POSE_CSV_COLUMNS = ('t_s', 'px', 'py', 'pz', 'qx', 'qy', 'qz', 'qw')

_TIME_FACTOR_NS = {'s': 10 ** 9, 'ms': 10 ** 6, 'us': 10 ** 3, 'ns': 1}
_AXIS_INDEX = {'X': 0, 'Y': 1, 'Z': 2}


class HeadMotionError(ValueError):
    """A motion file is missing, malformed, or asked for something it does not contain."""


# ================================================================ the result
@dataclass
class HeadMotion:
    """A recorded head-pose stream, cleaned.

    ``t_ns`` (F,) int64 strictly increasing times [ns]; ``position`` (F, 3) float64 head origin in
    the world [m]; ``quaternion`` (F, 4) float64 unit (x, y, z, w), sign-continuous, rotating
    head-frame vectors into the world.  ``source`` names where it came from (a path and what was
    read), ``dropped`` counts input rows kept out by reason (``'bad_quaternion'`` NaN/Inf/zero
    norm, ``'bad_position'`` NaN/Inf, ``'bad_time'`` NaN or not after the previous kept row).
    Construction checks shapes, finiteness, increasing times and unit quaternions (to 1e-6),
    and makes the quaternion stream sign-continuous.
    """

    t_ns: np.ndarray
    position: np.ndarray
    quaternion: np.ndarray
    source: str = ''
    dropped: dict = field(default_factory=dict)

    def __post_init__(self):
        t = np.asarray(self.t_ns)
        p = np.asarray(self.position, dtype=np.float64)
        q = np.asarray(self.quaternion, dtype=np.float64)
        if t.ndim != 1 or len(t) == 0:
            raise HeadMotionError(f'HeadMotion needs a non-empty (F,) t_ns, got shape {t.shape}')
        if not np.issubdtype(t.dtype, np.integer):
            raise HeadMotionError(f't_ns must be integer nanoseconds, got dtype {t.dtype}')
        f = len(t)
        if p.shape != (f, 3) or q.shape != (f, 4):
            raise HeadMotionError(f'HeadMotion with {f} times needs position ({f}, 3) and '
                                  f'quaternion ({f}, 4), got {p.shape} and {q.shape}')
        if f > 1 and np.any(np.diff(t) <= 0):
            raise HeadMotionError('HeadMotion t_ns must be strictly increasing')
        if not (np.all(np.isfinite(p)) and np.all(np.isfinite(q))):
            raise HeadMotionError('HeadMotion position/quaternion contain NaN or Inf')
        norm_err = np.abs(np.linalg.norm(q, axis=1) - 1.0)
        if np.any(norm_err > 1e-6):
            raise HeadMotionError(f'HeadMotion quaternions must be unit; sample '
                                  f'{int(np.argmax(norm_err))} is off by {norm_err.max():.3g}')
        q = make_sign_continuous(q)
        self.t_ns = np.ascontiguousarray(t, dtype=np.int64)
        self.position = np.ascontiguousarray(p)
        self.quaternion = np.ascontiguousarray(q)

    def __len__(self):
        return len(self.t_ns)

    @property
    def t_s(self) -> np.ndarray:
        """Times [s] relative to the first sample."""
        return (self.t_ns - self.t_ns[0]) * 1e-9

    @property
    def duration_s(self) -> float:
        return float(self.t_ns[-1] - self.t_ns[0]) * 1e-9

    @property
    def rate_hz(self) -> float:
        """Median sample rate [Hz] (0 for a single sample)."""
        if len(self) < 2:
            return 0.0
        return 1e9 / float(np.median(np.diff(self.t_ns)))

    def rotation(self) -> np.ndarray:
        """(F, 3, 3) rotation matrices head -> world."""
        return quat_to_matrix(self.quaternion)

    def pose(self, i: int) -> HeadPose:
        """Sample ``i`` as a ``model.HeadPose``."""
        q = self.quaternion[i].copy()
        return HeadPose(self.position[i].copy(), q, quat_to_matrix(q))


def angular_speed(motion: HeadMotion) -> np.ndarray:
    """(F-1,) head angular speed [rad/s]: rotation angle between consecutive samples / time step.

    The angle of the relative rotation ``q_i^-1 q_{i+1}`` is ``2 atan2(|v|, |w|)`` (sign
    insensitive, accurate for small angles too).
    """
    q = motion.quaternion
    a, b = q[:-1], q[1:]
    # relative rotation conj(a) * b
    w = np.sum(a * b, axis=1)
    v = (a[:, 3:4] * b[:, :3] - b[:, 3:4] * a[:, :3] - np.cross(a[:, :3], b[:, :3]))
    ang = 2.0 * np.arctan2(np.linalg.norm(v, axis=1), np.abs(w))
    return ang / (np.diff(motion.t_ns) * 1e-9)


def linear_speed(motion: HeadMotion) -> np.ndarray:
    """(F-1,) head origin speed [m/s] between consecutive samples."""
    return (np.linalg.norm(np.diff(motion.position, axis=0), axis=1)
            / (np.diff(motion.t_ns) * 1e-9))


# ================================================================ quaternion helpers
def make_sign_continuous(q: np.ndarray) -> np.ndarray:
    """Flip samples of a (F, 4) quaternion stream so consecutive dot products are >= 0."""
    q = np.array(q, dtype=np.float64)
    if len(q) < 2:
        return q
    d = np.sum(q[1:] * q[:-1], axis=1)
    flips = np.concatenate([[0], np.cumsum(d < 0)])
    q[flips % 2 == 1] *= -1.0
    return q


def _axis_rotations(axis: int, deg: np.ndarray) -> np.ndarray:
    """(F, 3, 3) rotations by ``deg`` degrees about coordinate axis 0/1/2."""
    r = np.radians(deg)
    c, s = np.cos(r), np.sin(r)
    m = np.zeros((len(r), 3, 3))
    i, j = (axis + 1) % 3, (axis + 2) % 3
    m[:, axis, axis] = 1.0
    m[:, i, i] = c
    m[:, j, j] = c
    m[:, i, j] = -s
    m[:, j, i] = s
    return m


# ================================================================ BVH
@dataclass
class BvhJoint:
    """One node of a BVH hierarchy (End Sites included, named ``<parent>_End``)."""

    name: str
    parent: int                 # index into Bvh.joints, -1 for the root
    offset: np.ndarray          # (3,) BVH units, in the parent's frame
    channels: tuple             # e.g. ('Zrotation', 'Yrotation', 'Xrotation'), as written
    first_channel: int          # column of the first channel in Bvh.motion
    line: int                   # line of the ROOT/JOINT/End Site keyword (1-based)
    end_site: bool = False


@dataclass
class Bvh:
    """A parsed BVH file: hierarchy, ``motion`` (F, C) channel values, ``frame_time`` [s]."""

    joints: list
    motion: np.ndarray
    frame_time: float
    path: str = ''

    @property
    def frame_count(self) -> int:
        return self.motion.shape[0]

    @property
    def joint_names(self) -> list:
        return [j.name for j in self.joints]

    def index(self, name: str) -> int:
        for i, j in enumerate(self.joints):
            if j.name == name:
                return i
        raise HeadMotionError(f'{self.path or "BVH"}: no joint named {name!r}; available joints: '
                              + ', '.join(self.joint_names))

    def _local(self, i: int):
        """Local translation (F, 3) and rotation (F, 3, 3) of joint i for every frame."""
        j = self.joints[i]
        f = self.frame_count
        trans = np.tile(j.offset, (f, 1))
        rot = np.tile(np.eye(3), (f, 1, 1))
        for k, ch in enumerate(j.channels):
            col = self.motion[:, j.first_channel + k]
            axis = _AXIS_INDEX[ch[0].upper()]
            if ch[1:].lower() == 'position':
                trans[:, axis] += col
            else:
                rot = rot @ _axis_rotations(axis, col)
        return trans, rot

    def chain(self, name: str) -> list:
        """Joint indices from the root down to ``name``."""
        i = self.index(name)
        out = []
        while i >= 0:
            out.append(i)
            i = self.joints[i].parent
        return out[::-1]

    def forward_kinematics(self, name: str):
        """World position (F, 3) [BVH units] and rotation (F, 3, 3) of joint ``name``, BVH frame.

        The rotation maps the joint's local coordinates to BVH world coordinates.
        """
        pos = rot = None
        for i in self.chain(name):
            t, r = self._local(i)
            if pos is None:
                pos, rot = t, r
            else:
                pos = pos + np.einsum('fij,fj->fi', rot, t)
                rot = rot @ r
        return pos, rot

    def all_positions(self) -> np.ndarray:
        """(F, J, 3) world positions [BVH units, BVH frame] of every joint and End Site."""
        f, n = self.frame_count, len(self.joints)
        pos = np.empty((f, n, 3))
        rots = [None] * n
        for i, j in enumerate(self.joints):     # parents precede children
            t, r = self._local(i)
            if j.parent < 0:
                pos[:, i] = t
                rots[i] = r
            else:
                pr = rots[j.parent]
                pos[:, i] = pos[:, j.parent] + np.einsum('fij,fj->fi', pr, t)
                rots[i] = pr @ r
        return pos


def _tokens(lines, start, stop):
    """(token, 1-based line) pairs of lines[start:stop]."""
    for k in range(start, stop):
        for tok in lines[k].split():
            yield tok, k + 1


def read_bvh(path: str) -> Bvh:
    """Parse a BVH file (HIERARCHY + MOTION); raises HeadMotionError naming the line at fault."""
    if not os.path.isfile(path):
        raise HeadMotionError(f'BVH file not found: {path}')
    with open(path, 'r', encoding='utf-8', errors='replace') as fh:
        lines = fh.read().splitlines()

    def fail(line, msg):
        raise HeadMotionError(f'{path}:{line}: malformed BVH: {msg}')

    motion_line = None
    for k, ln in enumerate(lines):
        if ln.strip().upper().startswith('MOTION'):
            motion_line = k
            break
    if motion_line is None:
        fail(len(lines), 'no MOTION section (file truncated?)')
    toks = list(_tokens(lines, 0, motion_line))
    if not toks or toks[0][0].upper() != 'HIERARCHY':
        fail(toks[0][1] if toks else 1, 'file must start with HIERARCHY')

    joints = []
    stack = []          # indices of open joints
    n_channels = 0
    pos = 1
    expect_open = False

    def take(n_needed, what, line):
        nonlocal pos
        if pos + n_needed > len(toks):
            fail(line, f'{what}: unexpected end of HIERARCHY')
        vals = toks[pos:pos + n_needed]
        pos += n_needed
        return vals

    while pos < len(toks):
        tok, line = toks[pos]
        pos += 1
        key = tok.upper()
        if expect_open:
            if tok != '{':
                fail(line, f"expected '{{' after {joints[-1].name}, got {tok!r}")
            stack.append(len(joints) - 1)
            expect_open = False
        elif key in ('ROOT', 'JOINT'):
            if key == 'ROOT' and (stack or joints):
                fail(line, 'only one ROOT is supported')
            if key == 'JOINT' and not stack:
                fail(line, 'JOINT outside any ROOT')
            (name, _), = take(1, key, line)
            if name in (j.name for j in joints):
                fail(line, f'joint name {name!r} used twice')
            joints.append(BvhJoint(name, stack[-1] if stack else -1, np.zeros(3), (),
                                   n_channels, line))
            expect_open = True
        elif key == 'END':
            (site, _), = take(1, 'End Site', line)
            if site.upper() != 'SITE' or not stack:
                fail(line, "expected 'End Site' inside a joint")
            parent = joints[stack[-1]]
            if parent.name + '_End' in (j.name for j in joints):
                fail(line, f'second End Site under {parent.name!r}, or a joint named '
                           f'{parent.name + "_End"!r}')
            joints.append(BvhJoint(parent.name + '_End', stack[-1], np.zeros(3), (),
                                   n_channels, line, end_site=True))
            expect_open = True
        elif key == 'OFFSET':
            if not stack:
                fail(line, 'OFFSET outside a joint')
            vals = take(3, 'OFFSET', line)
            try:
                joints[stack[-1]].offset = np.array([float(v) for v, _ in vals])
            except ValueError:
                fail(line, 'OFFSET needs three numbers, got ' + ' '.join(v for v, _ in vals))
        elif key == 'CHANNELS':
            if not stack:
                fail(line, 'CHANNELS outside a joint')
            j = joints[stack[-1]]
            (cnt, _), = take(1, 'CHANNELS', line)
            if not cnt.isdigit():
                fail(line, f'CHANNELS count must be an integer, got {cnt!r}')
            names = tuple(v for v, _ in take(int(cnt), 'CHANNELS', line))
            for nm in names:
                if not re.fullmatch(r'[XYZxyz](position|rotation)', nm, re.IGNORECASE):
                    fail(line, f'unknown channel {nm!r} (expected X/Y/Z + position/rotation)')
            if j.end_site:
                fail(line, 'an End Site has no CHANNELS')
            if j.channels:
                fail(line, f'second CHANNELS line for joint {j.name!r}')
            j.channels = names
            j.first_channel = n_channels
            n_channels += len(names)
        elif tok == '}':
            if not stack:
                fail(line, "unbalanced '}'")
            stack.pop()
        else:
            fail(line, f'unexpected token {tok!r}')
    if expect_open or stack:
        fail(motion_line + 1, 'HIERARCHY not closed before MOTION (unbalanced braces)')
    if not joints:
        fail(motion_line + 1, 'HIERARCHY has no ROOT')

    # ---- MOTION header
    k = motion_line + 1
    header = {}
    for key, pattern, label in (('frames', r'Frames:\s*(\S+)', 'Frames: N'),
                                ('time', r'Frame\s+Time:\s*(\S+)', 'Frame Time: T')):
        while k < len(lines) and not lines[k].strip():
            k += 1
        if k >= len(lines):
            fail(len(lines), f'missing "{label}" line after MOTION (file truncated?)')
        m = re.fullmatch(pattern, lines[k].strip(), re.IGNORECASE)
        if not m:
            fail(k + 1, f'expected "{label}", got {lines[k].strip()!r}')
        header[key] = (m.group(1), k + 1)
        k += 1
    try:
        n_frames = int(header['frames'][0])
    except ValueError:
        fail(header['frames'][1], f'frame count {header["frames"][0]!r} is not an integer')
    try:
        frame_time = float(header['time'][0])
    except ValueError:
        fail(header['time'][1], f'frame time {header["time"][0]!r} is not a number')
    if n_frames < 1:
        fail(header['frames'][1], f'frame count must be positive, got {n_frames}')
    if not (math.isfinite(frame_time) and frame_time > 0):
        fail(header['time'][1], f'frame time must be positive, got {frame_time}')

    rows, row_lines = [], []
    for kk in range(k, len(lines)):
        parts = lines[kk].split()
        if not parts:
            continue
        if len(parts) != n_channels:
            fail(kk + 1, f'frame {len(rows)} has {len(parts)} values, the hierarchy declares '
                         f'{n_channels} channels')
        rows.append(parts)
        row_lines.append(kk + 1)
    if len(rows) != n_frames:
        fail(len(lines), f'"Frames: {n_frames}" but {len(rows)} frame lines'
                         + (' (file truncated?)' if len(rows) < n_frames else ''))
    try:
        motion = np.array(rows, dtype=np.float64)
    except ValueError:
        for parts, ln in zip(rows, row_lines):
            try:
                [float(v) for v in parts]
            except ValueError:
                fail(ln, 'frame line holds a value that is not a number')
        raise
    if not np.all(np.isfinite(motion)):
        bad = int(np.nonzero(~np.all(np.isfinite(motion), axis=1))[0][0])
        fail(row_lines[bad], 'frame line holds NaN or Inf')
    return Bvh(joints=joints, motion=motion, frame_time=frame_time, path=path)


def bvh_head_axes_world(bvh: Bvh, joint: str = 'Head', head_axes=CMU_HEAD_AXES,
                        bvh_to_world=BVH_TO_WORLD) -> np.ndarray:
    """(F, 3, 3) head rotation in the project world: ``bvh_to_world @ R_joint @ head_axes``."""
    _, rot = bvh.forward_kinematics(joint)
    return np.asarray(bvh_to_world) @ rot @ np.asarray(head_axes)


def walking_direction(position: np.ndarray, t_ns: np.ndarray, min_speed: float = 0.5,
                      window_s: float = 0.5):
    """Walking part and horizontal walking direction of a world-frame (F, 3) track [m], z up.

    The velocity is a centred difference over ``window_s`` [s] (about one stride, so the sway
    of the head within a stride averages out).  The clip's travel direction ``u`` is the
    horizontal start-to-end displacement; a sample belongs to the walking part when its velocity
    along ``u`` exceeds ``min_speed`` [m/s] (so side-steps, ducking and turning on the spot do
    not count).  Returns ``(direction (F, 2) unit xy velocity direction, NaN off the walking
    part; walking (F,) bool)``.
    """
    p = np.asarray(position, dtype=np.float64)
    t = (np.asarray(t_ns, dtype=np.int64) - int(t_ns[0])) * 1e-9
    f = len(p)
    direction = np.full((f, 2), np.nan)
    walking = np.zeros(f, dtype=bool)
    u = p[-1, :2] - p[0, :2]
    if f < 3 or np.linalg.norm(u) < 1e-9:
        return direction, walking
    u = u / np.linalg.norm(u)
    half = max(1, int(round(0.5 * window_s / (t[-1] / (f - 1)))))
    lo = np.clip(np.arange(f) - half, 0, f - 1)
    hi = np.clip(np.arange(f) + half, 0, f - 1)
    v = (p[hi, :2] - p[lo, :2]) / (t[hi] - t[lo])[:, None]
    walking = v @ u > min_speed
    direction[walking] = v[walking] / np.linalg.norm(v[walking], axis=1, keepdims=True)
    return direction, walking


def infer_head_axes(bvh: Bvh, joint: str = 'Head', bvh_to_world=BVH_TO_WORLD,
                    scale: float = CMU_SCALE_M, min_speed: float = 0.5) -> np.ndarray:
    """Head-joint local axes found from the motion itself (columns: forward, left, up).

    Up: the signed local coordinate axis whose world image is best aligned with world up on
    average over the clip.  Forward: among the signed axes perpendicular to it, the one whose
    horizontal world image best follows the walking direction over the walking part (see
    :func:`walking_direction`; ``min_speed`` [m/s], ``scale`` [m per BVH unit]).
    Left = up x forward.  Raises HeadMotionError if the clip has no walking part.
    """
    pos, rot = bvh.forward_kinematics(joint)
    m = np.asarray(bvh_to_world, dtype=np.float64)
    rot_w = m @ rot                                   # joint-local -> project world
    t_ns = np.round(np.arange(bvh.frame_count) * bvh.frame_time * 1e9).astype(np.int64)
    direction, walking = walking_direction(pos @ m.T * scale, t_ns, min_speed)
    if not np.any(walking):
        raise HeadMotionError(f'{bvh.path}: joint {joint!r} never walks faster than '
                              f'{min_speed} m/s; cannot infer the forward axis')
    cands = [s * np.eye(3)[a] for a in range(3) for s in (1.0, -1.0)]
    up = max(cands, key=lambda c: float(np.mean((rot_w @ c)[:, 2])))

    def follow(c):
        h = (rot_w[walking] @ c)[:, :2]
        h = h / np.maximum(np.linalg.norm(h, axis=1, keepdims=True), 1e-12)
        return float(np.mean(np.sum(h * direction[walking], axis=1)))

    fwd = max((c for c in cands if abs(np.dot(c, up)) < 0.5), key=follow)
    return np.stack([fwd, np.cross(up, fwd), up], axis=1)


def _bone_middle(bvh: Bvh, i: int) -> np.ndarray:
    """Half the offset [BVH units, joint-local] to joint i's End Site (else its first child)."""
    kids = [k for k, j in enumerate(bvh.joints) if j.parent == i]
    if not kids:
        raise HeadMotionError(f"joint {bvh.joints[i].name!r} has no child or End Site; "
                              "origin='center' needs one (use origin='joint')")
    ends = [k for k in kids if bvh.joints[k].end_site]
    return 0.5 * bvh.joints[(ends or kids)[0]].offset


def load_bvh_head_motion(path: str, joint: str = 'Head', scale: float = CMU_SCALE_M,
                         head_axes=CMU_HEAD_AXES, bvh_to_world=BVH_TO_WORLD,
                         origin='center') -> HeadMotion:
    """Head poses of one BVH joint for every frame, in metres and REP-103 frames.

    ``scale`` [m per BVH unit] (CMU: 0.056444); ``head_axes`` (3, 3) columns are the joint-local
    coordinates of the head x (forward), y (left), z (up) axes; ``bvh_to_world`` takes BVH world
    coordinates to the z-up world.  ``origin`` places the head-frame origin: ``'center'``
    (default; the project's head frame has its origin at the head centre) = the middle of the
    bone the joint drives, i.e. halfway to its End Site (for the CMU Head joint, at the top of
    the neck, that is 4.6 cm up the head), or to its first child joint; ``'joint'`` = the joint
    itself; or a (3,) offset [m] in the head frame from the joint.
    Times start at 0 and step by the file's Frame Time.
    """
    bvh = read_bvh(path)
    if not (math.isfinite(scale) and scale > 0):
        raise HeadMotionError(f'scale must be a positive number of metres per unit, got {scale}')
    m = np.asarray(bvh_to_world, dtype=np.float64)
    axes = np.asarray(head_axes, dtype=np.float64)
    for nm, r in (('bvh_to_world', m), ('head_axes', axes)):
        if r.shape != (3, 3) or not np.allclose(r @ r.T, np.eye(3), atol=1e-9) \
                or np.linalg.det(r) < 0:
            raise HeadMotionError(f'{nm} must be a proper 3x3 rotation matrix')
    pos, rot = bvh.forward_kinematics(joint)
    if isinstance(origin, str):
        if origin == 'center':
            pos = pos + rot @ _bone_middle(bvh, bvh.index(joint))
        elif origin != 'joint':
            raise HeadMotionError(f"origin must be 'center', 'joint' or a (3,) offset, "
                                  f"got {origin!r}")
    rot_w = m @ rot @ axes
    pos_w = (pos @ m.T) * scale
    if not isinstance(origin, str):
        off = np.asarray(origin, dtype=np.float64)
        if off.shape != (3,) or not np.all(np.isfinite(off)):
            raise HeadMotionError(f'origin offset must be 3 finite numbers [m], got {origin!r}')
        pos_w = pos_w + rot_w @ off
    q = make_sign_continuous(matrices_to_quats(rot_w))
    t_ns = np.round(np.arange(bvh.frame_count) * bvh.frame_time * 1e9).astype(np.int64)
    where = origin if isinstance(origin, str) else 'offset ' + str(list(np.ravel(origin)))
    return HeadMotion(t_ns, pos_w, q, source=f'{path} (BVH joint {joint!r}, origin {where}, '
                                             f'scale {scale} m/unit)')


# ================================================================ pose tables
#: Column names pose tables of trackers and headsets use (lower case), tried in this order when
#: a table does not name its columns as asked: time, position (x y z), quaternion (x y z w).
TIME_NAMES = ('t_s', 't', 'time', 'timestamp', 'stamp', 'time_s', 'seconds', 'sec', 'ts')
POSITION_NAMES = (('px', 'py', 'pz'), ('x', 'y', 'z'), ('pos_x', 'pos_y', 'pos_z'),
                  ('position_x', 'position_y', 'position_z'), ('tx', 'ty', 'tz'),
                  ('pos.x', 'pos.y', 'pos.z'), ('position.x', 'position.y', 'position.z'))
QUATERNION_NAMES = (('qx', 'qy', 'qz', 'qw'), ('quat_x', 'quat_y', 'quat_z', 'quat_w'),
                    ('rot_x', 'rot_y', 'rot_z', 'rot_w'),
                    ('orientation_x', 'orientation_y', 'orientation_z', 'orientation_w'),
                    ('ox', 'oy', 'oz', 'ow'), ('q.x', 'q.y', 'q.z', 'q.w'),
                    ('orientation.x', 'orientation.y', 'orientation.z', 'orientation.w'))
#: The largest stamp a ROS time can hold [ns].
MAX_STAMP_NS = 2 ** 63 - 1


def recognise_columns(path: str, delimiter=None):
    """The columns of a pose table by their names, without flags: ``(time, quaternion (x, y, z,
    w) names, position names or None)``, matched case-insensitively against
    :data:`TIME_NAMES`, :data:`QUATERNION_NAMES` and :data:`POSITION_NAMES` (the table's own
    spelling is returned).  Raises HeadMotionError naming the columns it found when a time or
    quaternion column is missing."""
    if not os.path.isfile(path):
        raise HeadMotionError(f'pose table not found: {path}')
    with open(path, 'r', encoding='utf-8', errors='replace') as fh:
        header = next((ln for ln in fh if ln.strip() and not ln.lstrip().startswith('#')), '')
    delim = delimiter if delimiter is not None else (',' if ',' in header else None)
    names = [n.strip() for n in (header.split(delim) if delim else header.split())]
    lower = {n.lower(): n for n in names}
    time = next((lower[t] for t in TIME_NAMES if t in lower), None)
    quat = next((tuple(lower[c] for c in cs) for cs in QUATERNION_NAMES
                 if all(c in lower for c in cs)), None)
    if quat is None and all(c in lower for c in ('w', 'x', 'y', 'z')) and \
            not any(all(c in lower for c in cs) for cs in POSITION_NAMES if cs != ('x', 'y', 'z')):
        quat = tuple(lower[c] for c in ('x', 'y', 'z', 'w'))   # an orientation-only w x y z
    pos = next((tuple(lower[c] for c in cs) for cs in POSITION_NAMES
                if all(c in lower for c in cs) and not (quat and set(cs) & set(quat))), None)
    if time is None or quat is None:
        missing = ' and no '.join(w for w, v in (('time', time), ('quaternion', quat))
                                  if v is None)
        raise HeadMotionError(f'{path}: no {missing} columns recognised among {names} (name '
                              'them with --time-column / --quat-columns)')
    return time, quat, pos


def read_pose_table(path: str, time_column: str = 't_s', time_unit: str = 's',
                    quat_columns=('qx', 'qy', 'qz', 'qw'), quat_order: str = 'xyzw',
                    position_columns=('px', 'py', 'pz'), neck_offset=None, pivot=None,
                    delimiter=None, source: str = '', time_scale=None) -> HeadMotion:
    """Read a pose table: CSV or whitespace-separated text whose first non-comment line names
    the columns.  Blank lines and lines starting with ``#`` are skipped.

    ``time_column`` in ``time_unit`` ('s', 'ms', 'us', 'ns'), or in ticks of ``time_scale``
    seconds (e.g. ``'1e-7'`` for 100 ns ticks; a string is taken exactly), any epoch: times are
    parsed exactly (no float rounding) and the first row's stamp is subtracted before scaling;
    the times are absolute when the first stamp fits a ROS time (int64 ns), else relative to it;
    ``quat_columns`` four column names holding the quaternion components in ``quat_order``
    ('xyzw' or 'wxyz'); ``position_columns`` three column names [m], or None for an
    orientation-only table: then the head origin is ``pivot + R @ neck_offset`` (a head turning
    about a fixed neck pivot; ``neck_offset`` (3,) head frame [m], default zeros; ``pivot`` (3,)
    world [m], default origin).  ``delimiter`` None = ',' if the header contains one, else
    whitespace.

    Rows with a NaN/Inf/zero quaternion, a NaN/Inf position or a time that is NaN or not after
    the previous kept row are kept out and counted in ``HeadMotion.dropped``; quaternions are
    normalised and made sign-continuous.  Missing file/column, a bad header, a row with the
    wrong number of fields or a non-numeric field raise HeadMotionError naming the line.
    """
    if time_unit not in _TIME_FACTOR_NS:
        raise HeadMotionError(f'time_unit must be one of {sorted(_TIME_FACTOR_NS)}, '
                              f'got {time_unit!r}')
    if time_scale is not None:
        try:
            scale = decimal.Decimal(str(time_scale))
        except decimal.InvalidOperation:
            scale = None
        if scale is None or not scale.is_finite() or scale <= 0:
            raise HeadMotionError(f'time_scale must be a positive number of seconds per tick, '
                                  f'got {time_scale!r}')
        ns_per_tick = scale * 10 ** 9
    else:
        ns_per_tick = decimal.Decimal(_TIME_FACTOR_NS[time_unit])
    if quat_order not in ('xyzw', 'wxyz'):
        raise HeadMotionError(f"quat_order must be 'xyzw' or 'wxyz', got {quat_order!r}")
    if len(quat_columns) != 4:
        raise HeadMotionError(f'quat_columns needs 4 names, got {list(quat_columns)}')
    if position_columns is not None and len(position_columns) != 3:
        raise HeadMotionError(f'position_columns needs 3 names, got {list(position_columns)}')
    if not os.path.isfile(path):
        raise HeadMotionError(f'pose table not found: {path}')
    with open(path, 'r', encoding='utf-8', errors='replace') as fh:
        lines = fh.read().splitlines()

    body = [(k + 1, ln) for k, ln in enumerate(lines)
            if ln.strip() and not ln.lstrip().startswith('#')]
    if not body:
        raise HeadMotionError(f'{path}: empty pose table (no header line)')
    hline, header = body[0]
    delim = delimiter if delimiter is not None else (',' if ',' in header else None)

    def split(s):
        return [c.strip() for c in s.split(delim)] if delim is not None else s.split()

    names = split(header)
    for nm in names:
        try:
            float(nm)
        except ValueError:
            continue
        raise HeadMotionError(f'{path}:{hline}: bad header: expected column names, got '
                              f'{header.strip()!r}')
    if len(set(names)) != len(names) or any(not nm for nm in names):
        raise HeadMotionError(f'{path}:{hline}: bad header: empty or repeated column names in '
                              f'{header.strip()!r}')
    wanted = [time_column, *quat_columns] + list(position_columns or ())
    missing = [nm for nm in wanted if nm not in names]
    if missing:
        raise HeadMotionError(f'{path}:{hline}: missing column(s) {missing}; the header has '
                              f'{names}')
    col = {nm: names.index(nm) for nm in names}

    rows, row_lines = [], []
    for ln_no, ln in body[1:]:
        parts = split(ln)
        if len(parts) != len(names):
            raise HeadMotionError(f'{path}:{ln_no}: {len(parts)} fields, the header names '
                                  f'{len(names)}')
        rows.append(parts)
        row_lines.append(ln_no)
    if not rows:
        raise HeadMotionError(f'{path}: pose table has a header but no rows')
    num_cols = [col[nm] for nm in quat_columns] + [col[nm] for nm in position_columns or ()]
    try:
        vals = np.array([[r[c] for c in num_cols] for r in rows], dtype=np.float64)
    except ValueError:
        for r, ln_no in zip(rows, row_lines):
            for c in num_cols:
                try:
                    float(r[c])
                except ValueError:
                    raise HeadMotionError(f'{path}:{ln_no}: column {names[c]!r} value '
                                          f'{r[c]!r} is not a number') from None
        raise
    t_ns = np.zeros(len(rows), dtype=np.int64)
    t_ok = np.ones(len(rows), dtype=bool)
    tc = col[time_column]
    stamps = []
    for i, (r, ln_no) in enumerate(zip(rows, row_lines)):
        try:
            d = decimal.Decimal(r[tc])
        except decimal.InvalidOperation:
            raise HeadMotionError(f'{path}:{ln_no}: time {r[tc]!r} is not a number') from None
        stamps.append(d if d.is_finite() else None)
        t_ok[i] = d.is_finite()
    first = next((d for d in stamps if d is not None), decimal.Decimal(0))
    origin = int((first * ns_per_tick).to_integral_value(rounding=decimal.ROUND_HALF_EVEN))
    absolute = 0 <= origin <= MAX_STAMP_NS // 2
    for i, d in enumerate(stamps):
        if d is None:
            continue
        rel = int(((d - first) * ns_per_tick).to_integral_value(
            rounding=decimal.ROUND_HALF_EVEN))
        v = rel + (origin if absolute else 0)
        if not -MAX_STAMP_NS <= v <= MAX_STAMP_NS:
            raise HeadMotionError(f'{path}:{row_lines[i]}: time {d} is {rel / 1e9:.3g} s from '
                                  'the first row: more than a ROS time can hold (a wrong '
                                  '--time-unit / --time-scale?)')
        t_ns[i] = v

    q = vals[:, :4] if quat_order == 'xyzw' else vals[:, [1, 2, 3, 0]]
    norm = np.linalg.norm(q, axis=1)
    q_ok = np.isfinite(norm) & (norm > 1e-9)
    p_ok = np.ones(len(rows), dtype=bool)
    if position_columns is not None:
        p_ok = np.all(np.isfinite(vals[:, 4:7]), axis=1)
    keep = q_ok & p_ok & t_ok
    # time must increase over kept rows
    last = None
    for i in np.nonzero(keep)[0]:
        if last is not None and t_ns[i] <= last:
            keep[i] = False
            t_ok[i] = False
        else:
            last = t_ns[i]
    dropped = {'bad_quaternion': int(np.sum(~q_ok)),
               'bad_position': int(np.sum(q_ok & ~p_ok)),
               'bad_time': int(np.sum(q_ok & p_ok & ~t_ok))}
    if not np.any(keep):
        raise HeadMotionError(f'{path}: no usable rows (dropped: {dropped})')
    qk = make_sign_continuous(q[keep] / norm[keep, None])
    if position_columns is not None:
        pos = vals[keep, 4:7]
    else:
        off = np.zeros(3) if neck_offset is None else np.asarray(neck_offset, float).reshape(3)
        piv = np.zeros(3) if pivot is None else np.asarray(pivot, float).reshape(3)
        pos = piv + quat_to_matrix(qk) @ off
    unit = f'{time_scale} s ticks' if time_scale is not None else time_unit
    desc = source or (f'{path} (pose table, time {time_column!r} [{unit}]'
                      + ('' if absolute else ', relative to the first row') + ')')
    return HeadMotion(t_ns[keep], pos, qk, source=desc, dropped=dropped)


def read_vr360(path: str, neck_offset=None, pivot=None) -> HeadMotion:
    """Head-mounted-display trace of Corbillon et al. (MMSys 2017/2018): header
    ``timestamp viewpoint w x y z``, time in seconds, orientation only.

    Positions are ``pivot + R @ neck_offset`` (zeros by default; see :func:`read_pose_table`).
    The quaternion is taken as given (world z up, head z up: see the module doc); following
    Corbillon et al. (2017), "360-Degree Video Head Movement Dataset", the rotation turns the
    reference viewing direction (1, 0, 0) into the viewing direction, i.e. head x is forward as
    in REP-103.  The ``viewpoint`` column (which video viewpoint was shown) is ignored.
    """
    return read_pose_table(path, time_column='timestamp', time_unit='s',
                           quat_columns=('w', 'x', 'y', 'z'), quat_order='wxyz',
                           position_columns=None, neck_offset=neck_offset, pivot=pivot,
                           source=f'{path} (VR360 HMD trace, orientation only)')


def write_pose_csv(path: str, motion: HeadMotion, comments=()) -> None:
    """Write ``t_s,px,py,pz,qx,qy,qz,qw`` rows (time in s to 1 us, 7 significant digits for
    positions [m] and quaternions); ``comments`` are written first as ``# `` lines.
    Times are absolute (``t_ns / 1e9``)."""
    with open(path, 'w', encoding='utf-8', newline='\n') as fh:
        for c in comments:
            for ln in str(c).splitlines() or ['']:
                fh.write(('# ' + ln).rstrip() + '\n')
        fh.write(','.join(POSE_CSV_COLUMNS) + '\n')
        for t, p, q in zip(motion.t_ns, motion.position, motion.quaternion):
            sec, ns = divmod(int(t), 10 ** 9)
            us = int(round(ns / 1000.0))
            if us == 10 ** 6:
                sec, us = sec + 1, 0
            ts = f'{sec}.{us:06d}' if sec >= 0 else f'{t * 1e-9:.6f}'
            fh.write(ts + ',' + ','.join(f'{v:.7g}' for v in (*p, *q)) + '\n')


def read_pose_csv(path: str) -> HeadMotion:
    """Read a file written by :func:`write_pose_csv`."""
    return read_pose_table(path, time_column='t_s', time_unit='s',
                           quat_columns=('qx', 'qy', 'qz', 'qw'), quat_order='xyzw',
                           position_columns=('px', 'py', 'pz'), delimiter=',',
                           source=f'{path} (pose CSV)')


def load_bundled_walk() -> HeadMotion:
    """CMU 131_01 "start, walk, stop" head poses shipped with the package (994 frames, 120 Hz,
    8.3 s; head centre, metres, REP-103 frames; made by scripts/make_head_motion_data.py).
    Attribution: ``data/ATTRIBUTION.md``."""
    if not os.path.isfile(BUNDLED_WALK_CSV):
        raise HeadMotionError(f'bundled walk data missing: {BUNDLED_WALK_CSV} '
                              '(regenerate with scripts/make_head_motion_data.py)')
    m = read_pose_csv(BUNDLED_WALK_CSV)
    m.source = (f'{BUNDLED_WALK_CSV} (CMU mocap 131_01 walk, head centre, '
                'via yuki-koyama/bvh11; see data/ATTRIBUTION.md)')
    return m
