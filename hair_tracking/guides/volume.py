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
from numba import njit, prange

from hair_tracking.core.kernels import FASTMATH, parallel_and_serial

#: Most cells a grid may have (its density and velocity then take 128 MB, one more such grid
#: for each further lane of the splat (:data:`LANES`), the rest density and each lane's list of
#: the cells a run touches at most 32 MB each).
MAX_CELLS = 4_000_000
#: Parts the strands are split into for the splat, each added into its own grid (on its own
#: thread in the parallel variant, :func:`splat`): the sums are the same on any thread count.
LANES = 2
#: [s] how often the stage runs: every substep when they are at least this long, else every
#: ``round(PERIOD_S / dt)`` substeps, whichever way the solver is called (a pose's substeps at
#: 60 Hz poses and dt 1/240 s: once a pose).
PERIOD_S = 1.0 / 60.0


class VolumeGrid:
    """The volume stage of strands with rest shape ``rest`` (S, N, 3, head frame [m]) and
    inverse masses ``inv_mass`` (S, N), for a :class:`~hair_tracking.core.scene.VolumeSpec`
    ``spec``.  The cell is ``spec.cell_size``, or larger where the grid would have more than
    :data:`MAX_CELLS` cells (:attr:`h`: the cell in use).  ``parallel``: the splat's lanes and
    the nodes' reads run on every thread (the guide solver's choice of kernel variants)."""

    def __init__(self, rest: np.ndarray, inv_mass: np.ndarray, spec, parallel: bool = False):
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
        #: the cells a run gave weight to (:func:`splat`, each lane's; at most 27 a node),
        #: and their counts
        self.touched = np.empty((LANES, min(n ** 3, 27 * rest.shape[0] * rest.shape[1])),
                                dtype=np.int64)
        self.counts = np.zeros(LANES, dtype=np.int64)
        #: density and weighted velocity of the present run (cleared where touched), and a
        #: grid for each further lane of the splat
        self.grids = np.zeros((LANES, n, n, n, 4))
        self.grid = self.grids[0]
        self._splat, self._interact = (splat, interact) if parallel else \
            (splat_serial, interact_serial)
        self._splat(rest, np.zeros_like(rest), self.inv_mass,
                    self._to_grid(np.eye(3), np.zeros(3)), self.grids, self.cell, self.wts,
                    self.touched, self.counts)
        self.rest_density[...] = self.grid[..., 0]
        self.grid[...] = 0.0
        occupied = self.rest_density[self.rest_density > 0.0]
        self.rest_ref = float(occupied.mean()) if occupied.size else 1.0

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
        self._splat(x, v, self.inv_mass, self._to_grid(rot, pos), self.grids, self.cell,
                    self.wts, self.touched, self.counts)
        touched = self.touched[0, :self.counts[0]]
        settle(self.grid, self.rest_density, touched)
        push = self.pressure * dt / self.rest_ref
        smooth = 1.0 - math.exp(-self.friction * dt)
        self._interact(v, rot, self.grid, self.cell, self.wts, (push, smooth))
        clear(self.grid, touched)

    def _to_grid(self, rot: np.ndarray, pos: np.ndarray) -> np.ndarray:
        """(3, 4): a world point's grid coordinates [cells] for the head at ``rot``, ``pos``
        (``[R^T / h | -(R^T pos + origin) / h]``)."""
        out = np.empty((3, 4))
        out[:, :3] = rot.T / self.h
        out[:, 3] = -(rot.T @ pos + self.origin) / self.h
        return out


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


def _splat(x, v, inv_mass, to_grid, grids, cell, wts, touched, counts):
    """Add every free node's weights (``grids[0, ..., 0]``, quadratic B-splines over the
    3 x 3 x 3 cells around ``to_grid`` (3, 4) times its position) and weighted velocity
    (``grids[0, ..., 1:]``, world frame) to the grid ``grids[0]`` (n, n, n, 4); a node's first
    cell (flat index; -1: not splatted) into ``cell`` (S, N) and its weights and their
    derivatives (x, y, z; then the same derivatives) into ``wts`` (S, N, 18), for
    :func:`interact`; the cells given weight, each once, into ``touched[0]``, their count
    into ``counts[0]``.

    The strands are split into :data:`LANES` parts, each added into its own grid
    (``grids[l]``, ``touched[l]``; on its own thread in the parallel variant), each later part
    then into the first (and cleared): every cell's sum is the same on any thread count."""
    n = grids.shape[1]
    strands = x.shape[0]
    for lane in prange(LANES):
        flat = grids[lane].reshape(-1)
        count = 0
        for s in range(lane * strands // LANES, (lane + 1) * strands // LANES):
            for i in range(x.shape[1]):
                cell[s, i] = -1
                if not inv_mass[s, i] > 0.0:
                    continue
                px, py, pz = x[s, i, 0], x[s, i, 1], x[s, i, 2]
                ux = to_grid[0, 0] * px + to_grid[0, 1] * py + to_grid[0, 2] * pz + \
                    to_grid[0, 3]
                uy = to_grid[1, 0] * px + to_grid[1, 1] * py + to_grid[1, 2] * pz + \
                    to_grid[1, 3]
                uz = to_grid[2, 0] * px + to_grid[2, 1] * py + to_grid[2, 2] * pz + \
                    to_grid[2, 3]
                if not (1.0 <= ux < n - 2 and 1.0 <= uy < n - 2 and 1.0 <= uz < n - 2):
                    continue
                w = wts[s, i]
                first = (_weights(ux, w, 0) * n + _weights(uy, w, 3)) * n + _weights(uz, w, 6)
                cell[s, i] = first
                vx, vy, vz = v[s, i, 0], v[s, i, 1], v[s, i, 2]
                for a in range(3):
                    for b in range(3):
                        wab = w[a] * w[3 + b]
                        row = first + (a * n + b) * n
                        for d in range(3):
                            m = wab * w[6 + d]
                            at = 4 * (row + d)
                            if flat[at] == 0.0 and m > 0.0:
                                touched[lane, count] = row + d
                                count += 1
                            flat[at] += m
                            flat[at + 1] += m * vx
                            flat[at + 2] += m * vy
                            flat[at + 3] += m * vz
        counts[lane] = count
    into = grids[0].reshape(-1)
    for lane in range(1, LANES):
        flat = grids[lane].reshape(-1)
        for j in range(counts[lane]):
            at = 4 * touched[lane, j]
            if into[at] == 0.0:
                touched[0, counts[0]] = touched[lane, j]
                counts[0] += 1
            for k in range(4):
                into[at + k] += flat[at + k]
                flat[at + k] = 0.0


splat, splat_serial = parallel_and_serial(_splat, fastmath=FASTMATH, error_model='numpy')


@njit(cache=True, fastmath=FASTMATH, error_model='numpy')
def settle(grid, rest, touched):
    """Each touched cell's sums into what :func:`interact` reads: ``grid[..., 0]`` the density
    above the rest density ``rest`` (n, n, n), ``max(rho - rho0, 0)``, and
    ``grid[..., 1:]`` the cell's velocity (its weighted velocity over its weight)."""
    flat = grid.reshape(-1)
    dens = rest.reshape(-1)
    for j in range(touched.shape[0]):
        c = touched[j]
        m = flat[4 * c]
        flat[4 * c] = max(m - dens[c], 0.0)
        for k in range(1, 4):
            flat[4 * c + k] /= m


def _interact(v, rot, grid, cell, wts, gains):
    """Steps 2 and 3 of the module docstring for every node :func:`splat` splatted, from the
    grid :func:`settle` made; ``gains = (pressure dt / rho_ref, 1 - exp(-friction dt))``.  Every
    cell a node weights above zero it gave weight to itself (so the cell was settled), and its
    27 weights sum to 1 (the B-splines' partition of unity), so the grid's velocity at it is
    the weighted sum."""
    push, smooth = gains
    n = grid.shape[0]
    flat = grid.reshape(-1)
    for s in prange(cell.shape[0]):
        for i in range(cell.shape[1]):
            first = cell[s, i]
            if first < 0:
                continue
            w = wts[s, i]
            gx = gy = gz = 0.0                     # grad e per cell, head frame
            vx = vy = vz = 0.0                     # the grid's velocity at the node
            for a in range(3):
                for b in range(3):
                    at = 4 * (first + (a * n + b) * n)
                    # the row of three cells along z, summed with the z weights
                    e, ez = 0.0, 0.0
                    rx = ry = rz = 0.0
                    for d in range(3):
                        c, dc = w[6 + d], w[15 + d]
                        e += c * flat[at]
                        ez += dc * flat[at]
                        rx += c * flat[at + 1]
                        ry += c * flat[at + 2]
                        rz += c * flat[at + 3]
                        at += 4
                    wab = w[a] * w[3 + b]
                    gx += w[9 + a] * w[3 + b] * e
                    gy += w[a] * w[12 + b] * e
                    gz += wab * ez
                    vx += wab * rx
                    vy += wab * ry
                    vz += wab * rz
            # the pull toward the grid's velocity, and the push turned into the world frame
            v[s, i, 0] += smooth * (vx - v[s, i, 0]) - push * (
                rot[0, 0] * gx + rot[0, 1] * gy + rot[0, 2] * gz)
            v[s, i, 1] += smooth * (vy - v[s, i, 1]) - push * (
                rot[1, 0] * gx + rot[1, 1] * gy + rot[1, 2] * gz)
            v[s, i, 2] += smooth * (vz - v[s, i, 2]) - push * (
                rot[2, 0] * gx + rot[2, 1] * gy + rot[2, 2] * gz)


interact, interact_serial = parallel_and_serial(_interact, fastmath=FASTMATH,
                                                error_model='numpy')


@njit(cache=True, fastmath=FASTMATH, error_model='numpy')
def clear(grid, touched):
    """Zero the cells ``touched`` of ``grid`` (n, n, n, 4), for the next run."""
    flat = grid.reshape(-1)
    for j in range(touched.shape[0]):
        for k in range(4):
            flat[4 * touched[j] + k] = 0.0
