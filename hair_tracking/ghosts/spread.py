"""Spread of a ghost group: equations (2) and (3) of Park & Kim (from HairControl, Milliez et al.
2018, "HairControl: A Tracking Solution for Directable Hair Simulation").

The ghosts of one guide form a group; at every node index ``k`` the group's nodes have a centre of
mass ``c`` and a variance (equation (3), a sum, not a mean)::

    V = sum_i || c - d_i ||^2                                                        (3)

HairControl keeps ``V`` near a target ``V_bar`` (the rest variance ``v0`` times
``tracking.spread_target``) with the penalty::

    P = k_v (V - V_bar)^2                                                            (2)

which it minimises in an optimisation the paper calls too costly for real time.  The tracker
(stage (e) of :mod:`hair_tracking.ghosts.kernels`) therefore reduces ``P`` with one closed-form
step per substep instead: scaling the offsets ``d_i - c`` by ``f`` multiplies ``V`` by ``f^2``,
so ``f = sqrt(V_bar / V)`` makes ``P`` zero.  That ratio is clipped to [0.5, 2] (a stable step
when a group collapses or explodes) and blended with ``spread`` in [0, 1], the strength that
plays the role of ``k_v``: ``f = 1 + spread (ratio - 1)`` (:func:`spread_factor`).

The numba functions are inlined into the tracking kernel; :func:`spread_penalty` states equation
(2) for tests and diagnostics.
"""
import math

from numba import njit


@njit(cache=True, inline='always')
def group_variance(P, j, l0, lanes, m):
    """Equation (3): ``sum_i || P[j, :, i] - m ||^2`` over the lanes ``l0 .. l0 + lanes - 1``
    of ``P`` (N, 3, L) (one group's nodes at node index ``j``, [m]) about the centre ``m`` (a
    tuple) [m^2].  ``l0`` and ``lanes`` unsigned (``uint64``) in the kernel, so that the loop
    vectorises."""
    m0, m1, m2 = m
    var = 0.0
    for kk in range(lanes):
        i = l0 + kk
        e0 = P[j, 0, i] - m0
        e1 = P[j, 1, i] - m1
        e2 = P[j, 2, i] - m2
        var += e0 * e0 + e1 * e1 + e2 * e2
    return var


@njit(cache=True, inline='always')
def spread_penalty(var, var_target, k_v):
    """Equation (2): ``k_v (V - V_bar)^2`` for the variance ``var`` of equation (3) and its
    target ``var_target`` [m^2]."""
    e = var - var_target
    return k_v * e * e


@njit(cache=True, inline='always')
def spread_factor(var, var_target, spread):
    """The scale of a group's offsets from its centre of mass that reduces equation (2):
    ``1 + spread (ratio - 1)``, ``ratio = sqrt(var_target / var)`` clipped to [0.5, 2]; 1 for a
    group without spread (``var <= 1e-30`` m^2)."""
    if not var > 1e-30:
        return 1.0
    ratio = math.sqrt(var_target / var)
    if ratio > 2.0:
        ratio = 2.0
    elif ratio < 0.5:
        ratio = 0.5
    return 1.0 + spread * (ratio - 1.0)
