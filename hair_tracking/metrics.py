"""Figures of merit of strand arrays (numpy; cheap enough to run per published frame).

Stretch is ``max |l / l0 - 1|`` over segments (the metric of research.md, section A); errors of an
approximation against a reference are normalised by strand length, as in the reduced-hair
literature (Chai et al. 2014).
"""
import numpy as np


def segment_lengths(x: np.ndarray) -> np.ndarray:
    """(S, N, 3) -> (S, N-1) segment lengths [m]."""
    d = np.diff(x, axis=1)
    return np.sqrt(np.einsum('snk,snk->sn', d, d))


def max_stretch(x: np.ndarray, rest_length: np.ndarray) -> float:
    """Largest relative length error of any segment (0 means exact)."""
    if x.size == 0:
        return 0.0
    with np.errstate(divide='ignore', invalid='ignore'):
        r = np.abs(segment_lengths(x) / rest_length - 1.0)
    r = r[np.isfinite(r)]
    return float(r.max()) if r.size else 0.0


def kinetic_energy(v: np.ndarray) -> float:
    """Sum of 0.5 |v|^2 per node (unit node mass) [J per kg of node mass]."""
    return 0.5 * float(np.einsum('snk,snk->', v, v))


def position_error(x: np.ndarray, ref: np.ndarray, strand_length: np.ndarray):
    """(rms, max) node distance to the reference divided by each strand's length."""
    d = np.linalg.norm(x - ref, axis=2) / strand_length[:, None]
    return float(np.sqrt(np.mean(d * d))), float(d.max())


def tip_error(x: np.ndarray, ref: np.ndarray, strand_length: np.ndarray) -> float:
    """Mean tip distance to the reference divided by strand length."""
    return float(np.mean(np.linalg.norm(x[:, -1] - ref[:, -1], axis=1) / strand_length))
