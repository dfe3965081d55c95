"""Groom generation: roots on the scalp and rest shapes of guide and ghost strands (head frame).

Roots lie on an ellipsoid (``scene.groom.scalp``).  The scalp is the cap with polar angle (from +z)
below a limit that shrinks smoothly toward the face: ``theta_max(phi) = max_polar - (max_polar -
front_max_polar) * max(0, cos phi)`` with ``phi`` the azimuth from +x (forward, REP-103).

* Guide roots are spread evenly: a spherical Fibonacci lattice (Gonzalez 2010, "Measurement of
  areas on a sphere using Fibonacci and latitude-longitude lattices") restricted to the cap, evenly
  sub-sampled to the requested count, with a small seeded jitter.
* Ghost roots are uniform random on the cap (seeded), ``guides * ghosts_per_guide`` of them,
  stored in the order of a Morton (Z-order) curve through their positions (:func:`scalp_order`),
  so strands near each other on the scalp are near each other in memory: a ghost tracker that
  reads each strand's nearby guides then finds them in cache (the blend kernel at 100 k strands
  runs about 1.3x faster than on the random order).
* Each strand leaves the scalp along the surface normal (the first segment fixes the root
  direction) and bends toward -z (head frame) by ``droop``; nodes that would fall inside the scalp
  are pushed out radially.  Lengths vary uniformly by ``length_variation``.
"""
from dataclasses import dataclass
from typing import Optional

import numpy as np

from hair_tracking.core.scene import GroomSpec, ScalpSpec

#: Free nodes of a rest shape stay outside the scalp ellipsoid scaled by this factor (about 5 mm
#: out on the default head, more than the collider's margin, so the solver keeps its margin).
REST_CLEARANCE = 1.05


@dataclass
class Groom:
    """The rest shapes of a groom.  ``guide_index``, when given, names the ghost strands that
    are the guides of a tracker that takes its guides among the strands (an imported groom
    chooses them by their shapes, :mod:`hair_tracking.grooms.guides`); ``note`` says where the
    strands came from (an imported groom's report line)."""

    guide_rest: np.ndarray    # (G, Ng, 3) head frame [m]
    ghost_rest: np.ndarray    # (S, Ns, 3) head frame [m]
    guide_index: Optional[np.ndarray] = None
    note: str = ''
    detail_rest: Optional[np.ndarray] = None    # (S, D, 3): ghost_rest at groom.detail_nodes


def make_groom(spec: GroomSpec) -> Groom:
    rng = np.random.default_rng(spec.seed)
    g_dirs = _fibonacci_cap(spec.guides, spec.scalp, rng)
    s_dirs = _random_cap(spec.guides * spec.ghosts_per_guide, spec.scalp, rng)
    g_len = _lengths(spec, spec.guides, rng)
    s_len = _lengths(spec, len(s_dirs), rng)
    ghosts = strand_shapes(s_dirs, s_len, spec.ghost_nodes, spec)
    return Groom(guide_rest=strand_shapes(g_dirs, g_len, spec.guide_nodes, spec),
                 ghost_rest=ghosts[scalp_order(ghosts[:, 0])])


def scalp_order(points: np.ndarray, bits: int = 21) -> np.ndarray:
    """The permutation that sorts ``points`` (S, 3) along a Morton (Z-order) curve: coordinates
    quantised to ``bits`` bits over their bounding box, the bits interleaved x y z, codes sorted
    (stable).  G. M. Morton, "A computer oriented geodetic data base and a new technique in file
    sequencing", IBM, 1966."""
    p = np.asarray(points, dtype=np.float64)
    if p.shape[0] == 0:
        return np.zeros(0, dtype=np.int64)
    lo = p.min(axis=0)
    span = np.maximum(p.max(axis=0) - lo, 1e-300)
    q = np.floor((p - lo) / span * ((1 << bits) - 1)).astype(np.uint64)
    code = np.zeros(p.shape[0], dtype=np.uint64)
    for b in range(bits):
        for axis in range(3):
            bit = (q[:, axis] >> np.uint64(b)) & np.uint64(1)
            code |= bit << np.uint64(3 * b + axis)
    return np.argsort(code, kind='stable')


def _lengths(spec, n, rng):
    return spec.length * (1.0 + spec.length_variation * rng.uniform(-1.0, 1.0, n))


def polar_limit_deg(cos_phi, scalp: ScalpSpec):
    """The scalp cap's edge [deg from the top] at the azimuth whose cosine is ``cos_phi``
    (1: toward the face): ``front_max_polar_deg`` in front, ``max_polar_deg`` at the sides and
    the back."""
    return scalp.max_polar_deg - (scalp.max_polar_deg - scalp.front_max_polar_deg) * \
        np.maximum(0.0, cos_phi)


def in_scalp(u: np.ndarray, scalp: ScalpSpec) -> np.ndarray:
    """Which unit directions ``u`` (..., 3) fall on the scalp cap."""
    polar = np.degrees(np.arccos(np.clip(u[..., 2], -1.0, 1.0)))
    cos_phi = u[..., 0] / np.maximum(np.hypot(u[..., 0], u[..., 1]), 1e-12)
    return polar <= polar_limit_deg(cos_phi, scalp)


def _fibonacci(m: int) -> np.ndarray:
    i = np.arange(m) + 0.5
    z = 1.0 - 2.0 * i / m
    r = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    phi = np.pi * (3.0 - np.sqrt(5.0)) * i
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def _fibonacci_cap(n: int, scalp: ScalpSpec, rng) -> np.ndarray:
    m = max(n, 16)
    while True:
        pts = _fibonacci(m)
        pts = pts[in_scalp(pts, scalp)]
        if len(pts) >= n:
            break
        m = int(m * 1.25) + 8
    pts = pts[np.linspace(0, len(pts) - 1, n).round().astype(int)]
    jitter = rng.normal(scale=0.15 * np.sqrt(4.0 / m), size=pts.shape)
    moved = pts + jitter
    moved /= np.linalg.norm(moved, axis=1, keepdims=True)
    keep = in_scalp(moved, scalp)
    pts[keep] = moved[keep]
    return pts


def _random_cap(n: int, scalp: ScalpSpec, rng) -> np.ndarray:
    out = np.empty((0, 3))
    while len(out) < n:
        v = rng.normal(size=(max(2 * (n - len(out)), 64), 3))
        v /= np.linalg.norm(v, axis=1, keepdims=True)
        out = np.concatenate([out, v[in_scalp(v, scalp)]])
    return out[:n]


def strand_shapes(dirs: np.ndarray, lengths: np.ndarray, nodes: int,
                  spec: GroomSpec) -> np.ndarray:
    """Rest shapes (S, nodes, 3) of strands rooted at scalp directions ``dirs`` (S, 3)."""
    radii = np.asarray(spec.scalp.radii)
    center = np.asarray(spec.scalp.center)
    roots = center + dirs * radii
    normals = dirs / radii
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    seg = (lengths / (nodes - 1))[:, None]
    down = np.array([0.0, 0.0, -1.0])
    shape = np.empty((len(dirs), nodes, 3))
    shape[:, 0] = roots
    shape[:, 1] = roots + normals * seg
    for k in range(2, nodes):
        w = spec.droop * min(1.0, (k - 1) / max(1.0, 0.25 * (nodes - 1)))
        d = (1.0 - w) * normals + w * down
        norm = np.linalg.norm(d, axis=1, keepdims=True)
        d = np.where(norm > 1e-9, d / np.maximum(norm, 1e-12), normals)
        p = shape[:, k - 1] + d * seg
        # keep the rest shape outside the scalp ellipsoid (pushed out radially, then the
        # segment is rescaled to its length so rest lengths stay exact)
        rel = (p - center) / radii
        r = np.linalg.norm(rel, axis=1)
        inside = r < REST_CLEARANCE
        if np.any(inside):
            p[inside] = center + rel[inside] / r[inside, None] * REST_CLEARANCE * radii
            step = p - shape[:, k - 1]
            step /= np.maximum(np.linalg.norm(step, axis=1, keepdims=True), 1e-12)
            p = shape[:, k - 1] + step * seg
        shape[:, k] = p
    return shape
