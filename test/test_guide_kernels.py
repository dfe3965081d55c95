"""The guide-strand numba kernels agree with plain-numpy references on random inputs.

The references (:mod:`hair_tracking.guides.reference`) are written independently of the
kernels' loop structure: vectorised over strands, Gauss–Seidel along the strand, masses used
directly (not through ``pair_weights``).
Kernels use fused multiply-add (``core.kernels.FASTMATH``), so agreement is to ~1e-12, not bitwise.
"""
import numba
import numpy as np
import pytest

from hair_tracking.guides import ftl

from hair_tracking.guides import integrate

from hair_tracking.guides import pbd_constraints

from hair_tracking.core.transforms import quat_normalize, quat_to_matrix
from hair_tracking.guides import reference
from hair_tracking.guides.reference import (ftl_pass as ref_ftl_pass,
                                            guide_finalize as ref_finalize,
                                            guide_predict as ref_predict,
                                            jacobi_bend as ref_jacobi_bend,
                                            pbd_sweep as ref_pbd_sweep,
                                            xpbd_sweep as ref_xpbd_sweep)

ATOL = 1e-12


# ------------------------------------------------------------------------------ fixtures
def random_case(seed, s=13, n=7, all_free=False):
    """Random strands (S not a multiple of BLOCK), head motion, state, masses."""
    rng = np.random.default_rng(seed)
    rest = np.cumsum(rng.normal(size=(s, n, 3)) * 0.02, axis=1) + rng.normal(size=(s, 1, 3)) * 0.1
    rest[0, 4] = rest[0, 3]                      # one zero-length rest segment
    rest_length = np.linalg.norm(np.diff(rest, axis=1), axis=2)
    inv_mass = rng.uniform(0.5, 2.0, size=(s, n))
    if not all_free:
        inv_mass[rng.random((s, n)) < 0.15] = 0.0
    inv_mass[:, :2] = 0.0
    q_prev = quat_normalize(rng.normal(size=4))
    q = quat_normalize(q_prev + rng.normal(size=4) * 0.1)
    rot_prev, rot = quat_to_matrix(q_prev), quat_to_matrix(q)
    pos_prev, pos = rng.normal(size=3) * 0.1, rng.normal(size=3) * 0.1
    x = (rest @ rot_prev.T + pos_prev) + rng.normal(size=(s, n, 3)) * 0.01
    v = rng.normal(size=(s, n, 3)) * 0.5
    return dict(rest=rest, rest_length=rest_length, inv_mass=inv_mass, rot=rot, pos=pos,
                rot_prev=rot_prev, pos_prev=pos_prev, x=x, v=v,
                gravity=np.array([0.3, -1.0, -9.81]),
                damping=2.0, dt=1.0 / 240.0, shock=0.6, shape=300.0)


def pbd_lane_data(inv_mass, rest_length, bend_rest):
    """The lane-layout arguments of pbd_step after inv_mass: rest lengths, bending rest
    distances, both pair weights, work space."""
    lanes = pbd_constraints.lane_major
    return (lanes(rest_length), lanes(bend_rest), lanes(pbd_constraints.pair_weights(inv_mass, 1)),
            lanes(pbd_constraints.pair_weights(inv_mass, 2)),
            pbd_constraints.lane_work(*inv_mass.shape))


def kernel_common(c):
    """The :data:`integrate.StepMotion` of a random case."""
    rot_rel = integrate.relative_rotation(c['rot_prev'], c['rot'])
    return tuple(integrate.StepMotion(c['rot'], c['pos'], rot_rel, c['pos_prev'], c['gravity'],
                                      float(np.exp(-c['damping'] * c['dt'])), c['dt'],
                                      c['shock'], c['shape']))


def run_pbd_step(x, v, x_old, rest, inv_mass, rest_length, bend_rest, c, iterations, k, kb,
                 max_disp, finalize):
    """:func:`pbd_constraints.pbd_step` with its arguments built from plain arrays."""
    rl, br, sw, bw, work = pbd_lane_data(inv_mass, rest_length, bend_rest)
    return pbd_constraints.pbd_step(
        tuple(pbd_constraints.PbdModel(rest, inv_mass, rl, br, sw, bw)),
        tuple(integrate.GuideState(x, v, x_old)), kernel_common(c),
        tuple(pbd_constraints.PbdParams(iterations, k, kb, max_disp, finalize)), work)


def run_xpbd_step(x, v, x_old, rest, im, rest_length, bend_rest, lam_s, lam_b, c, iterations,
                  a_s, a_b, max_disp, finalize):
    """:func:`pbd_constraints.xpbd_step` with its arguments built from plain arrays (``lam_*``
    in lane-major layout)."""
    lanes = pbd_constraints.lane_major
    model = pbd_constraints.XpbdModel(
        rest, im, lanes(im), lanes(rest_length), lanes(bend_rest),
        lanes(pbd_constraints.xpbd_gain(im, 1, a_s)), lanes(pbd_constraints.xpbd_gain(im, 2, a_b)))
    work = pbd_constraints.XpbdWork(pbd_constraints.lane_work(*im.shape), lam_s, lam_b)
    return pbd_constraints.xpbd_step(
        tuple(model), tuple(integrate.GuideState(x, v, x_old)), kernel_common(c),
        tuple(pbd_constraints.XpbdParams(iterations, a_s, a_b, max_disp, finalize)),
        tuple(work))


def run_ftl_step(x, v, x_old, corr, rest, im, rest_length, bend_rest, c, passes, kb, s_damp,
                 max_disp, finalize):
    """:func:`ftl.ftl_step` with its arguments built from plain arrays."""
    return ftl.ftl_step(
        tuple(ftl.FtlModel(rest, im, rest_length, bend_rest,
                           pbd_constraints.pair_weights(im, 2))),
        tuple(integrate.GuideState(x, v, x_old)), kernel_common(c),
        tuple(ftl.FtlParams(passes, kb, s_damp, max_disp, finalize)), corr)


def reference_predict(c):
    return ref_predict(c['x'], c['v'], c['rest'], c['inv_mass'], c['rot'], c['pos'],
                       c['rot_prev'], c['pos_prev'], c['gravity'], c['damping'], c['dt'],
                       c['shock'], c['shape'])


# --------------------------------------------------------------------------------- tests
def test_relative_rotation_moves_head_points_rigidly():
    c = random_case(0)
    rot_rel = integrate.relative_rotation(c['rot_prev'], c['rot'])
    p_head = np.array([0.03, -0.02, 0.1])
    before = c['rot_prev'] @ p_head + c['pos_prev']
    after = c['rot'] @ p_head + c['pos']
    assert np.allclose(rot_rel @ (before - c['pos_prev']) + c['pos'], after, atol=1e-14)


def test_head_motion_kernel_matches_numpy_and_flags_non_finite():
    c = random_case(9)
    out = np.empty((3, 3))
    args = [c['rot_prev'], c['pos_prev'], c['rot'], c['pos']]
    assert integrate.head_motion(*args, out)
    assert np.allclose(out, c['rot'] @ c['rot_prev'].T, rtol=0, atol=1e-15)
    for k, idx in ((0, (1, 2)), (1, (0,)), (2, (2, 0)), (3, (2,))):
        bad = [a.copy() for a in args]
        bad[k][idx] = np.inf if k % 2 else np.nan
        assert not integrate.head_motion(*bad, out)


@pytest.mark.parametrize('finalize', [True, False])
@pytest.mark.parametrize('seed', [1, 2])
def test_pbd_step_matches_reference(seed, finalize):
    c = random_case(seed)
    bend_rest = pbd_constraints.second_neighbour_rest(c['rest'])
    iterations, k, kb, max_disp = 3, 0.9, 0.4, 0.02
    p, xc, vn = reference_predict(c)
    for _ in range(iterations):
        ref_pbd_sweep(p, c['rest_length'], c['inv_mass'], 1, k)
        ref_pbd_sweep(p, bend_rest, c['inv_mass'], 2, kb)
    x, v, x_old = c['x'].copy(), c['v'].copy(), np.zeros_like(c['x'])
    clamped = run_pbd_step(x, v, x_old, c['rest'], c['inv_mass'], c['rest_length'], bend_rest,
                           c, iterations, k, kb, max_disp, finalize)
    assert np.allclose(x_old, xc, rtol=0, atol=ATOL)
    if finalize:
        p_ref, v_ref, clamped_ref = ref_finalize(p, xc, c['inv_mass'], None, c['dt'], max_disp,
                                                 0.0)
        assert clamped_ref > 0 and clamped == clamped_ref
        assert np.allclose(x, p_ref, rtol=0, atol=ATOL)
        assert np.allclose(v, v_ref, rtol=0, atol=1e-9)
    else:
        assert clamped == 0
        assert np.allclose(x, p, rtol=0, atol=ATOL)
        assert np.array_equal(v, c['v'])             # predict reads v, finalize writes it


@pytest.mark.parametrize('finalize', [True, False])
def test_xpbd_step_matches_reference(finalize):
    c = random_case(3)
    bend_rest = pbd_constraints.second_neighbour_rest(c['rest'])
    iterations, max_disp = 4, 0.0
    a_s, a_b = 1e-6 / c['dt'] ** 2, 1e-3 / c['dt'] ** 2
    p, xc, vn = reference_predict(c)
    lam_s = np.zeros(c['rest_length'].shape)
    lam_b = np.zeros(bend_rest.shape)
    for _ in range(iterations):
        ref_xpbd_sweep(p, c['rest_length'], c['inv_mass'], lam_s, 1, a_s)
        ref_xpbd_sweep(p, bend_rest, c['inv_mass'], lam_b, 2, a_b)
    x, v, x_old = c['x'].copy(), c['v'].copy(), np.zeros_like(c['x'])
    lanes = pbd_constraints.lane_major
    k_lam_s = lanes(np.full(lam_s.shape, 123.0))    # the kernel must reset the multipliers
    k_lam_b = lanes(np.full(lam_b.shape, -7.0))
    im = c['inv_mass']
    clamped = run_xpbd_step(x, v, x_old, c['rest'], im, c['rest_length'], bend_rest, k_lam_s,
                            k_lam_b, c, iterations, a_s, a_b, max_disp, finalize)
    assert clamped == 0
    assert np.allclose(pbd_constraints.from_lane_major(k_lam_s, lam_s.shape), lam_s,
                       rtol=1e-9, atol=1e-9)
    assert np.allclose(pbd_constraints.from_lane_major(k_lam_b, lam_b.shape), lam_b,
                       rtol=1e-9, atol=1e-9)
    if finalize:
        p_ref, v_ref, _ = ref_finalize(p, xc, c['inv_mass'], None, c['dt'], max_disp, 0.0)
        assert np.allclose(x, p_ref, rtol=0, atol=ATOL)
        assert np.allclose(v, v_ref, rtol=0, atol=1e-9)
    else:
        assert np.allclose(x, p, rtol=0, atol=ATOL)


@pytest.mark.parametrize('finalize', [True, False])
def test_ftl_step_matches_reference(finalize):
    c = random_case(4, all_free=True)
    bend_rest = pbd_constraints.second_neighbour_rest(c['rest'])
    kb, s_damp, max_disp = 0.5, 0.85, 0.01
    p, xc, vn = reference_predict(c)
    ref_jacobi_bend(p, bend_rest, c['inv_mass'], kb)
    corr = ref_ftl_pass(p, c['rest'], c['rest_length'], c['rot'])
    x, v, x_old = c['x'].copy(), c['v'].copy(), np.zeros_like(c['x'])
    k_corr = np.full_like(x, np.nan)
    clamped = run_ftl_step(x, v, x_old, k_corr, c['rest'], c['inv_mass'], c['rest_length'],
                           bend_rest, c, 1, kb, s_damp, max_disp, finalize)
    assert np.allclose(k_corr, corr, rtol=0, atol=ATOL)
    if finalize:
        p_ref, v_ref, clamped_ref = ref_finalize(p, xc, c['inv_mass'], corr, c['dt'], max_disp,
                                                 s_damp)
        assert clamped_ref > 0 and clamped == clamped_ref
        assert np.allclose(x, p_ref, rtol=0, atol=ATOL)
        assert np.allclose(v, v_ref, rtol=0, atol=1e-9)
    else:
        assert np.allclose(x, p, rtol=0, atol=ATOL)
        seg = np.linalg.norm(np.diff(x, axis=1), axis=2)
        assert np.allclose(seg[:, 1:], c['rest_length'][:, 1:], rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize('kind', ['pbd', 'xpbd', 'ftl'])
def test_solver_steps_match_the_package_reference_steps(kind):
    """Whole substeps (predict, constraints, finalize) of each guide kernel against
    :func:`reference.pbd_step`, :func:`reference.xpbd_step`, :func:`reference.ftl_step`."""
    c = random_case(6, all_free=(kind == 'ftl'))
    bend_rest = pbd_constraints.second_neighbour_rest(c['rest'])
    motion = {k: c[k] for k in ('rot', 'pos', 'rot_prev', 'pos_prev', 'gravity', 'damping',
                                'shock', 'shape')}
    im, dt, max_disp = c['inv_mass'], c['dt'], 0.01
    x, v, x_old = c['x'].copy(), c['v'].copy(), np.zeros_like(c['x'])
    lanes = pbd_constraints.lane_major
    if kind == 'pbd':
        want = reference.pbd_step(c['x'], c['v'], c['rest'], im, c['rest_length'], bend_rest,
                                  motion, dt, 3, 0.8, 0.3, max_disp)
        clamped = run_pbd_step(x, v, x_old, c['rest'], im, c['rest_length'], bend_rest, c, 3,
                               0.8, 0.3, max_disp, True)
    elif kind == 'xpbd':
        a_s, a_b = 1e-6 / dt ** 2, 1e-3 / dt ** 2
        want = reference.xpbd_step(c['x'], c['v'], c['rest'], im, c['rest_length'], bend_rest,
                                   motion, dt, 3, a_s, a_b, max_disp)
        clamped = run_xpbd_step(x, v, x_old, c['rest'], im, c['rest_length'], bend_rest,
                                lanes(np.zeros((im.shape[0], im.shape[1] - 1))),
                                lanes(np.zeros((im.shape[0], im.shape[1] - 2))), c, 3, a_s, a_b,
                                max_disp, True)
    else:
        want = reference.ftl_step(c['x'], c['v'], c['rest'], im, c['rest_length'], bend_rest,
                                  motion, dt, 2, 0.4, 0.8, max_disp)
        clamped = run_ftl_step(x, v, x_old, np.zeros_like(x), c['rest'], im, c['rest_length'],
                               bend_rest, c, 2, 0.4, 0.8, max_disp, True)
    assert want[2] > 0 and clamped == want[2]
    assert np.allclose(x, want[0], rtol=0, atol=ATOL)
    assert np.allclose(v, want[1], rtol=0, atol=1e-9)


def test_ftl_pass_fallback_on_collapsed_segment():
    c = random_case(5, s=3, n=6, all_free=True)
    p = c['rest'] @ c['rot'].T + c['pos']
    p[1, 3] = p[1, 2]                         # collapsed: direction from the rest shape
    expected = p.copy()
    ref_ftl_pass(expected, c['rest'], c['rest_length'], c['rot'])
    corr = np.zeros_like(p)
    ftl.ftl_pass_block(p, c['rest'], c['rest_length'], c['rot'], corr, 0, 3, False, None)
    assert np.all(np.isfinite(p))
    assert np.allclose(p, expected, atol=ATOL)
    # the collapsed node went back to its rest-shape place relative to its predecessor
    assert np.allclose(p[1, 3] - p[1, 2], c['rot'] @ (c['rest'][1, 3] - c['rest'][1, 2]),
                       atol=1e-12)


def test_finalize_kernel_matches_reference():
    c = random_case(6)
    rng = np.random.default_rng(6)
    x_old = c['x'].copy()
    p = x_old + rng.normal(size=x_old.shape) * 0.02
    corr = rng.normal(size=x_old.shape) * 0.01
    for s_damp, max_disp in ((0.0, 0.0), (0.0, 0.02), (0.8, 0.0), (0.8, 0.02)):
        x, v = p.copy(), np.zeros_like(p)
        clamped = integrate.finalize(x, v, x_old, c['inv_mass'], corr, c['dt'], max_disp,
                                     s_damp)
        p_ref, v_ref, clamped_ref = ref_finalize(p, x_old, c['inv_mass'], corr, c['dt'],
                                                 max_disp, s_damp)
        assert clamped == clamped_ref
        assert (clamped > 0) == (max_disp > 0)
        assert np.allclose(x, p_ref, rtol=0, atol=ATOL)
        assert np.allclose(v, v_ref, rtol=0, atol=1e-9)


def test_carry_rigid_matches_reference():
    c = random_case(7)
    rot_rel = integrate.relative_rotation(c['rot_prev'], c['rot'])
    out = np.empty_like(c['x'])
    integrate.carry_rigid(c['x'], rot_rel, c['pos_prev'], c['pos'], out)
    expected = (c['x'] - c['pos_prev']) @ rot_rel.T + c['pos']
    assert np.allclose(out, expected, rtol=0, atol=1e-14)


def test_pair_weights_and_gain():
    im = np.array([[0.0, 0.0, 1.0, 3.0]])
    w1 = pbd_constraints.pair_weights(im, 1)
    assert np.array_equal(w1[0, 0], [0.0, 0.0])              # both pinned: skipped
    assert np.allclose(w1[0, 1], [0.0, 1.0])
    assert np.allclose(w1[0, 2], [0.25, 0.75])
    g = pbd_constraints.xpbd_gain(im, 2, 0.5)
    assert np.allclose(g[0], [1.0 / 1.5, 1.0 / 3.5])
    rest = np.array([[[0, 0, 0], [0, 0, 1], [0, 1, 1], [0, 1, 1]]], float)
    assert np.allclose(pbd_constraints.second_neighbour_rest(rest), [[np.sqrt(2), 1.0]])


def test_kernels_deterministic_across_threads_and_blocks():
    c = random_case(8, s=21, n=9)
    bend_rest = pbd_constraints.second_neighbour_rest(c['rest'])

    def run(sl, threads):
        old = numba.get_num_threads()
        numba.set_num_threads(threads)
        try:
            x, v = c['x'][sl].copy(), c['v'][sl].copy()
            run_pbd_step(x, v, np.zeros_like(x), c['rest'][sl].copy(), c['inv_mass'][sl].copy(),
                         c['rest_length'][sl], bend_rest[sl], c, 4, 1.0, 0.3, 0.05, True)
        finally:
            numba.set_num_threads(old)
        return x, v

    a = run(slice(None), 1)
    b = run(slice(None), numba.config.NUMBA_NUM_THREADS)
    assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])
    # a strand's result does not depend on the block it is processed in
    sub = run(slice(3, 6), 1)
    assert np.array_equal(sub[0], a[0][3:6]) and np.array_equal(sub[1], a[1][3:6])


def test_ftl_bending_sweep_is_the_gradient_of_the_bending_energy():
    """FTL's bending sweep moves every free node i by -k/2 w_i times the gradient of
    E = sum C^2 / (2 (w_i + w_j)) over the second-neighbour constraints, computed from the
    positions before the sweep: the kernel, the reference and a finite-difference gradient
    agree."""
    c = random_case(6, s=5, n=11)
    im = np.ones(c['inv_mass'].shape)                # uniform masses, as the guides have
    im[:, :2] = 0.0
    bend_rest = pbd_constraints.second_neighbour_rest(c['rest'])
    x = c['x'] + 0.01 * np.random.default_rng(3).normal(size=c['x'].shape)
    k = 0.6
    kern = x.copy()
    pbd_constraints.jacobi_bend_block(kern, bend_rest, pbd_constraints.pair_weights(im, 2), k,
                                      0, x.shape[0])
    ref = x.copy()
    ref_jacobi_bend(ref, bend_rest, im, k)
    assert np.allclose(kern, ref, rtol=0, atol=ATOL)

    def energy(y):
        d = np.linalg.norm(y[:, 2:] - y[:, :-2], axis=2) - bend_rest
        return 0.5 * np.sum(d * d / (im[:, :-2] + im[:, 2:]))
    grad = np.zeros_like(x)
    eps = 1e-7
    for idx in np.ndindex(*x.shape):
        if im[idx[:2]] == 0:
            continue
        up, down = x.copy(), x.copy()
        up[idx] += eps
        down[idx] -= eps
        grad[idx] = (energy(up) - energy(down)) / (2 * eps)
    assert np.abs(kern - x).max() > 1e-4
    assert np.allclose(kern - x, -0.5 * k * grad, rtol=0, atol=1e-8)


@pytest.mark.parametrize('strands', [1, 13, 16, 21, 40])
def test_lane_sweep_equals_strand_by_strand_sweep(strands):
    """The side-by-side sweep of the PBD kernel (blocks of LANES strands, padding lanes for the
    rest) moves every strand exactly as the strand-by-strand sweep does, bit for bit."""
    c = random_case(5, s=strands, n=9)
    im, n, lanes = c['inv_mass'], c['x'].shape[1], pbd_constraints.LANES
    for gap, k, rest_dist in ((1, 0.9, c['rest_length']),
                              (2, 0.4, pbd_constraints.second_neighbour_rest(c['rest']))):
        w = pbd_constraints.pair_weights(im, gap)
        ref = c['x'].copy()
        pbd_constraints.pbd_sweep_block(ref, rest_dist, w, gap, k, 0, strands)
        assert not np.array_equal(ref, c['x'])
        out = c['x'].copy()
        work = pbd_constraints.lane_work(strands, n)
        rd_l, w_l = pbd_constraints.lane_major(rest_dist), pbd_constraints.lane_major(w)
        for b in range(work.shape[0]):
            s0, s1 = b * lanes, min((b + 1) * lanes, strands)
            pbd_constraints.lanes_in(out, s0, s1, work[b])
            pbd_constraints.pbd_sweep_lanes(work[b], rd_l[b], w_l[b], n, gap, k)
            pbd_constraints.lanes_out(work[b], out, s0, s1)
        assert np.array_equal(out, ref)
        used = strands - (work.shape[0] - 1) * lanes      # lanes of the last block
        assert np.all(work[-1].reshape(n, 3, lanes)[:, :, used:] == 0.0)   # padding stays 0


def test_lane_major_layout_round_trip():
    a = np.arange(21 * 5 * 2, dtype=float).reshape(21, 5, 2)
    lm = pbd_constraints.lane_major(a)
    lanes = pbd_constraints.LANES
    assert lm.shape == (2, 5 * 2 * lanes)
    assert lm[1, (3 * 2 + 1) * lanes + 4] == a[lanes + 4, 3, 1]     # [m][k][lane]
    assert np.all(lm[1].reshape(5, 2, lanes)[:, :, 21 - lanes:] == 0.0)   # padding
    assert np.array_equal(pbd_constraints.from_lane_major(lm, a.shape), a)
    b = np.arange(3 * 4, dtype=float).reshape(3, 4)
    assert np.array_equal(pbd_constraints.from_lane_major(pbd_constraints.lane_major(b), b.shape),
                          b)


@pytest.mark.parametrize('variant', ['strain_limit', 'strain_limit_serial'])
def test_strain_limiting_puts_every_segment_within_its_bound(variant):
    from hair_tracking.guides import pbd_constraints
    rng = np.random.default_rng(3)
    s, n = 5, 9
    rest = np.full((s, n - 1), 0.02)
    x = np.cumsum(rng.normal(size=(s, n, 3)), axis=1)
    x *= 0.02 / np.linalg.norm(np.diff(x, axis=1), axis=2).mean()
    x[:, 1:] *= rng.uniform(0.7, 1.4, size=(s, n - 1, 1))       # stretched and squeezed
    inv_mass = np.ones((s, n))
    inv_mass[:, :2] = 0.0                                           # the roots are held
    before, v = x.copy(), np.zeros_like(x)
    moved = getattr(pbd_constraints, variant)(x, v, inv_mass, rest, 0.01, 0.005)
    lengths = np.linalg.norm(np.diff(x, axis=1), axis=2)
    free = inv_mass[:, 1:] > 0
    assert np.all(np.abs(lengths[free] / rest[free] - 1.0) <= 0.01 + 1e-12)
    assert np.array_equal(x[:, :2], before[:, :2]) and moved > 0
    np.testing.assert_allclose(v, (x - before) / 0.005, atol=1e-9)  # the velocity follows
    again = x.copy()
    getattr(pbd_constraints, variant)(x, v, inv_mass, rest, 0.01, 0.005)
    np.testing.assert_allclose(x, again, rtol=0, atol=1e-15)        # within bounds: left
