import control
import numpy as np
import pytest
import scipy.linalg as sla
import slycot
from scipy.optimize import linear_sum_assignment

from fdikit import ModelError
from fdikit.model import LinearFaultModel
from fdikit.model.structure import (
    invariant_zeros,
    is_detectable,
    is_observable,
    markov_parameters,
    observability_matrix,
    rank,
    relative_degree,
    unobservable_modes,
)


# ------------------------------------------------------------------ reference helpers
def reference_zeros(A, B, C, D, tol=None):
    """python-control's zeros (SLICOT AB08ND through slycot), independent of fdikit.

    With ``tol``, AB08ND is called directly with that rank tolerance (python-control passes 0,
    i.e. SLICOT's default, which can be too tight: see test_zeros_wide_system_match_slycot).
    """
    n, m = B.shape
    p = C.shape[0]
    try:
        if tol is not None:
            out = slycot.ab08nd(n, m, p, A, B, C, D, tol=tol)
            nu = out[0]
            z = sla.eigvals(out[8][:nu, :nu], out[9][:nu, :nu]) if nu else np.zeros(0, complex)
        else:
            z = np.asarray(control.zeros(control.ss(A, B, C, D)), complex)
    except slycot.exceptions.SlycotParameterError:
        # python-control 0.10.2 lets slycot pick a too-small workspace for some shapes; call
        # AB08ND directly with a generous one, then finish exactly as python-control does.
        out = slycot.ab08nd(n, m, p, A, B, C, D, ldwork=50 * (n + m + p) ** 2 + 1000)
        nu = out[0]
        z = sla.eigvals(out[8][:nu, :nu], out[9][:nu, :nu]) if nu else np.zeros(0, complex)
    return z[np.isfinite(z)]


def assert_same_set(z, zref, rtol=1e-7):
    z, zref = np.asarray(z, complex), np.asarray(zref, complex)
    assert z.size == zref.size, f"{z} vs {zref}"
    if z.size:
        cost = np.abs(z[:, None] - zref[None, :])
        r, c = linear_sum_assignment(cost)
        err = cost[r, c] / np.maximum(1.0, np.abs(zref[c]))
        assert err.max() <= rtol, f"{z} vs {zref}: {err.max():.2e}"


def assert_rank_drops(A, B, C, D, z):
    """Independent check: the Rosenbrock matrix loses rank at every returned zero."""
    n = A.shape[0]
    P = lambda s: np.block([[A - s * np.eye(n), B], [C, D]])  # noqa: E731
    normal = np.linalg.matrix_rank(P(0.1234 + 0.5678j), tol=1e-8)
    for s in z:
        sv = np.linalg.svd(P(s), compute_uv=False)
        assert np.sum(sv > 1e-8 * sv[0]) < normal, (s, sv)


def rand_orth(rng, n):
    q, _ = np.linalg.qr(rng.standard_normal((n, n)))
    return q


# ------------------------------------------------------------------ rank
def test_rank_rule():
    assert rank(np.eye(3)) == 3
    assert rank([[1.0, 2.0], [2.0, 4.0]]) == 1
    assert rank(np.zeros((2, 3))) == 0
    assert rank(np.zeros((0, 3))) == 0
    # 1e-20 relative to 1 is below max(shape)*eps; 1e-10 is not
    assert rank(np.diag([1.0, 1e-20])) == 1
    assert rank(np.diag([1.0, 1e-10])) == 2
    assert rank(np.diag([1.0, 1e-10]), tol=1e-8) == 1


def test_observability_matrix_and_observable():
    A = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [-1.0, -2.0, -3.0]])
    C = np.array([[1.0, 0.0, 0.0]])
    O = observability_matrix(A, C)
    np.testing.assert_allclose(O, np.eye(3))
    assert is_observable(A, C)
    assert not is_observable(A, [[0.0, 0.0, 0.0]])


# ------------------------------------------------------------------ unobservable modes (PBH)
def test_unobservable_modes_block_system_in_random_coordinates():
    rng = np.random.default_rng(1)
    Ao = np.array([[-1.0, 2.0], [-2.0, -1.0]])
    Au = np.array([[0.5, 3.0], [-3.0, 0.5]])  # unobservable, eigenvalues 0.5 +- 3j
    A = sla.block_diag(Ao, Au, [[-4.0]])
    A[4, 0] = 1.0  # couplings among observable states
    A[2, 0] = 0.7  # observable -> unobservable coupling: states 2, 3 stay hidden from C
    C = np.array([[1.0, 0.0, 0.0, 0.0, 1.0], [0.0, 1.0, 0.0, 0.0, 0.0]])
    T = rand_orth(rng, 5) @ np.diag([1.0, 2.0, 0.5, 3.0, 1.5])
    At, Ct = np.linalg.solve(T, A @ T), C @ T
    ev = unobservable_modes(At, Ct)
    assert_same_set(ev, [0.5 + 3j, 0.5 - 3j], rtol=1e-9)
    # independent PBH check: rank [A - lam I; C] < n exactly at those modes
    for lam in np.linalg.eigvals(At):
        smin = np.linalg.svd(np.vstack([At - lam * np.eye(5), Ct]), compute_uv=False)[-1]
        is_unobs = np.min(np.abs(lam - ev)) < 1e-8
        assert (smin < 1e-9) == is_unobs, (lam, smin)
    # count agrees with the observability matrix rank (Kalman)
    assert ev.size == 5 - np.linalg.matrix_rank(observability_matrix(At, Ct))
    assert not is_observable(At, Ct)
    assert not is_detectable(At, Ct)  # 0.5 +- 3j unstable
    # discrete: same pair scaled into the unit disc
    assert is_detectable(At / 10.0, Ct, dt=0.1)


def test_unobservable_defective_eigenvalue_found():
    # a 3x3 Jordan block at -1 hidden from the output: PBH at computed eigenvalues is fragile here
    J = np.array([[-1.0, 1.0, 0.0], [0.0, -1.0, 1.0], [0.0, 0.0, -1.0]])
    A = sla.block_diag([[-2.0]], J)
    A[1, 0] = 1.0
    C = np.array([[1.0, 0.0, 0.0, 0.0]])
    T = rand_orth(np.random.default_rng(2), 4)
    ev = unobservable_modes(T.T @ A @ T, C @ T)
    assert ev.size == 3
    np.testing.assert_allclose(ev, -1.0, atol=1e-4)  # eps**(1/3) perturbation of a Jordan block
    assert is_detectable(T.T @ A @ T, C @ T)


@pytest.mark.parametrize("seed", range(6))
def test_unobservable_modes_random_hidden_blocks(seed):
    # x_u is driven by x_o but never reaches y: exactly eig(Au) is unobservable. Long single-output
    # chains in random coordinates make a plain staircase with a tight tolerance miss them.
    rng = np.random.default_rng(seed)
    for _ in range(15):
        no, nu, p = int(rng.integers(5, 18)), int(rng.integers(1, 5)), int(rng.integers(1, 3))
        Au = rng.standard_normal((nu, nu))
        A = np.block([[rng.standard_normal((no, no)), np.zeros((no, nu))],
                      [rng.standard_normal((nu, no)), Au]])
        C = np.hstack([rng.standard_normal((p, no)), np.zeros((p, nu))])
        T = rng.standard_normal((no + nu, no + nu)) + np.sqrt(no + nu) * np.eye(no + nu)
        At, Ct = np.linalg.solve(T, A @ T), C @ T
        assert_same_set(unobservable_modes(At, Ct), np.linalg.eigvals(Au), rtol=1e-6)


def test_detectable_boundary_and_model():
    # an unobservable integrator is not detectable (continuous); a mode on the unit circle neither
    assert not is_detectable(np.diag([-1.0, 0.0]), [[1.0, 0.0]])
    assert not is_detectable(np.diag([0.5, 1.0]), [[1.0, 0.0]], dt=0.1)
    m = LinearFaultModel(np.diag([-1.0, -3.0]), np.ones((2, 1)), [[1.0, 0.0]])
    assert is_detectable(m) and not is_observable(m)
    md = LinearFaultModel(np.diag([0.5, -3.0]), np.ones((2, 1)), [[1.0, 0.0]], dt=0.1)
    assert not is_detectable(md)  # |-3| > 1 in discrete time


# ------------------------------------------------------------------ invariant zeros
def test_zeros_hand_computed_siso():
    # G(s) = (s + 2) / ((s + 1)(s + 3)), controllable canonical form
    z = invariant_zeros([[0.0, 1.0], [-3.0, -4.0]], [[0.0], [1.0]], [[2.0, 1.0]])
    assert_same_set(z, [-2.0], rtol=1e-12)
    # with feedthrough: 1/(s+1) + 1 = (s + 2)/(s + 1)
    assert_same_set(invariant_zeros([[-1.0]], [[1.0]], [[1.0]], [[1.0]]), [-2.0], rtol=1e-12)


def test_zeros_hand_computed_mimo_in_random_coordinates():
    # diag( (s+2)/((s+1)(s+3)),  (s-1)/((s+4)(s+5)) ) -> zeros {-2, 1}
    A = sla.block_diag([[0.0, 1.0], [-3.0, -4.0]], [[0.0, 1.0], [-20.0, -9.0]])
    B = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 0.0], [0.0, 1.0]])
    C = np.array([[2.0, 1.0, 0.0, 0.0], [0.0, 0.0, -1.0, 1.0]])
    rng = np.random.default_rng(3)
    T, U, V = rand_orth(rng, 4), rand_orth(rng, 2), rand_orth(rng, 2)
    z = invariant_zeros(T.T @ A @ T, T.T @ B @ V, U @ C @ T)
    assert_same_set(z, [-2.0, 1.0], rtol=1e-10)


def test_zeros_none():
    # square, D = 0, CB invertible and n = m: no finite zeros
    A = np.array([[-1.0, 2.0], [0.0, -3.0]])
    assert invariant_zeros(A, np.eye(2), [[1.0, 1.0], [0.0, 1.0]]).size == 0
    # a generic non-square system has no invariant zeros (python-control agrees)
    rng = np.random.default_rng(4)
    A, B, C = rng.standard_normal((5, 5)), rng.standard_normal((5, 2)), rng.standard_normal((3, 5))
    assert invariant_zeros(A, B, C).size == 0
    assert reference_zeros(A, B, C, np.zeros((3, 2))).size == 0


@pytest.mark.parametrize("seed", range(40))
def test_zeros_random_square_match_python_control(seed):
    rng = np.random.default_rng(100 + seed)
    n, m = int(rng.integers(1, 8)), int(rng.integers(1, 4))
    A, B, C = rng.standard_normal((n, n)), rng.standard_normal((n, m)), rng.standard_normal((m, n))
    D = rng.standard_normal((m, m)) if seed % 3 == 0 else np.zeros((m, m))
    if seed % 5 == 1:
        D[:, 0] = 0.0  # rank-deficient feedthrough
    z = invariant_zeros(A, B, C, D)
    assert_same_set(z, reference_zeros(A, B, C, D), rtol=1e-7)
    assert_rank_drops(A, B, C, D, z)


def _series_zero_factor(rng, n, m, p, z0):
    """A random (p x m) system preceded, on every input, by (s - z0)/(s + 2): zeros include z0 (x m)."""
    G = control.ss(rng.standard_normal((n, n)) - 2 * np.eye(n), rng.standard_normal((n, m)),
                   rng.standard_normal((p, n)), np.zeros((p, m)))
    F = control.ss(-2.0 * np.eye(m), np.eye(m), -(2.0 + z0) * np.eye(m), np.eye(m))  # (s - z0)/(s + 2)
    S = control.series(F, G)
    return (np.asarray(S.A), np.asarray(S.B), np.asarray(S.C), np.asarray(S.D))


@pytest.mark.parametrize("seed", range(10))
def test_zeros_tall_system_match_python_control(seed):
    rng = np.random.default_rng(200 + seed)
    m = int(rng.integers(1, 3))
    p = m + int(rng.integers(1, 3))
    A, B, C, D = _series_zero_factor(rng, int(rng.integers(2, 5)), m, p, z0=0.7)
    z = invariant_zeros(A, B, C, D)
    zref = reference_zeros(A, B, C, D)
    assert_same_set(z, zref, rtol=1e-7)
    assert_rank_drops(A, B, C, D, z)
    assert np.sum(np.abs(z - 0.7) < 1e-6) == m  # the series zero, once per input channel


@pytest.mark.parametrize("seed", range(10))
def test_zeros_wide_system_match_slycot(seed):
    rng = np.random.default_rng(300 + seed)
    p = int(rng.integers(1, 3))
    m = p + int(rng.integers(1, 3))
    # the dual of a tall system with a series zero is a wide one with the same zeros
    A, B, C, D = _series_zero_factor(rng, int(rng.integers(2, 5)), p, m, z0=-0.3)
    A, B, C, D = A.T, C.T, B.T, D.T
    z = invariant_zeros(A, B, C, D)
    # AB08ND with an explicit tolerance: with python-control's tol=0 (SLICOT default) seed 3
    # misses the zero at -0.3, although G(-0.3) = 0 (checked by assert_rank_drops)
    assert_same_set(z, reference_zeros(A, B, C, D, tol=1e-10), rtol=1e-7)
    assert_rank_drops(A, B, C, D, z)
    assert np.sum(np.abs(z + 0.3) < 1e-6) == p


def test_zeros_tall_unobservable_modes_are_zeros():
    # for a tall system an unobservable mode is an (output-decoupling) invariant zero
    rng = np.random.default_rng(5)
    A = sla.block_diag(rng.standard_normal((3, 3)), [[-0.25]])
    B = rng.standard_normal((4, 1))
    C = np.hstack([rng.standard_normal((3, 3)), np.zeros((3, 1))])
    z = invariant_zeros(A, B, C)
    assert_same_set(z, [-0.25], rtol=1e-10)
    assert_same_set(z, reference_zeros(A, B, C, np.zeros((3, 1))))


def test_zeros_of_fault_group_of_a_model():
    # (A, M, C) with M = the fault directions of a LinearFaultModel
    A = np.array([[0.0, 1.0], [-3.0, -4.0]])
    m = LinearFaultModel(A, np.zeros((2, 1)), [[2.0, 1.0]],
                         faults=[("leak", [0.0, 1.0], None)])
    assert_same_set(invariant_zeros(m, "f"), [-2.0], rtol=1e-12)
    with pytest.raises(ModelError, match="group"):
        invariant_zeros(m, "x")
    with pytest.raises(ModelError, match="columns"):
        invariant_zeros(A, np.ones((2, 1)), np.ones((1, 3)))


# ------------------------------------------------------------------ Markov parameters, relative degree
def test_markov_parameters_equal_discrete_impulse_response():
    rng = np.random.default_rng(6)
    A = 0.5 * rng.standard_normal((4, 4))
    B, C, D = rng.standard_normal((4, 2)), rng.standard_normal((3, 4)), rng.standard_normal((3, 2))
    H = markov_parameters(A, B, C, D, k=6)
    assert H.shape == (7, 3, 2)
    # the impulse response of x[k+1] = A x + B u, y = C x + D u is D, CB, CAB, ...
    resp = control.impulse_response(control.ss(A, B, C, D, 1.0), T=np.arange(7.0))
    Y = np.asarray(resp.outputs)  # (outputs, inputs, time)
    np.testing.assert_allclose(np.moveaxis(Y, -1, 0), H, rtol=1e-12, atol=1e-12)


def test_relative_degree_paper_remark_and_a1():
    # ng-tan-edwards-kuang, remark after (49): CM = 0 but B1 holds
    A = np.array([[0.0, 1.0], [0.0, 0.0]])
    rd = relative_degree(A, [[0.0], [1.0]], [[1.0, 0.0]])
    assert rd.per_input == (2,) and rd.overall == 2 and not rd.is_one
    assert rd.rank_M == 1 and rd.rank_CM == 0
    # measuring the velocity too: relative degree one (A1)
    rd = relative_degree(A, [[0.0], [1.0]], np.eye(2))
    assert rd.per_input == (1,) and rd.overall == 1 and rd.is_one


def test_relative_degree_b1_matches_paper_condition():
    # random systems with CM rank-deficient: overall == 2  <=>  condition B1 holds
    rng = np.random.default_rng(7)
    seen = set()
    for _ in range(30):
        n, p, q = 5, 3, 2
        A, C = rng.standard_normal((n, n)), rng.standard_normal((p, n))
        # make C M of rank 1: one fault column in ker C
        N = sla.null_space(C)
        M = np.column_stack([N @ rng.standard_normal(N.shape[1]), rng.standard_normal(n)])
        if rng.random() < 0.5:  # sometimes make B1 fail: second column in ker C and CAM dependent
            M[:, 1] = N @ rng.standard_normal(N.shape[1])
        CM, CAM = C @ M, C @ A @ M
        rk = lambda X: np.linalg.matrix_rank(X, tol=1e-9)  # noqa: E731  (entries are O(1) or O(eps))
        b1 = rk(np.block([[CAM, CM], [CM, np.zeros_like(CM)]])) == rk(CM) + rk(M)
        rd = relative_degree(A, M, C)
        assert rd.rank_CM == rk(CM)
        assert (rd.overall == 1) == (rk(CM) == q)
        assert (rd.overall == 2) == (b1 and rk(CM) < q)
        seen.add(rd.overall)
    assert {1, 2} & seen


def test_relative_degree_special_cases():
    A = np.diag([-1.0, -2.0])
    # D column nonzero -> 0; input that never reaches the output -> None
    rd = relative_degree(A, [[1.0, 0.0], [0.0, 1.0]], [[1.0, 0.0]], [[1.0, 0.0]])
    assert rd.per_input == (0, None)
    assert rd.overall is None  # the second input cannot be recovered: not left invertible
    # two identical columns: the paper's rank test counts rank M (= 1), so relative degree one
    rd = relative_degree(A, [[1.0, 1.0], [1.0, 1.0]], np.eye(2))
    assert rd.per_input == (1, 1) and rd.overall == 1 and rd.rank_M == 1 and rd.is_one
    # two inputs seen through one output: rank T grows by at most 1 < rank M = 2 -> None
    rd = relative_degree(A, np.eye(2), [[1.0, 1.0]])
    assert rd.per_input == (1, 1) and rd.overall is None and not rd.is_one
    # large ||A||: generic C B of full column rank is relative degree one whatever the time scale
    rng = np.random.default_rng(8)
    A6, B6, C6 = 1e4 * rng.standard_normal((6, 6)), rng.standard_normal((6, 2)), rng.standard_normal((3, 6))
    rd = relative_degree(A6, B6, C6)
    assert rd.per_input == (1, 1) and rd.overall == 1 and rd.is_one


@pytest.mark.parametrize("seed", range(6))
def test_relative_degree_siso_equals_pole_zero_excess_at_large_scale(seed):
    # SISO: relative degree = deg(den) - deg(num); poles and zeros around 1e3 rad/s make the
    # unscaled Markov parameters span ~ 1e3**n
    rng = np.random.default_rng(400 + seed)
    n = int(rng.integers(3, 8))
    nz = int(rng.integers(0, n))
    poles = -1e3 * (0.5 + rng.random(n))
    zeros = 1e3 * rng.standard_normal(nz)
    G = control.ss(control.tf(np.poly(zeros) * 7.0, np.poly(poles)))
    T = rand_orth(rng, n) @ np.diag(np.exp(rng.standard_normal(n)))
    A, B = np.linalg.solve(T, np.asarray(G.A) @ T), np.linalg.solve(T, np.asarray(G.B))
    C = np.asarray(G.C) @ T
    rd = relative_degree(A, B, C)
    assert rd.per_input == (n - nz,) and rd.overall == n - nz
    # invariant under time scaling
    assert relative_degree(A / 1e3, B, C).overall == n - nz
