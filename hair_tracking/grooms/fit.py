"""An imported groom put on the head: units and up axis (given or guessed), the transform into
the head frame, the fit of the roots onto the scalp and the rest shape kept outside it.

* **Units** (``groom.units: auto``): a head of hair's roots span about :data:`ROOT_SPAN` (0.18 m:
  front hairline to nape, ear to ear); the unit of :data:`~hair_tracking.core.scene_params.
  GROOM_UNITS` that makes the roots' largest bounding-box side closest to it (in ratio) is
  taken.  A file that states its units (a USD stage's ``metersPerUnit``, an NPZ's
  ``meters_per_unit``) is believed.
* **Up axis** (``groom.up_axis: auto``): hair hangs, so the up axis is the one of the six
  (+-x, +-y, +-z) along which the roots lie farthest above the tips, on average over the strands
  in strand lengths; a groom in which none lies above (hair standing up) is taken as z up.  A
  file that states its up axis is believed.
* **Face** (``groom.face_axis: auto``): hair grows on the top, the back and the sides of the
  head and leaves the face bare, so the face looks toward the side the roots leave open: the
  roots' directions from the centre of the sphere through them (an algebraic least-squares
  sphere), across the up axis, averaged, point to the back of the head, and the face is the
  file axis across the up axis nearest their opposite (:func:`guess_face`).  When that mean is
  short (roots all round the head, or too few to tell) the up axis's convention is taken: a
  y-up file faces +z (Maya, Houdini, Cem Yuksel's and USC-HairSalon's models), a z-up file +x,
  an x-up file +y (:data:`FORWARD`: the next axis).  The axes then become REP-103's (x forward,
  y left, z up); ``groom.file_rotation_deg`` turns anything else.
* **Fit** (``groom.fit``): the translation (``translate``), or translation and uniform scale
  (``scale``), that puts the roots on the scalp ellipsoid (``groom.scalp``) in the least-squares
  sense of the normalised radial distance ``|(p - c) / a| - 1`` (Levenberg-Marquardt from the
  roots' crown on top of the ellipsoid; the ellipsoid fit of Gander, Golub & Strebel 1994,
  "Least-squares fitting of circles and ellipses", with the shape held fixed); ``none`` keeps
  the coordinates.  ``groom.file_offset`` is added after the fit.
* **Onto the scalp**: every root is moved along its ray from the ellipsoid's centre onto the
  ellipsoid, and a root outside the scalp cap (``groom.scalp``'s polar limits: on the face, an
  ear or the neck) to the cap's edge at its azimuth (:func:`into_cap`), its strand carried with
  it; every other vertex inside the ellipsoid scaled by
  :data:`~hair_tracking.core.groom.REST_CLEARANCE` is pushed out along its ray, the rule of the
  procedural groom, so no strand starts inside the head and the collider keeps its margin.
"""
import math
from typing import Tuple

from numba import njit
import numpy as np

from hair_tracking.core.groom import in_scalp, polar_limit_deg, REST_CLEARANCE
from hair_tracking.core.scene_params import GROOM_UNITS

#: The span [m] of a head of hair's roots, the yardstick of the units guess.
ROOT_SPAN = 0.18
#: ... and of a whole groom's, when the roots all coincide (a single strand).
GROOM_SPAN = 0.4
#: Units given for a groom are refused when they make its span this many times larger or
#: smaller than :data:`ROOT_SPAN` (a fringe alone passes; mm read as cm, or cm as m, not).
IMPLAUSIBLE_SPAN_FACTOR = 5.0
#: The file axis taken as forward for each up axis: the one after it in x, y, z order (y up
#: faces +z, z up faces +x, x up faces +y), whatever the up axis's sign.
FORWARD = {'x': 1, 'y': 2, 'z': 0}
#: The up axes a groom may have: each axis of the file, either way.
UP_AXES = ('x', '-x', 'y', '-y', 'z', '-z')


def _unit(axis: str) -> np.ndarray:
    """The file axis ``axis`` ('x', '-y', ...) as a unit vector."""
    u = np.zeros(3)
    u['xyz'.index(axis[-1])] = -1.0 if axis.startswith('-') else 1.0
    return u


def convention_face(up: str) -> str:
    """The file axis a groom with up axis ``up`` faces by convention (:data:`FORWARD`)."""
    return 'xyz'[FORWARD[up[-1]]]


def axes(up: str, face: str = '') -> np.ndarray:
    """Head-frame coordinates of a file's x, y, z for up axis ``up`` and face axis ``face``
    (default: :func:`convention_face`), rows: head x = ``face``, head z = ``up``, head y = z
    cross x."""
    u, f = _unit(up), _unit(face or convention_face(up))
    if abs(float(u @ f)) > 0.5:
        raise ValueError(f'face axis {face} lies along the up axis {up}')
    return np.array([f, np.cross(u, f), u])


#: Head-frame coordinates of a file's x, y, z per up axis, facing its convention (rows: head
#: x, y, z).
AXES = {up: axes(up) for up in UP_AXES}
#: How far [deg] the hair may hang from the up axis chosen before the report says to turn it.
OFF_AXIS_DEG = 25.0
#: The up axis is guessed only when the roots lie at least this far (strand lengths, on
#: average) above the tips.
MIN_DROP = 0.05
#: The fit onto the scalp uses at most this many roots (evenly picked in the file's order).
FIT_ROOTS = 2000
#: The face is taken from the roots when their mean direction across the up axis
#: (:func:`guess_face`) is at least this long (0: roots evenly all round the head; the default
#: scalp cap, open on the face, gives 0.23, the tests' synthetic groom 0.27-0.31) ...
MIN_FACE_ASYMMETRY = 0.1
#: ... and said to be clear from this length on.
CLEAR_FACE_ASYMMETRY = 0.2


def _span(roots: np.ndarray, points: np.ndarray) -> Tuple[float, float, str]:
    """``(span [file units], the span it should have [m], words)``: the largest side of the
    roots' bounding box against :data:`ROOT_SPAN`, or the whole groom's against
    :data:`GROOM_SPAN` when the roots coincide."""
    span = float(np.ptp(roots, axis=0).max()) if roots.shape[0] else 0.0
    if span > 0.0:
        return span, ROOT_SPAN, 'the roots span'
    span = float(np.ptp(points, axis=0).max()) if points.shape[0] else 0.0
    return span, GROOM_SPAN, 'the groom spans'


def guess_units(roots: np.ndarray, points: np.ndarray) -> Tuple[str, str]:
    """``(unit, words)``: the unit of GROOM_UNITS whose roots' span is nearest ROOT_SPAN."""
    span, target, what = _span(roots, points)
    if not span > 0.0:
        return 'm', 'm (nothing to measure)'
    name = min(GROOM_UNITS, key=lambda k: abs(math.log(GROOM_UNITS[k] * span / target)))
    return name, (f'{name} (guessed: {what} {span:.4g} units, {span * GROOM_UNITS[name]:.3g} m '
                  f'in {name})')


def units_problem(roots: np.ndarray, points: np.ndarray, unit: float, words: str) -> str:
    """Why ``unit`` [m per file unit] (named ``words``) cannot be a groom's: its roots span
    more than :data:`IMPLAUSIBLE_SPAN_FACTOR` times more or less than a head of hair's
    (:data:`ROOT_SPAN`; a whole groom's, :data:`GROOM_SPAN`, when the roots coincide), naming
    the unit the strands suggest (:func:`guess_units`); '' when it can."""
    span, target, what = _span(roots, points)
    if not span > 0.0 or abs(math.log(span * unit / target)) <= \
            math.log(IMPLAUSIBLE_SPAN_FACTOR):
        return ''
    return (f'with units {words} {what} {span * unit:.3g} m, which no head of hair does; the '
            f'strands suggest {guess_units(roots, points)[1]}')


def guess_up(roots: np.ndarray, tips: np.ndarray, lengths: np.ndarray) -> Tuple[str, str]:
    """``(axis, words)``: of the six axes of :data:`UP_AXES`, the one along which the roots lie
    farthest above the tips (mean of the difference over the strand lengths: hair hangs); z
    when none does by MIN_DROP.  The words say how far the tips hang along it and, when the
    mean hang is more than :data:`OFF_AXIS_DEG` from it (a groom turned by no right angle),
    by how much, so that ``groom.file_rotation_deg`` can turn the rest."""
    hang = np.mean((roots - tips) / np.maximum(lengths, 1e-300)[:, None], axis=0)
    drop = {up: float(AXES[up][2] @ hang) for up in UP_AXES}
    best = max(drop, key=drop.get)
    if drop[best] < MIN_DROP:
        return 'z', ('z (guessed: the roots lie above the tips along no axis by '
                     f'{MIN_DROP} strand lengths; the most is {drop[best]:.2f} along {best})')
    norm = float(np.linalg.norm(hang))
    off = math.degrees(math.acos(min(1.0, drop[best] / norm)))
    words = (f'{best} (guessed: the tips hang {drop[best]:.2f} strand lengths below the roots '
             f'along {best}, the hair {off:.0f} deg from it')
    if off > OFF_AXIS_DEG:
        words += '; turn the rest with groom.file_rotation_deg'
    return best, words + ')'


def sphere_centre(points: np.ndarray) -> np.ndarray:
    """Centre of the sphere through ``points`` (P, 3) in the algebraic least-squares sense
    (``|p|^2 = 2 c . p + k``, linear in ``c`` and ``k``; Gander, Golub & Strebel 1994); the
    points' mean when they do not fix one (fewer than four, or all on a plane)."""
    p = np.asarray(points, dtype=np.float64)
    mean = p.mean(axis=0)
    q = p - mean
    a = np.concatenate([2.0 * q, np.ones((q.shape[0], 1))], axis=1)
    sol, _, rank, _ = np.linalg.lstsq(a, np.einsum('ij,ij->i', q, q), rcond=None)
    return mean + sol[:3] if rank == 4 else mean


def guess_face(roots: np.ndarray, up: str) -> Tuple[str, str, float]:
    """``(axis, words, asymmetry)``: of the four file axes across ``up``, the one the face
    looks toward, from the side of the head the roots leave open (see the module docstring):
    ``asymmetry`` is the length of the roots' mean unit direction from their sphere's centre
    (:func:`sphere_centre`) across the up axis, 0..1; below :data:`MIN_FACE_ASYMMETRY` the
    axis is '' (nothing to tell).  The words say how clear the open side is and, when it is more
    than :data:`OFF_AXIS_DEG` from the axis chosen, by how much."""
    p = np.asarray(roots, dtype=np.float64)
    if p.shape[0] > FIT_ROOTS:
        p = p[np.linspace(0, p.shape[0] - 1, FIT_ROOTS).round().astype(np.int64)]
    u = _unit(up)
    d = p - sphere_centre(p)
    d /= np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-300)
    across = d.mean(axis=0)
    across -= (across @ u) * u
    asym = float(np.linalg.norm(across))
    if asym < MIN_FACE_ASYMMETRY:
        return '', (f'the roots leave no side of the head open (their mean direction across '
                    f'the up axis is {asym:.2f} long, under {MIN_FACE_ASYMMETRY})'), asym
    candidates = [a for a in UP_AXES if a[-1] != up[-1]]
    face = max(candidates, key=lambda a: -float(_unit(a) @ across))
    off = math.degrees(math.acos(min(1.0, -float(_unit(face) @ across) / asym)))
    words = (f'{face} (guessed: the roots leave the scalp open toward {face}, '
             f'{"clearly" if asym >= CLEAR_FACE_ASYMMETRY else "faintly"}: their mean '
             f'direction across the up axis is {asym:.2f} long, {off:.0f} deg from it')
    if off > OFF_AXIS_DEG:
        words += '; turn the rest with groom.file_rotation_deg'
    return face, words + ')', asym


def rotation(degrees) -> np.ndarray:
    """Rotation matrix of turns about x, then y, then z (fixed axes) by ``degrees`` (3,)."""
    ax, ay, az = np.radians(np.asarray(degrees, dtype=np.float64))
    cx, sx, cy, sy, cz, sz = math.cos(ax), math.sin(ax), math.cos(ay), math.sin(ay), \
        math.cos(az), math.sin(az)
    rx = np.array([[1.0, 0.0, 0.0], [0.0, cx, -sx], [0.0, sx, cx]])
    ry = np.array([[cy, 0.0, sy], [0.0, 1.0, 0.0], [-sy, 0.0, cy]])
    rz = np.array([[cz, -sz, 0.0], [sz, cz, 0.0], [0.0, 0.0, 1.0]])
    return rz @ ry @ rx


def fit_to_scalp(roots: np.ndarray, center, radii, scale: bool,
                 iterations: int = 60) -> Tuple[float, np.ndarray, float]:
    """``(s, t, rms)``: the uniform scale (1 unless ``scale``) and translation putting ``roots``
    (S, 3; at most :data:`FIT_ROOTS` of them, evenly picked) on the ellipsoid ``center``,
    ``radii`` in the least-squares sense of ``|(s p + t - c) / a| - 1`` (Levenberg-Marquardt,
    until a step moves less than 1e-10 of the radii), and that RMS at the fit."""
    c = np.asarray(center, dtype=np.float64)
    a = np.asarray(radii, dtype=np.float64)
    p = np.asarray(roots, dtype=np.float64)
    if p.shape[0] > FIT_ROOTS:
        p = p[np.linspace(0, p.shape[0] - 1, FIT_ROOTS).round().astype(np.int64)]
    lo, hi = p.min(axis=0), p.max(axis=0)
    t = np.array([c[0] - 0.5 * (lo[0] + hi[0]), c[1] - 0.5 * (lo[1] + hi[1]),
                  c[2] + a[2] - hi[2]])
    log_s = 0.0

    def residual(t, log_s):
        q = (math.exp(log_s) * p + t - c) / a
        r = np.linalg.norm(q, axis=1)
        return q, np.maximum(r, 1e-12), r - 1.0

    q, r, f = residual(t, log_s)
    cost = float(f @ f)
    lam = 1e-3
    n = 4 if scale else 3
    for _ in range(iterations):
        jac = np.empty((p.shape[0], n))
        jac[:, :3] = q / (a * r[:, None])
        if scale:
            jac[:, 3] = np.einsum('ik,ik->i', q, math.exp(log_s) * p / a) / r
        h = jac.T @ jac
        g = jac.T @ f
        step = np.linalg.solve(h + lam * np.diag(np.diag(h) + 1e-12), -g)
        t_new = t + step[:3]
        s_new = log_s + (step[3] if scale else 0.0)
        q_new, r_new, f_new = residual(t_new, s_new)
        new_cost = float(f_new @ f_new)
        if new_cost < cost:
            t, log_s, q, r, f, cost = t_new, s_new, q_new, r_new, f_new, new_cost
            lam = max(lam * 0.3, 1e-9)
            if np.abs(step[:3]).max() < 1e-10 * a.min() and \
                    (not scale or abs(step[3]) < 1e-10):
                break
        else:
            lam *= 10.0
    return math.exp(log_s), t, math.sqrt(cost / max(1, p.shape[0]))


def onto_ellipsoid(points: np.ndarray, center, radii) -> np.ndarray:
    """``points`` (..., 3) moved along their rays from ``center`` onto the ellipsoid."""
    c = np.asarray(center, dtype=np.float64)
    a = np.asarray(radii, dtype=np.float64)
    rel = (points - c) / a
    r = np.linalg.norm(rel, axis=-1, keepdims=True)
    rel = np.where(r > 1e-12, rel / np.maximum(r, 1e-12), np.array([0.0, 0.0, 1.0]))
    return c + rel * a


def shift_strands(points: np.ndarray, counts: np.ndarray, shift: np.ndarray) -> None:
    """Every strand of ``points`` (P, 3; strands of ``counts`` vertices one after another)
    moved by its row of ``shift`` (S, 3), in place."""
    _shift_kernel(points, np.ascontiguousarray(counts, dtype=np.int64),
                  np.ascontiguousarray(shift, dtype=np.float64))


@njit(cache=True)
def _shift_kernel(p, counts, shift):
    v = 0
    for s in range(counts.shape[0]):
        for _ in range(counts[s]):
            for k in range(3):
                p[v, k] += shift[s, k]
            v += 1


def push_out(points: np.ndarray, center, radii, factor: float = REST_CLEARANCE) -> np.ndarray:
    """``points`` (..., 3, float64; a view is fine) inside the ellipsoid scaled by ``factor``
    moved along their rays from ``center`` onto it, in place; the others as they are.
    Returns ``points``."""
    c = np.asarray(center, dtype=np.float64)
    a = np.asarray(radii, dtype=np.float64) * factor
    _push_out_kernel(points.reshape((1,) * (3 - points.ndim) + points.shape), c, a)
    return points


@njit(cache=True)
def _push_out_kernel(p, c, a):
    """:func:`push_out` of ``p`` (S, N, 3), in place; ``a`` the scaled radii."""
    for s in range(p.shape[0]):
        for i in range(p.shape[1]):
            qx = (p[s, i, 0] - c[0]) / a[0]
            qy = (p[s, i, 1] - c[1]) / a[1]
            qz = (p[s, i, 2] - c[2]) / a[2]
            r2 = qx * qx + qy * qy + qz * qz
            if r2 < 1.0:
                r = max(math.sqrt(r2), 1e-12)
                p[s, i, 0] = c[0] + qx / r * a[0]
                p[s, i, 1] = c[1] + qy / r * a[1]
                p[s, i, 2] = c[2] + qz / r * a[2]


def into_cap(points: np.ndarray, center, radii, scalp) -> np.ndarray:
    """Which of ``points`` (P, 3, on the ellipsoid ``center``, ``radii``) lie outside the scalp
    cap of ``scalp`` (:func:`~hair_tracking.core.groom.in_scalp`); those are moved, in place,
    to the cap's edge at their azimuth, on the ellipsoid.  Returns the mask of the moved."""
    c = np.asarray(center, dtype=np.float64)
    a = np.asarray(radii, dtype=np.float64)
    u = (points - c) / a
    u /= np.maximum(np.linalg.norm(u, axis=1, keepdims=True), 1e-300)
    out = ~in_scalp(u, scalp)
    if out.any():
        v = u[out]
        rho = np.hypot(v[:, 0], v[:, 1])
        cos_phi = np.where(rho > 1e-12, v[:, 0] / np.maximum(rho, 1e-12), 1.0)
        sin_phi = np.where(rho > 1e-12, v[:, 1] / np.maximum(rho, 1e-12), 0.0)
        limit = np.radians(polar_limit_deg(cos_phi, scalp))
        edge = np.stack([np.sin(limit) * cos_phi, np.sin(limit) * sin_phi, np.cos(limit)],
                        axis=1)
        points[out] = c + edge * a
    return out


def head_axes(unit: float, up: str, degrees=(0.0, 0.0, 0.0), face: str = '') -> np.ndarray:
    """The matrix (3, 3) taking file coordinates to the head frame's axes and metres: scaled by
    ``unit`` [m per unit], axes of ``up`` and ``face`` (:func:`axes`), turned by ``degrees``
    (:func:`rotation`)."""
    return rotation(degrees) @ axes(up, face) * unit


def affine(points: np.ndarray, m: np.ndarray, b, in_place: bool = False) -> np.ndarray:
    """``points`` (P, 3) mapped to ``m @ p + b``: a new float64 array, or with ``in_place``
    ``points`` itself where it is a writable contiguous float64 array (one pass, no BLAS
    call)."""
    p = np.ascontiguousarray(points)
    own = in_place and p is points and p.dtype == np.float64 and p.flags.writeable
    out = p if own else np.empty(p.shape)
    _affine_kernel(p, np.ascontiguousarray(m, dtype=np.float64),
                   np.ascontiguousarray(b, dtype=np.float64), out)
    return out


@njit(cache=True)
def _affine_kernel(p, m, b, out):
    for k in range(p.shape[0]):
        x, y, z = float(p[k, 0]), float(p[k, 1]), float(p[k, 2])
        for i in range(3):
            out[k, i] = x * m[i, 0] + y * m[i, 1] + z * m[i, 2] + b[i]
