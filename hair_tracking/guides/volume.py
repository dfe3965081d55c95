"""Hair volume: the guides push each other apart and move together through a grid on the head.

Each strand is simulated alone; this stage is what strands do to one another, through a grid
fixed to the head (Petrovic, Henne & Anderson 2005, "Volumetric methods for simulation and
rendering of hair", Pixar: hair-hair friction as velocity smoothing on a grid, and a push out of
over-dense cells; the grid velocity and density force of Jolt's hair, the target density from
the groom's rest pose of Unity's hair).  Every :data:`PERIOD_S` of substeps of the guide
solver (:class:`~hair_tracking.guides.solver.GuideSolver`), over that time ``dt``, for the free
nodes:

1. every node is splatted into the grid with quadratic B-spline weights over 3 x 3 x 3 cells
   (smooth, so the push does not jump at cell faces): its weight (the density, in nodes a
   cell) and its weighted velocity;
2. a node's velocity gains ``dt`` times the push ``-pressure grad e`` (per cell), with ``e =
   max(rho - rho0, 0) / rho_ref`` the density above the rest pose's (``rho0``: the guides' rest
   shape splatted the same way, so a styled groom keeps its own volume; ``rho_ref`` the mean
   rest density of the cells the rest pose occupies): hair lying on hair is held up as a
   pressure holds it, against gravity;
3. and moves toward the grid's velocity there by ``1 - exp(-friction dt)``, which keeps their
   sum (momentum) and damps the strands' motion against each other.

The stage changes velocities only: the next substep's prediction moves the nodes and the
solver's pass puts the lengths back (exactly, under FTL); running every few substeps, it leaves
the solver's compiled runs of those substeps as they are. The grid is a cube around the head
(side twice the hair's reach: root distance plus strand length, and cells of padding), so its
memory is set by the groom and ``volume.cell_size`` and does not grow with any motion; a node
outside it is left alone. Only the cells the nodes touch are cleared after a run.
"""
import math

import numpy as np
from numba import njit

from hair_tracking.core.kernels import FASTMATH

#: Most cells a grid may have (its density and velocity then take 128 MB, the rest density
#: 32 MB).
MAX_CELLS = 4_000_000
#: [s] how often the stage runs: every substep when they are at least this long, else every
#: ``round(PERIOD_S / dt)`` substeps, whichever way the solver is called (a pose's substeps at
#: 60 Hz poses and dt 1/240 s: once a pose).
PERIOD_S = 1.0 / 60.0


class VolumeGrid:
    """The volume stage of strands with rest shape ``rest`` (S, N, 3, head frame [m]) and
    inverse masses ``inv_mass`` (S, N), for a :class:`~hair_tracking.core.scene.VolumeSpec`
    ``spec``.  The cell is ``spec.cell_size``, or larger where the grid would have more than
    :data:`MAX_CELLS` cells (:attr:`h`: the cell in use)."""

    def __init__(self, rest: np.ndarray, inv_mass: np.ndarray, spec):
        rest = np.ascontiguousarray(rest, dtype=np.float64)
        seg = np.linalg.norm(np.diff(rest, axis=1), axis=2).sum(axis=1)
        reach = float((np.linalg.norm(rest[:, 0], axis=1) + seg).max())
        # two cells of padding each side: a node's B-spline covers its cell's neighbours
        h = max(float(spec.cell_size), 2.0 * reach / (MAX_CELLS ** (1.0 / 3.0) - 6.0))
        n = int(math.ceil(2.0 * reach / h)) + 5
        self.h = h
        self.pressure = float(spec.pressure)
        self.friction = float(spec.friction)
        self.origin = np.full(3, -reach - 2.0 * h)
        self.inv_mass = np.ascontiguousarray(inv_mass, dtype=np.float64)
        self.rest_density = np.zeros((n, n, n))
        #: each node's first cell and B-spline weights (:func:`splat`)
        self.cell = np.empty(rest.shape[:2], dtype=np.int64)
        self.wts = np.empty(rest.shape[:2] + (18,))
        scratch = np.zeros((n, n, n, 4))
        splat(rest, np.zeros_like(rest), self.inv_mass, np.eye(3), np.zeros(3), self.origin,
              h, scratch, self.cell, self.wts)
        self.rest_density[...] = scratch[..., 0]
        occupied = self.rest_density[self.rest_density > 0.0]
        self.rest_ref = float(occupied.mean()) if occupied.size else 1.0
        #: density and weighted velocity of the present run (cleared where touched)
        self.grid = np.zeros((n, n, n, 4))

    @staticmethod
    def period(dt: float) -> int:
        """Substeps ``dt`` [s] between two runs of the stage (:data:`PERIOD_S`)."""
        return max(1, int(round(PERIOD_S / dt)))

    @property
    def cells(self) -> int:
        """Cells of the grid."""
        return self.rest_density.size

    def apply(self, x: np.ndarray, v: np.ndarray, rot: np.ndarray, pos: np.ndarray,
              dt: float) -> None:
        """The stage over the time ``dt`` [s] since it last ran, for the strands at ``x`` with
        velocities ``v`` (world frame, changed in place), the head at ``rot``, ``pos``."""
        splat(x, v, self.inv_mass, rot, pos, self.origin, self.h, self.grid, self.cell,
              self.wts)
        push = self.pressure * dt / self.rest_ref
        smooth = 1.0 - math.exp(-self.friction * dt)
        interact(v, rot, self.grid, self.rest_density, self.cell, self.wts, (push, smooth))


@njit(cache=True, inline='always', fastmath=FASTMATH, error_model='numpy')
def _weights(u, out, at):
    """The quadratic B-spline weights of the three cells from ``int(u - 0.5)`` at ``u`` (in
    cells) and their derivatives into ``out[at:at + 3]`` and ``out[at + 9:at + 12]``; returns
    that first cell."""
    c = int(u - 0.5)
    f = u - c
    out[at] = 0.5 * (1.5 - f) ** 2
    out[at + 1] = 0.75 - (f - 1.0) ** 2
    out[at + 2] = 0.5 * (f - 0.5) ** 2
    out[at + 9] = f - 1.5
    out[at + 10] = -2.0 * (f - 1.0)
    out[at + 11] = f - 0.5
    return c


@njit(cache=True, fastmath=FASTMATH, error_model='numpy')
def splat(x, v, inv_mass, rot, pos, origin, h, grid, cell, wts):
    """Add every free node's weights (``grid[..., 0]``, quadratic B-splines over its 3 x 3 x 3
    cells) and weighted velocity (``grid[..., 1:]``, world frame) to ``grid`` (n, n, n, 4); a
    node's first cell (flat index; -1: not splatted) into ``cell`` (S, N) and its weights and
    their derivatives (x, y, z; then the same derivatives) into ``wts`` (S, N, 18), for
    :func:`interact`."""
    n = grid.shape[0]
    flat = grid.reshape(-1)
    for s in range(x.shape[0]):
        for i in range(x.shape[1]):
            cell[s, i] = -1
            if not inv_mass[s, i] > 0.0:
                continue
            dx, dy, dz = x[s, i, 0] - pos[0], x[s, i, 1] - pos[1], x[s, i, 2] - pos[2]
            ux = ((rot[0, 0] * dx + rot[1, 0] * dy + rot[2, 0] * dz) - origin[0]) / h
            uy = ((rot[0, 1] * dx + rot[1, 1] * dy + rot[2, 1] * dz) - origin[1]) / h
            uz = ((rot[0, 2] * dx + rot[1, 2] * dy + rot[2, 2] * dz) - origin[2]) / h
            if not (1.0 <= ux < n - 2 and 1.0 <= uy < n - 2 and 1.0 <= uz < n - 2):
                continue
            w = wts[s, i]
            i0 = _weights(ux, w, 0)
            j0 = _weights(uy, w, 3)
            k0 = _weights(uz, w, 6)
            first = (i0 * n + j0) * n + k0
            cell[s, i] = first
            vx, vy, vz = v[s, i, 0], v[s, i, 1], v[s, i, 2]
            for a in range(3):
                for b in range(3):
                    wab = w[a] * w[3 + b]
                    row = 4 * (first + (a * n + b) * n)
                    for d in range(3):
                        m = wab * w[6 + d]
                        at = row + 4 * d
                        flat[at] += m
                        flat[at + 1] += m * vx
                        flat[at + 2] += m * vy
                        flat[at + 3] += m * vz


@njit(cache=True, fastmath=FASTMATH, error_model='numpy')
def interact(v, rot, grid, rest, cell, wts, gains):
    """Steps 2 and 3 of the module docstring for every node :func:`splat` splatted, then the
    cells it touched cleared; ``gains = (pressure dt / rho_ref, 1 - exp(-friction dt))``."""
    push, smooth = gains
    n = grid.shape[0]
    flat = grid.reshape(-1)
    dens = rest.reshape(-1)
    for s in range(cell.shape[0]):
        for i in range(cell.shape[1]):
            first = cell[s, i]
            if first < 0:
                continue
            w = wts[s, i]
            gx = gy = gz = 0.0                     # grad e per cell, head frame
            vx = vy = vz = wsum = 0.0              # the grid's velocity at the node
            for a in range(3):
                for b in range(3):
                    row = first + (a * n + b) * n
                    for d in range(3):
                        at = row + d
                        m = flat[4 * at]
                        e = max(m - dens[at], 0.0)
                        gx += w[9 + a] * w[3 + b] * w[6 + d] * e
                        gy += w[a] * w[12 + b] * w[6 + d] * e
                        gz += w[a] * w[3 + b] * w[15 + d] * e
                        if m > 0.0:
                            c = w[a] * w[3 + b] * w[6 + d]
                            wsum += c
                            c /= m
                            vx += c * flat[4 * at + 1]
                            vy += c * flat[4 * at + 2]
                            vz += c * flat[4 * at + 3]
            if wsum > 0.0:
                vx, vy, vz = vx / wsum, vy / wsum, vz / wsum
            else:
                vx, vy, vz = v[s, i, 0], v[s, i, 1], v[s, i, 2]
            # the pull toward the grid's velocity, and the push turned into the world frame
            v[s, i, 0] += smooth * (vx - v[s, i, 0]) - push * (
                rot[0, 0] * gx + rot[0, 1] * gy + rot[0, 2] * gz)
            v[s, i, 1] += smooth * (vy - v[s, i, 1]) - push * (
                rot[1, 0] * gx + rot[1, 1] * gy + rot[1, 2] * gz)
            v[s, i, 2] += smooth * (vz - v[s, i, 2]) - push * (
                rot[2, 0] * gx + rot[2, 1] * gy + rot[2, 2] * gz)
    for s in range(cell.shape[0]):
        for i in range(cell.shape[1]):
            first = cell[s, i]
            if first < 0:
                continue
            for a in range(3):
                for b in range(3):
                    row = 4 * (first + (a * n + b) * n)
                    for k in range(12):
                        flat[row + k] = 0.0
