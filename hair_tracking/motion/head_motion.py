"""A head-pose stream, cleaned, and the maths of head motion.

:class:`HeadMotion` holds integer nanosecond times, head positions [m] and unit quaternions
(x, y, z, w) in the REP-103 conventions of the project (world z up; head frame x forward out of
the face, y to the person's left, z up through the top of the head when the person stands
upright looking ahead).  A pose maps head-frame points to the world,
``p_world = position + R(q) @ p_head`` (see ``model.HeadPose``).  The quaternion stream is
normalised and sign-continuous (consecutive dot products >= 0), so interpolation never takes the
long way round.  Every reader of :mod:`hair_tracking.motion` (BVH, pose tables) and every
generator of :mod:`hair_tracking.evaluation.synthetic_motion` produces one.
"""
from dataclasses import dataclass, field

import numpy as np

from hair_tracking.core.model import HeadPose
from hair_tracking.core.transforms import quat_to_matrix


class HeadMotionError(ValueError):
    """A motion file is missing, malformed, or asked for something it does not contain."""


class UnitsError(HeadMotionError):
    """The units of a recording cannot be told from the file: an option has to name them."""


#: The median rate [Hz] a head-pose stream has (a tracker, a headset, motion capture), and the
#: longest it lasts [s]: a reader that chooses a file's units checks its choice against them,
#: and a stream outside them is reported (see :func:`timing_problem`).
PLAUSIBLE_RATE_HZ = (1.0, 10_000.0)
PLAUSIBLE_DURATION_S = 86_400.0
#: Fastest median head speed [m/s] taken from a recording without a warning (a sprint is 10).
PLAUSIBLE_HEAD_SPEED = 10.0


def timing_problem(rate_hz: float, duration_s: float) -> str:
    """Why a head-pose stream of this median rate [Hz] and duration [s] cannot be right (times
    read in the wrong unit, most likely), or '' when it can.  A rate of 0 (one sample) is not
    checked."""
    lo, hi = PLAUSIBLE_RATE_HZ
    if rate_hz > 0 and not lo <= rate_hz <= hi:
        return (f'a median rate of {rate_hz:.3g} Hz over {duration_s:.4g} s (a head-pose '
                f'stream has {lo:g} Hz to {hi:g} Hz)')
    if duration_s > PLAUSIBLE_DURATION_S:
        return (f'a duration of {duration_s:.4g} s (more than a day) at a median rate of '
                f'{rate_hz:.3g} Hz')
    return ''


def speed_problem(position: np.ndarray, t_ns: np.ndarray) -> str:
    """Why a head moving through ``position`` [m] (F, 3) at ``t_ns`` cannot be a person's (its
    median speed over :data:`PLAUSIBLE_HEAD_SPEED` m/s: lengths read in the wrong unit, most
    likely), or '' when it can."""
    if len(t_ns) < 2:
        return ''
    dt = np.diff(np.asarray(t_ns, dtype=np.int64)) * 1e-9
    step = np.linalg.norm(np.diff(np.asarray(position, dtype=np.float64), axis=0), axis=1)
    speed = float(np.median(step[dt > 0] / dt[dt > 0])) if np.any(dt > 0) else 0.0
    if speed > PLAUSIBLE_HEAD_SPEED:
        return (f'the head moves at a median {speed:.4g} m/s (a person\'s head: below '
                f'{PLAUSIBLE_HEAD_SPEED:g} m/s)')
    return ''


@dataclass
class HeadMotion:
    """A recorded head-pose stream, cleaned.

    ``t_ns`` (F,) int64 strictly increasing times [ns]; ``position`` (F, 3) float64 head origin in
    the world [m]; ``quaternion`` (F, 4) float64 unit (x, y, z, w), sign-continuous, rotating
    head-frame vectors into the world.  ``source`` names where it came from (a path and what was
    read), ``dropped`` counts input rows kept out by reason (``'bad_quaternion'`` NaN/Inf/zero
    norm, ``'bad_position'`` NaN/Inf, ``'bad_time'`` NaN or not after the previous kept row);
    ``units`` says how a reader took the file's units when it recognised them itself ('' when
    they were given).
    Construction checks shapes, finiteness, increasing times and unit quaternions (to 1e-6),
    and makes the quaternion stream sign-continuous.
    """

    t_ns: np.ndarray
    position: np.ndarray
    quaternion: np.ndarray
    source: str = ''
    dropped: dict = field(default_factory=dict)
    units: str = ''

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


def make_sign_continuous(q: np.ndarray) -> np.ndarray:
    """Flip samples of a (F, 4) quaternion stream so consecutive dot products are >= 0."""
    q = np.array(q, dtype=np.float64)
    if len(q) < 2:
        return q
    d = np.sum(q[1:] * q[:-1], axis=1)
    flips = np.concatenate([[0], np.cumsum(d < 0)])
    q[flips % 2 == 1] *= -1.0
    return q


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
