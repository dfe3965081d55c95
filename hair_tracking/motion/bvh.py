"""BVH (Biovision Hierarchy) motion capture -> head poses.

:func:`read_bvh` parses HIERARCHY and MOTION, keeping every joint's CHANNELS order as written (it
differs between joints in the CMU conversion), and :meth:`Bvh.forward_kinematics` evaluates the
chain.  :func:`load_bvh_head_motion` turns one joint into a head-pose stream
(:class:`~hair_tracking.motion.head_motion.HeadMotion`).  BVH semantics follow Meredith &
Maddock (2001), "Motion capture file formats explained" (University of Sheffield, CS-01-11): a
joint's local transform is ``T(OFFSET + position channels) * R_c1(a1) * R_c2(a2) * R_c3(a3)``
with the rotation channels multiplied in the order they are listed, angles in degrees, and the
global transform is the product down the chain from the root.

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
:func:`~hair_tracking.motion.head_motion.walking_direction`) the head's x axis follows the
horizontal walking direction with a mean cosine of 0.97, and its z axis has a mean cosine of
0.99 with world up (0.95 over the whole clip, which includes bending down at t = 2.5-3.5 s);
:func:`infer_head_axes` recovers the same mapping from the motion alone, and the tests check
both.  The reported head origin is the head centre (middle of the Head bone, see
:func:`load_bvh_head_motion`).
"""
from dataclasses import dataclass
import math
import os
import re

import numpy as np

from hair_tracking.core.transforms import matrices_to_quats
from hair_tracking.motion.head_motion import (HeadMotion, HeadMotionError, make_sign_continuous,
                                              UnitsError, walking_direction)

#: metres per BVH length unit for the CMU conversions (README of the data set: 0.056444).
CMU_SCALE_M = 0.056444

#: metres per BVH length unit, by name ('cmu': the CMU conversions).
BVH_UNITS = {'cmu': CMU_SCALE_M, 'm': 1.0, 'cm': 0.01, 'mm': 0.001, 'in': 0.0254}

#: How tall a skeleton's rest pose is taken to be when its unit is recognised [m] (an adult).
REST_HEIGHT_M = 1.7
#: A unit given for a BVH file is refused when it makes the rest pose this many times shorter
#: or taller than :data:`REST_HEIGHT_M` (0.57 m to 5.1 m: children and partial skeletons
#: pass, a centimetre file read in metres or millimetres does not).
IMPLAUSIBLE_HEIGHT_FACTOR = 3.0

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

_AXIS_INDEX = {'X': 0, 'Y': 1, 'Z': 2}


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


def recognise_units(bvh: Bvh):
    """The length unit of a BVH file from its skeleton: ``(metres per unit, words)``.

    The rest pose (every channel 0) is taken to stand :data:`REST_HEIGHT_M` tall, BVH being y
    up; the unit of :data:`BVH_UNITS` nearest to the height that implies (by ratio) is chosen
    when it is within a factor 1.35, otherwise UnitsError asks for ``--units`` or ``--scale``.
    """
    height = rest_height(bvh)
    if not height > 0:
        raise UnitsError(f'{bvh.path}: cannot recognise the units (the rest pose has no '
                         f'height); give --units or --scale')
    implied = REST_HEIGHT_M / height
    name = min(BVH_UNITS, key=lambda k: abs(math.log(BVH_UNITS[k] / implied)))
    if abs(math.log(BVH_UNITS[name] / implied)) > math.log(1.35):
        raise UnitsError(f'{bvh.path}: cannot recognise the units: the rest pose is '
                         f'{height:.4g} units tall, which matches none of '
                         f'{", ".join(BVH_UNITS)}; give --units or --scale')
    return BVH_UNITS[name], (f'{name} (auto: rest pose {height:.4g} units tall = '
                             f'{height * BVH_UNITS[name]:.2f} m)')


def rest_height(bvh: Bvh) -> float:
    """How tall the rest pose (every channel 0) stands [BVH units], BVH being y up."""
    rest = Bvh(joints=bvh.joints, motion=np.zeros((1, bvh.motion.shape[1])),
               frame_time=bvh.frame_time, path=bvh.path)
    return float(np.ptp(rest.all_positions()[0][:, 1]))


def units_problem(bvh: Bvh, scale: float, words: str) -> str:
    """Why ``scale`` [m per unit] (named ``words``) cannot be the unit of ``bvh``: a rest pose
    more than :data:`IMPLAUSIBLE_HEIGHT_FACTOR` times shorter or taller than a person
    (:data:`REST_HEIGHT_M`), naming the unit the skeleton suggests; '' when it can."""
    height = rest_height(bvh) * scale
    if not height > 0 or abs(math.log(height / REST_HEIGHT_M)) <= \
            math.log(IMPLAUSIBLE_HEIGHT_FACTOR):
        return ''
    try:
        suggested = f'; the skeleton suggests {recognise_units(bvh)[1]}'
    except UnitsError:
        suggested = ''
    return (f'{bvh.path}: with units {words} the rest pose stands {height:.4g} m tall, which '
            f'no person does{suggested}')


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
