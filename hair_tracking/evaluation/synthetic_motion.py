"""Synthetic head motions: extremes for the evaluation and the stability matrix.

Every generator returns a :class:`~hair_tracking.motion.head_motion.HeadMotion` (integer
nanosecond times, head-centre positions [m] and unit quaternions (x, y, z, w) in the world
frame, REP-103: z up, head x forward), so synthetic and recorded motions go through the same
code.  The head
starts upright at :data:`HEAD_HEIGHT` above the origin.  Motions are defined analytically and
sampled at ``rate_hz``; rotations are built from rotation vectors (axis * angle) so a given peak
angular speed is exact up to sampling.

Generators (all deterministic; ``seed`` where random):

* :func:`still` -- the head does not move (settling, long gaps).
* :func:`shake` -- rotation ``angle(t) = A sin(2 pi f t)`` about a head axis: peak angular speed
  ``2 pi f A`` [rad/s] (a head shake about z, a nod about y).
* :func:`spin` -- constant angular speed about a world axis, started abruptly (an infinite
  angular acceleration at t = 0, the harshest case) or over ``ramp_s``.
* :func:`oscillate` -- translation ``x(t) = A sin(2 pi f t)`` along a world axis: peak speed
  ``2 pi f A`` [m/s].
* :func:`dash` -- accelerate to ``speed`` [m/s] in ``ramp_s``, cruise, stop in ``ramp_s``.
* :func:`teleport` -- still, then a jump of ``distance`` [m] between two samples, then still.
* :func:`wander` -- a smooth random motion (sums of sinusoids with random phases) of any length,
  bounded for any duration: the one-hour run.
* :func:`concat` joins motions end to start (the next one is moved to start where the previous
  ended), :func:`with_tail` appends a still head, :func:`resample` changes the sampling rate
  (linear position, slerp orientation).

:func:`glitch_stream` turns a motion into raw pose arrays with NaN positions, NaN or zero
quaternions and sign-flipped quaternions injected, for the input-hygiene cases (a
``HeadMotion`` cannot hold invalid samples by construction).
"""
from dataclasses import dataclass
import math
from typing import Callable, Dict, Sequence

import numpy as np

from hair_tracking.core.transforms import quat_multiply, quat_to_matrix, slerp
from hair_tracking.motion.head_motion import HeadMotion, make_sign_continuous

#: Height [m] of the head centre above the world origin at the start of every synthetic motion.
HEAD_HEIGHT = 1.6

_NS = 10 ** 9


class SyntheticMotionError(ValueError):
    """A generator was given an impossible parameter (names it and says why)."""


def _check_positive(name: str, value: float, allow_zero: bool = False) -> float:
    v = float(value)
    if not math.isfinite(v) or v < 0.0 or (v == 0.0 and not allow_zero):
        bound = '>= 0' if allow_zero else '> 0'
        raise SyntheticMotionError(f'{name} must be a finite number {bound}, got {value!r}')
    return v


def _unit_axis(name: str, axis) -> np.ndarray:
    a = np.asarray(axis, dtype=np.float64).reshape(-1)
    if a.size != 3 or not np.all(np.isfinite(a)) or np.linalg.norm(a) < 1e-12:
        raise SyntheticMotionError(f'{name} must be a non-zero 3-vector, got {axis!r}')
    return a / np.linalg.norm(a)


def times_ns(duration_s: float, rate_hz: float) -> np.ndarray:
    """Sample times [ns] from 0 to ``duration_s`` inclusive at ``rate_hz`` (integer ns)."""
    duration_s = _check_positive('duration_s', duration_s, allow_zero=True)
    rate_hz = _check_positive('rate_hz', rate_hz)
    n = int(math.floor(duration_s * rate_hz + 1e-9)) + 1
    return np.round(np.arange(n) * (_NS / rate_hz)).astype(np.int64)


def rotvec_to_quat(rv: np.ndarray) -> np.ndarray:
    """(F, 3) rotation vectors (axis * angle [rad]) -> (F, 4) unit quaternions (x, y, z, w)."""
    rv = np.asarray(rv, dtype=np.float64)
    ang = np.linalg.norm(rv, axis=-1, keepdims=True)
    half = 0.5 * ang
    # sin(a/2)/a, with its limit 1/2 at a = 0
    k = np.where(ang > 1e-12, np.sin(half) / np.where(ang > 1e-12, ang, 1.0), 0.5)
    return np.concatenate([rv * k, np.cos(half)], axis=-1)


def _motion(t_ns, position, quaternion, source) -> HeadMotion:
    q = np.asarray(quaternion, dtype=np.float64)
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    return HeadMotion(np.asarray(t_ns, dtype=np.int64), np.asarray(position, dtype=np.float64),
                      make_sign_continuous(q), source=source)


def _base_position(f: int) -> np.ndarray:
    p = np.zeros((f, 3))
    p[:, 2] = HEAD_HEIGHT
    return p


def _identity_quats(f: int) -> np.ndarray:
    q = np.zeros((f, 4))
    q[:, 3] = 1.0
    return q


# ----------------------------------------------------------------- generators
def still(duration_s: float = 1.0, rate_hz: float = 120.0) -> HeadMotion:
    """An upright head at rest at ``(0, 0, HEAD_HEIGHT)`` for ``duration_s`` [s]."""
    t = times_ns(duration_s, rate_hz)
    return _motion(t, _base_position(len(t)), _identity_quats(len(t)),
                   f'synthetic still {duration_s:g} s')


def shake(peak_angular_speed: float, frequency_hz: float = 3.0, axis=(0.0, 0.0, 1.0),
          duration_s: float = 2.0, rate_hz: float = 120.0) -> HeadMotion:
    """Head rotating back and forth about the head-frame ``axis`` (z: shake "no", y: nod "yes").

    ``angle(t) = A sin(2 pi f t)`` with ``A = peak_angular_speed / (2 pi f)`` [rad]; the peak
    angular speed [rad/s] is reached at every zero crossing.  The head centre does not move.
    """
    w = _check_positive('peak_angular_speed', peak_angular_speed, allow_zero=True)
    f = _check_positive('frequency_hz', frequency_hz)
    ax = _unit_axis('axis', axis)
    t = times_ns(duration_s, rate_hz)
    ts = t * 1e-9
    amp = w / (2.0 * math.pi * f)
    ang = amp * np.sin(2.0 * math.pi * f * ts)
    q = rotvec_to_quat(ang[:, None] * ax)
    return _motion(t, _base_position(len(t)), q,
                   f'synthetic shake {w:g} rad/s peak, {f:g} Hz, amplitude {amp:.3g} rad, '
                   f'axis {ax.round(3).tolist()}')


def spin(angular_speed: float, axis=(0.0, 0.0, 1.0), duration_s: float = 2.0,
         ramp_s: float = 0.0, rate_hz: float = 120.0) -> HeadMotion:
    """Head spinning about the world ``axis`` through the head centre at ``angular_speed``
    [rad/s], reached linearly over ``ramp_s`` [s] (0: an abrupt start)."""
    w = _check_positive('angular_speed', angular_speed, allow_zero=True)
    ramp = _check_positive('ramp_s', ramp_s, allow_zero=True)
    ax = _unit_axis('axis', axis)
    t = times_ns(duration_s, rate_hz)
    ts = t * 1e-9
    if ramp > 0.0:
        ang = np.where(ts < ramp, 0.5 * w * ts * ts / ramp, w * (ts - 0.5 * ramp))
    else:
        ang = w * ts
    q = rotvec_to_quat(ang[:, None] * ax)
    return _motion(t, _base_position(len(t)), q,
                   f'synthetic spin {w:g} rad/s about {ax.round(3).tolist()}, ramp {ramp:g} s')


def oscillate(peak_speed: float, amplitude: float = 0.5, axis=(1.0, 0.0, 0.0),
              duration_s: float = 2.0, rate_hz: float = 120.0) -> HeadMotion:
    """Head translating ``x(t) = A sin(2 pi f t)`` along the world ``axis``, upright, with
    ``f = peak_speed / (2 pi A)``: peak speed ``peak_speed`` [m/s], peak acceleration
    ``peak_speed^2 / A`` [m/s^2]."""
    v = _check_positive('peak_speed', peak_speed, allow_zero=True)
    amp = _check_positive('amplitude', amplitude)
    ax = _unit_axis('axis', axis)
    t = times_ns(duration_s, rate_hz)
    ts = t * 1e-9
    omega = v / amp
    p = _base_position(len(t)) + (amp * np.sin(omega * ts))[:, None] * ax
    return _motion(t, p, _identity_quats(len(t)),
                   f'synthetic oscillation {v:g} m/s peak, amplitude {amp:g} m, '
                   f'{omega / (2 * math.pi):.3g} Hz')


def dash(speed: float, ramp_s: float = 0.1, cruise_s: float = 1.0, axis=(1.0, 0.0, 0.0),
         rest_s: float = 0.5, rate_hz: float = 120.0) -> HeadMotion:
    """Still for ``rest_s``, accelerate uniformly to ``speed`` [m/s] along the world ``axis`` in
    ``ramp_s`` [s] (0: instantly), cruise ``cruise_s``, stop in ``ramp_s``, still ``rest_s``."""
    v = _check_positive('speed', speed, allow_zero=True)
    ramp = _check_positive('ramp_s', ramp_s, allow_zero=True)
    cruise = _check_positive('cruise_s', cruise_s, allow_zero=True)
    rest = _check_positive('rest_s', rest_s, allow_zero=True)
    ax = _unit_axis('axis', axis)
    total = 2.0 * rest + 2.0 * ramp + cruise
    t = times_ns(total, rate_hz)
    ts = t * 1e-9
    t1, t2, t3 = rest + ramp, rest + ramp + cruise, rest + 2.0 * ramp + cruise
    s = np.zeros_like(ts)
    if ramp > 0.0:
        a = v / ramp
        m = (ts > rest) & (ts <= t1)
        s[m] = 0.5 * a * (ts[m] - rest) ** 2
        d1 = 0.5 * v * ramp
    else:
        d1 = 0.0
    m = (ts > t1) & (ts <= t2)
    s[m] = d1 + v * (ts[m] - t1)
    d2 = d1 + v * cruise
    if ramp > 0.0:
        m = (ts > t2) & (ts <= t3)
        u = ts[m] - t2
        s[m] = d2 + v * u - 0.5 * (v / ramp) * u * u
    s[ts > t3] = d2 + d1
    p = _base_position(len(t)) + s[:, None] * ax
    return _motion(t, p, _identity_quats(len(t)),
                   f'synthetic dash {v:g} m/s, ramp {ramp:g} s, cruise {cruise:g} s')


def teleport(distance: float = 1.0, axis=(1.0, 0.0, 0.0), before_s: float = 1.0,
             after_s: float = 1.5, turn_rad: float = 0.0, rate_hz: float = 120.0) -> HeadMotion:
    """Still head that jumps by ``distance`` [m] along the world ``axis`` (and turns by
    ``turn_rad`` about world z) between two consecutive samples at ``before_s``."""
    d = _check_positive('distance', distance, allow_zero=True)
    ax = _unit_axis('axis', axis)
    t = times_ns(before_s + after_s, rate_hz)
    jumped = t * 1e-9 > before_s + 0.5 / rate_hz
    p = _base_position(len(t))
    p[jumped] += d * ax
    q = _identity_quats(len(t))
    q[jumped] = rotvec_to_quat(np.array([0.0, 0.0, float(turn_rad)]))
    return _motion(t, p, q, f'synthetic teleport {d:g} m, turn {turn_rad:g} rad')


def wander(duration_s: float, seed: int = 0, rate_hz: float = 60.0, angle_rad: float = 0.6,
           reach_m: float = 0.3, components: int = 4) -> HeadMotion:
    """Smooth random head motion of any length (bounded: sums of sinusoids).

    Each of yaw, pitch, roll is a sum of ``components`` sinusoids of frequencies 0.05-1.5 Hz
    with random phases, scaled to a peak of about ``angle_rad`` (roll half of it); the head
    centre wanders the same way within about ``reach_m`` [m] horizontally and ``reach_m / 3``
    vertically.  Samples are generated in chunks, so an hour at 60 Hz is cheap.
    """
    duration_s = _check_positive('duration_s', duration_s)
    rng = np.random.default_rng(int(seed))
    freqs = rng.uniform(0.05, 1.5, size=(6, components))
    phases = rng.uniform(0.0, 2.0 * math.pi, size=(6, components))
    weights = rng.uniform(0.5, 1.0, size=(6, components))
    weights /= weights.sum(axis=1, keepdims=True)
    scale = np.array([angle_rad, angle_rad, 0.5 * angle_rad, reach_m, reach_m, reach_m / 3.0])
    t = times_ns(duration_s, rate_hz)
    sig = np.empty((len(t), 6))
    chunk = 1 << 16
    for a in range(0, len(t), chunk):
        ts = t[a:a + chunk] * 1e-9
        arg = 2.0 * math.pi * ts[:, None, None] * freqs[None] + phases[None]
        sig[a:a + chunk] = (weights[None] * np.sin(arg)).sum(axis=2) * scale
    yaw = rotvec_to_quat(np.stack([0 * sig[:, 0], 0 * sig[:, 0], sig[:, 0]], axis=1))
    pitch = rotvec_to_quat(np.stack([0 * sig[:, 1], sig[:, 1], 0 * sig[:, 1]], axis=1))
    roll = rotvec_to_quat(np.stack([sig[:, 2], 0 * sig[:, 2], 0 * sig[:, 2]], axis=1))
    q = quat_multiply(yaw, quat_multiply(pitch, roll))
    p = _base_position(len(t)) + sig[:, 3:]
    return _motion(t, p, q, f'synthetic wander {duration_s:g} s, seed {seed}')


# ------------------------------------------------------------------ combinators
def concat(*motions: HeadMotion, gap_s: float = None) -> HeadMotion:
    """Join motions in time; each next one is moved rigidly (position and orientation) so that
    it starts where the previous one ended, ``gap_s`` [s] after it (default: the previous
    motion's median sample interval)."""
    if not motions:
        raise SyntheticMotionError('concat needs at least one motion')
    out_t, out_p, out_q = [motions[0].t_ns], [motions[0].position], [motions[0].quaternion]
    for m in motions[1:]:
        last_t, last_p, last_q = out_t[-1][-1], out_p[-1][-1], out_q[-1][-1]
        prev = out_t[-1]
        step = gap_s if gap_s is not None else (
            float(np.median(np.diff(prev))) * 1e-9 if len(prev) > 1 else 1e-3)
        t0 = int(last_t + round(_check_positive('gap_s', step) * _NS)) - int(m.t_ns[0])
        # rigid change of frame taking m's first pose onto the previous last pose
        q0 = m.quaternion[0]
        q0_inv = np.array([-q0[0], -q0[1], -q0[2], q0[3]])
        dq = quat_multiply(last_q, q0_inv)
        rot = quat_to_matrix(dq)
        out_t.append(m.t_ns + t0)
        out_p.append((m.position - m.position[0]) @ rot.T + last_p)
        out_q.append(quat_multiply(dq[None], m.quaternion))
    src = ' + '.join(m.source or '?' for m in motions)
    return _motion(np.concatenate(out_t), np.concatenate(out_p), np.concatenate(out_q), src)


def with_tail(motion: HeadMotion, still_s: float = 1.0, rate_hz: float = None) -> HeadMotion:
    """``motion`` followed by ``still_s`` [s] of the head held at its last pose."""
    still_s = _check_positive('still_s', still_s, allow_zero=True)
    if still_s == 0.0:
        return motion
    rate = rate_hz or (motion.rate_hz if len(motion) > 1 else 120.0)
    extra = times_ns(still_s, rate)[1:]
    t = np.concatenate([motion.t_ns, motion.t_ns[-1] + extra])
    p = np.concatenate([motion.position, np.repeat(motion.position[-1:], len(extra), axis=0)])
    q = np.concatenate([motion.quaternion, np.repeat(motion.quaternion[-1:], len(extra), axis=0)])
    return _motion(t, p, q, f'{motion.source} + still {still_s:g} s')


def resample(motion: HeadMotion, rate_hz: float) -> HeadMotion:
    """``motion`` sampled at ``rate_hz`` over its own time span: positions linearly
    interpolated, orientations by slerp (shortest arc)."""
    rate_hz = _check_positive('rate_hz', rate_hz)
    t = motion.t_ns[0] + times_ns(motion.duration_s, rate_hz)
    t = t[t <= motion.t_ns[-1]]
    i = np.clip(np.searchsorted(motion.t_ns, t, side='right'), 1, max(1, len(motion) - 1))
    if len(motion) == 1:
        return _motion(t, np.repeat(motion.position, len(t), 0),
                       np.repeat(motion.quaternion, len(t), 0), motion.source)
    t0, t1 = motion.t_ns[i - 1], motion.t_ns[i]
    u = np.clip((t - t0) / (t1 - t0), 0.0, 1.0)
    p = (1.0 - u)[:, None] * motion.position[i - 1] + u[:, None] * motion.position[i]
    q = slerp(motion.quaternion[i - 1], motion.quaternion[i], u)
    return _motion(t, p, q, f'{motion.source} resampled at {rate_hz:g} Hz')


def window(motion: HeadMotion, start_s: float, duration_s: float) -> HeadMotion:
    """The samples of ``motion`` with ``start_s <= t_s <= start_s + duration_s``, times kept."""
    ts = motion.t_s
    keep = (ts >= start_s) & (ts <= start_s + duration_s)
    if keep.sum() < 2:
        raise SyntheticMotionError(f'window [{start_s:g}, {start_s + duration_s:g}] s holds '
                                   f'fewer than 2 samples of {motion.source}')
    return HeadMotion(motion.t_ns[keep], motion.position[keep], motion.quaternion[keep],
                      source=f'{motion.source} [{start_s:g} s, +{duration_s:g} s]')


def busiest_window(motion: HeadMotion, duration_s: float) -> float:
    """Start time [s] of the ``duration_s`` window with the largest total head rotation
    (deterministic: the earliest such window on a 0.5 s grid)."""
    from hair_tracking.motion.head_motion import angular_speed
    ts = motion.t_s
    if ts[-1] <= duration_s:
        return 0.0
    ang = np.concatenate([[0.0], np.cumsum(angular_speed(motion) * np.diff(ts))])
    starts = np.arange(0.0, ts[-1] - duration_s + 1e-9, 0.5)
    a = np.interp(starts, ts, ang)
    b = np.interp(starts + duration_s, ts, ang)
    return float(starts[int(np.argmax(b - a))])


# -------------------------------------------------------------- invalid input
@dataclass
class RawStream:
    """Raw pose samples as a tracker might send them (may contain invalid values)."""

    t_ns: np.ndarray          # (F,) int64
    position: np.ndarray      # (F, 3) may hold NaN
    quaternion: np.ndarray    # (F, 4) may hold NaN, zeros, either sign, any norm
    injected: Dict[str, int]  # how many samples of each kind were injected
    valid: np.ndarray         # (F,) bool: the sample is a valid pose (a hygienic reader keeps it)


def glitch_stream(motion: HeadMotion, nan_every: int = 0, zero_every: int = 0,
                  flip_every: int = 0, scale_every: int = 0, seed: int = 0) -> RawStream:
    """Raw arrays of ``motion`` with faults injected at random samples (never the first):

    * about one in ``nan_every`` samples gets a NaN position or a NaN quaternion component;
    * about one in ``zero_every`` gets a zero quaternion;
    * about one in ``flip_every`` gets its quaternion negated (same rotation, q vs -q);
    * about one in ``scale_every`` gets its quaternion scaled by a factor in [0.5, 2] (not unit).

    0 disables a kind.  ``valid`` marks the samples a hygienic reader should keep.
    """
    rng = np.random.default_rng(int(seed))
    f = len(motion)
    p = motion.position.copy()
    q = motion.quaternion.copy()
    valid = np.ones(f, dtype=bool)
    injected = {'nan': 0, 'zero_quaternion': 0, 'sign_flip': 0, 'scaled': 0}

    def pick(every):
        if every <= 0 or f < 2:
            return np.zeros(0, dtype=np.int64)
        m = rng.random(f) < 1.0 / every
        m[0] = False
        return np.flatnonzero(m)

    for i in pick(scale_every):
        q[i] *= rng.uniform(0.5, 2.0)
        injected['scaled'] += 1
    for i in pick(flip_every):
        q[i] = -q[i]
        injected['sign_flip'] += 1
    for i in pick(nan_every):
        if rng.random() < 0.5:
            p[i, rng.integers(3)] = np.nan
        else:
            q[i, rng.integers(4)] = np.nan
        valid[i] = False
        injected['nan'] += 1
    for i in pick(zero_every):
        if valid[i]:
            q[i] = 0.0
            valid[i] = False
            injected['zero_quaternion'] += 1
    return RawStream(motion.t_ns.copy(), p, q, injected, valid)


# ------------------------------------------------------------------ registry
#: Named synthetic motions for the command line: name -> (factory(duration_s), description).
NAMED: Dict[str, Sequence] = {
    'shake10': (lambda d: with_tail(shake(10.0, 2.0, duration_s=d), 0.5),
                'head shake "no", 10 rad/s peak at 2 Hz (amplitude 0.8 rad)'),
    'nod8': (lambda d: with_tail(shake(8.0, 2.5, axis=(0, 1, 0), duration_s=d), 0.5),
             'nod "yes", 8 rad/s peak at 2.5 Hz (amplitude 0.51 rad)'),
    'shake50': (lambda d: with_tail(shake(50.0, 8.0, duration_s=d), 0.5),
                'violent shake, 50 rad/s peak at 8 Hz (amplitude 1.0 rad)'),
    'dash20': (lambda d: dash(20.0, 0.1, max(0.1, d - 1.2)),
               'dash: 0 -> 20 m/s in 0.1 s, cruise, stop in 0.1 s'),
    'wander': (lambda d: wander(d, seed=3), 'smooth random wandering (sums of sinusoids)'),
}


def named(name: str, duration_s: float) -> HeadMotion:
    """A motion of :data:`NAMED` lasting about ``duration_s`` [s] (plus its tail)."""
    if name not in NAMED:
        raise SyntheticMotionError(f'unknown synthetic motion {name!r} '
                                   f'(known: {", ".join(sorted(NAMED))})')
    factory: Callable = NAMED[name][0]
    return factory(_check_positive('duration_s', duration_s))
