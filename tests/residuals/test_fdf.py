"""Tests of the fault detection filters (exact UIO, optimal stochastic FDF) of residuals.fdf.

Every transmission is measured on the internal form recomputed by composing plant and filter,
and the internal form itself is checked against independent computations: the closed-form
error dynamics of each design, and the product of the filter's and the plant's frequency
responses.
"""

from __future__ import annotations

import itertools
import json

import numpy as np
import pytest
from scipy.linalg import solve_discrete_lyapunov, subspace_angles
from scipy.signal import cont2discrete

from fdikit.errors import ConditionError, ModelError
from fdikit.model import LinearFaultModel, dc_gain, frequency_response, observability_matrix
from fdikit.residuals.fdf import (
    FaultDetectionFilter,
    FilterDesign,
    conditioned_invariant_subspace,
    design_filter_set,
    design_optimal_fdf,
    design_uio,
    fault_detection_filter,
    fault_direction_split,
    fault_directions,
    filter_frequency_response,
    internal_form,
    reduce_filter,
    residual_covariance,
    stack_designs,
)
from fdikit.signals import Signals

F_BAND = np.linspace(0.0, 5.0, 101)  # Hz: DC and 0-5 Hz


# ----------------------------------------------------------------------------- systems
def _random_discrete(rng, n, m, p, dt=0.01, faults=(), stable=3.0):
    """Random stable continuous system, ZOH-discretised (dense discrete matrices)."""
    Ac = rng.normal(size=(n, n))
    Ac -= (np.max(np.linalg.eigvals(Ac).real) + stable) * np.eye(n)
    Bc = rng.normal(size=(n, m))
    C = rng.normal(size=(p, n))
    A, B, *_ = cont2discrete((Ac, Bc, C, np.zeros((p, m))), dt)
    return LinearFaultModel(A, B, C, dt=dt, faults=faults)


def _with_groups(m, rng, D=None, d=False, w=False):
    """Rebuild a model with control feedthrough and random disturbance / noise groups."""
    n, p = m.n_states, m.n_outputs
    kw = {}
    if d:
        kw.update(Bd=rng.normal(size=(n, 1)), Dd=rng.normal(size=(p, 1)))
    if w:
        kw.update(Bw=rng.normal(size=(n, 2)), Dw=rng.normal(size=(p, 2)))
    return LinearFaultModel(m.A, m.B, m.C, D, dt=m.dt, faults=m.fault_names, **kw)


def _sensor_nuisance_system():
    """Discrete system where a sensor-fault nuisance has rank(C E) = 1 < rank(E) = 2.

    C = [I3 0], the sensor fault on y0 has f = e1 and A f = A[:, 0]; A[1, 0] = A[2, 0] = 0 keeps
    C A f parallel to e1 while A[3:, 0] != 0, so the exact UIO does not exist.
    """
    rng = np.random.default_rng(1)
    n, p, dt = 5, 3, 0.01
    Ac = rng.normal(size=(n, n)) - 3 * np.eye(n)
    Ac[1, 0] = Ac[2, 0] = 0.0
    A = np.eye(n) + dt * Ac
    B = np.zeros((n, 2))
    B[2, 0] = dt
    B[4, 1] = dt
    return LinearFaultModel(A, B, np.eye(n)[:p], dt=dt, faults=["actuator:u0", "sensor:y0"])


def _ratio(design, model, target, nuisance):
    """max over the band of |G_nuisance| / |G_target| (2-norms over residual channels), and at DC."""
    M = internal_form(design, model)
    G = frequency_response(M, F_BAND, "f")
    names = M.fault_names
    t = np.linalg.norm(G[:, :, names.index(target)], axis=1)
    nu = np.linalg.norm(G[:, :, [names.index(s) for s in nuisance]], 2, axis=(1, 2)) \
        if len(nuisance) > 1 else np.linalg.norm(G[:, :, names.index(nuisance[0])], axis=1)
    return float(np.max(nu / t)), float(nu[0] / t[0]), float(np.min(t))


# ----------------------------------------------------------------------------- fault directions
def test_sensor_direction_is_minimum_norm_solution():
    rng = np.random.default_rng(0)
    m = _random_discrete(rng, 5, 1, 3, faults=["sensor:y1", "actuator:u0"])
    F = fault_directions(m, "sensor:y1")
    f = F[:, 0]
    np.testing.assert_allclose(m.C @ f, [0.0, 1.0, 0.0], atol=1e-12)
    # minimum norm: orthogonal to ker C (brute force: any null-space perturbation makes it longer)
    _, _, Vt = np.linalg.svd(m.C)
    N = Vt[3:].T
    np.testing.assert_allclose(N.T @ f, 0.0, atol=1e-12)
    for _ in range(20):
        g = f + N @ rng.normal(size=2)
        assert np.linalg.norm(g) > np.linalg.norm(f)
    np.testing.assert_allclose(F[:, 1], -m.A @ f, atol=1e-12)
    np.testing.assert_allclose(fault_directions(m, "actuator:u0")[:, 0], m.B[:, 0])


def test_additive_fault_with_feedthrough_directions():
    rng = np.random.default_rng(3)
    m = _random_discrete(rng, 4, 1, 4)
    b, d = rng.normal(size=4), rng.normal(size=4)
    m = m.with_faults(("leak", b, d), ("pure", b, None))
    F = fault_directions(m, "leak")
    fd = np.linalg.solve(m.C, d)  # C square: f_d unique
    np.testing.assert_allclose(F, np.column_stack([fd, b - m.A @ fd]), atol=1e-10)
    np.testing.assert_allclose(fault_directions(m, "pure")[:, 0], b)


def test_sensor_direction_outside_range_of_C_raises():
    m = LinearFaultModel(np.eye(2) * 0.5, np.zeros((2, 0)), [[1.0, 0.0], [1.0, 0.0]], dt=0.1,
                         faults=["sensor:y0"])
    with pytest.raises(ConditionError) as ei:
        fault_directions(m, "sensor:y0")
    assert ei.value.condition == "sensor direction"


def test_conditioned_invariant_subspace_chain():
    # x1 <- x2 <- x3 chain measured at x1 and x3: a fault on x2 is seen through x1 one step later
    A = np.array([[0.5, 1.0, 0.0], [0.0, 0.5, 0.0], [0.0, 0.0, 0.3]])
    C = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    S = conditioned_invariant_subspace(A, C, [[0.0], [1.0], [0.0]])
    assert S.shape[1] == 2
    P = S @ S.T
    np.testing.assert_allclose(P @ [1.0, 0.0, 0.0], [1.0, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(P @ [0.0, 1.0, 0.0], [0.0, 1.0, 0.0], atol=1e-12)


# ----------------------------------------------------------------------------- exact UIO
@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_uio_exact_decoupling_random(seed):
    rng = np.random.default_rng(seed)
    m = _random_discrete(rng, 6, 3, 4, faults=["actuator:u0", "actuator:u1", "actuator:u2"])
    d = design_uio(m, "actuator:u0", ["actuator:u1", "actuator:u2"])
    M = internal_form(d, m)
    G = frequency_response(M, F_BAND, "f")
    scale = np.max(np.abs(G[:, :, 0]))
    assert scale > 1e-3
    assert np.max(np.abs(G[:, :, 1:])) <= 1e-12 * scale
    # controls cancel exactly too
    assert np.max(np.abs(frequency_response(M, F_BAND, "u"))) <= 1e-12 * scale
    # the target reaches the residual at DC
    assert np.linalg.norm(dc_gain(M, "f")[:, 0]) > 1e-3
    assert d.info["rank_CE"] == d.info["rank_E"] == 2
    assert d.info["spectral_radius"] < 1


def test_uio_blocks_a_sensor_fault_nuisance_when_the_rank_condition_holds():
    rng = np.random.default_rng(7)
    m = _random_discrete(rng, 5, 2, 4, faults=["actuator:u0", "sensor:y2"])
    d = design_uio(m, "actuator:u0", ["sensor:y2"])
    assert d.info["rank_E"] == d.info["rank_CE"] == 2
    G = frequency_response(internal_form(d, m), F_BAND, "f")
    assert np.max(np.abs(G[:, :, 1])) <= 1e-12 * np.max(np.abs(G[:, :, 0]))
    # the sensor fault is a feedthrough of the plant: decoupling includes the direct path
    assert np.max(np.abs(d.Dy @ m.D_of("f")[:, 1])) < 1e-12


def test_uio_internal_form_matches_closed_form_error_dynamics():
    """w = T x - z obeys w+ = F w + (T B_g - K D_g) v, r = C w + (I - C H) D_g v (derived by hand)."""
    rng = np.random.default_rng(11)
    m = _random_discrete(rng, 5, 2, 3, faults=["actuator:u0", "actuator:u1", "sensor:y0"])
    m = _with_groups(m, rng, D=0.1 * rng.normal(size=(3, 2)))  # control feedthrough
    d = design_uio(m, "actuator:u0", ["actuator:u1"])
    H, T, K1 = d.info["H"], d.info["T"], d.info["K1"]
    F = d.A
    K = K1 + F @ H
    Bg, Dg = m.B_of("f"), m.D_of("f")
    cf = LinearFaultModel(F, np.zeros((5, 0)), m.C, dt=m.dt,
                          faults=[(f"g{i}", T @ Bg[:, i] - K @ Dg[:, i],
                                   (np.eye(3) - m.C @ H) @ Dg[:, i]) for i in range(3)])
    G1 = frequency_response(internal_form(d, m), F_BAND, "f")
    G2 = frequency_response(cf, F_BAND, "f")
    np.testing.assert_allclose(G1, G2, rtol=0, atol=1e-9 * np.max(np.abs(G2)))
    # the closed form shows the decoupling structurally: the nuisance (actuator u1, which has a
    # feedthrough here) enters neither the w-dynamics nor the residual directly
    assert np.max(np.abs(T @ Bg[:, 1] - K @ Dg[:, 1])) < 1e-12
    assert np.max(np.abs((np.eye(3) - m.C @ H) @ Dg[:, 1])) < 1e-12
    assert np.max(np.abs(T @ Bg[:, 0] - K @ Dg[:, 0])) > 1e-4


def test_uio_rank_condition_failure_names_the_ranks():
    m = _sensor_nuisance_system()
    with pytest.raises(ConditionError) as ei:
        design_uio(m, "actuator:u0", ["sensor:y0"])
    assert ei.value.condition == "rank(CE) = rank(E)"
    assert ei.value.details == {"rank_E": 2, "rank_CE": 1}
    assert "rank 2" in str(ei.value) and "rank 1" in str(ei.value)


def test_uio_detectability_failure():
    # E = e2, C = [1 1]: A1 = (I - E (CE)^+ C) A has the unobservable mode a (the invariant zero of
    # (A, E, C)); with a = 1.2 outside the unit circle no stable UIO exists.
    a = 1.2
    m = LinearFaultModel(np.diag([a, 0.5]), [[1.0], [0.0]], [[1.0, 1.0]], dt=0.1,
                         faults=["actuator:u0", ("n", [0.0, 1.0], None)])
    with pytest.raises(ConditionError) as ei:
        design_uio(m, "actuator:u0", ["n"])
    assert ei.value.condition == "detectability of (C, A1)"
    np.testing.assert_allclose(np.real(ei.value.details["unstable_unobservable_modes"]), [a], atol=1e-9)
    # with a stable zero (a = 0.6) the UIO exists and the mode stays an eigenvalue of F
    m2 = LinearFaultModel(np.diag([0.6, 0.5]), [[1.0], [0.0]], [[1.0, 1.0]], dt=0.1,
                          faults=["actuator:u0", ("n", [0.0, 1.0], None)])
    with pytest.raises(ConditionError) as ei2:  # target u0 = e1 is also blocked: nothing left
        design_uio(m2, "actuator:u0", ["n"])
    assert ei2.value.condition == "target visibility"


def test_uio_pole_placement():
    rng = np.random.default_rng(5)
    m = _random_discrete(rng, 4, 2, 3, faults=["actuator:u0", "actuator:u1"])
    poles = [0.1, 0.2, 0.3, 0.4]
    d = design_uio(m, "actuator:u0", ["actuator:u1"], poles=poles)
    ev = np.sort(np.linalg.eigvals(d.A).real)
    # the unobservable modes of (C, A1) cannot be moved; the observable ones are placed
    um = np.sort(np.real(d.info["unobservable_modes"]))
    assert um.size == 0 or all(np.min(np.abs(ev - z)) < 1e-8 for z in um)
    placed = [p for p in poles if np.min(np.abs(ev - p)) < 1e-6]
    assert len(placed) >= 4 - um.size


# ----------------------------------------------------------------------------- optimal stochastic FDF
def test_optimal_fdf_blocks_sensor_nuisance_where_uio_does_not_exist():
    m = _sensor_nuisance_system()
    d = design_optimal_fdf(m, "actuator:u0", ["sensor:y0"], gamma=1e-6)
    assert d.info["rank_E"] == 2 and d.info["rank_CE"] == 1
    assert not d.info["exact_uio_rank_condition"]
    worst, dc, tmin = _ratio(d, m, "actuator:u0", ["sensor:y0"])
    assert worst <= 1e-3 and dc <= 1e-3
    assert tmin > 1e-3  # the target is seen everywhere in the band
    # and the projector really annihilates the nuisance's output directions: H e1 = 0
    np.testing.assert_allclose(d.info["H"] @ np.eye(3)[:, 0], 0.0, atol=1e-12)


def test_optimal_fdf_nuisance_transmission_decreases_with_gamma():
    m = _sensor_nuisance_system()
    worst = [_ratio(design_optimal_fdf(m, "actuator:u0", ["sensor:y0"], gamma=g, reduce=None),
                    m, "actuator:u0", ["sensor:y0"])[0] for g in (1e-2, 1e-4, 1e-6, 1e-8)]
    assert all(b < a for a, b in itertools.pairwise(worst)), worst
    assert worst[-1] < 1e-2 * worst[0]
    # near the limit the transmission is proportional to gamma
    w10, w12 = (_ratio(design_optimal_fdf(m, "actuator:u0", ["sensor:y0"], gamma=g, reduce=None),
                       m, "actuator:u0", ["sensor:y0"])[0] for g in (1e-10, 1e-12))
    assert 50 < w10 / w12 < 200


def test_optimal_fdf_recovers_uio_structure_in_the_limit():
    """Where the exact UIO exists, gamma -> 0 drives the nuisance transmission towards zero and the
    nuisance eigenvalues towards z = 0 (continuous time: -infinity)."""
    rng = np.random.default_rng(2)
    m = _random_discrete(rng, 5, 2, 3, faults=["actuator:u0", "actuator:u1"])
    ratios, fast = [], []
    for g in (1e-3, 1e-6, 1e-9):
        d = design_optimal_fdf(m, "actuator:u0", ["actuator:u1"], gamma=g, reduce=None)
        ratios.append(_ratio(d, m, "actuator:u0", ["actuator:u1"])[0])
        fast.append(np.min(np.abs(d.info["eigenvalues"])))
    assert ratios[0] > ratios[1] > ratios[2] and ratios[2] < 1e-4
    assert fast[2] < fast[0] and fast[2] < 1e-3


@pytest.mark.parametrize("system", ["sensor", "uio-exists"])
def test_nuisance_subspace_becomes_unobservable_from_the_residual(system):
    """The UIO's geometric structure: as gamma -> 0 the (weakly) unobservable subspace of the filter
    (Hr C, A - L C) converges to the nuisance subspace S2* (principal angles from an SVD of the
    observability matrix, independent of the design's own computations)."""
    if system == "sensor":
        m, t, nu, gammas = _sensor_nuisance_system(), "actuator:u0", "sensor:y0", (1e-4, 1e-6, 1e-8, 1e-10)
    else:
        m = _random_discrete(np.random.default_rng(2), 5, 2, 3, faults=["actuator:u0", "actuator:u1"])
        t, nu, gammas = "actuator:u0", "actuator:u1", (1e-2, 1e-4, 1e-6, 1e-8)
    S2 = conditioned_invariant_subspace(m.A, m.C, fault_directions(m, nu))
    k = S2.shape[1]
    angles = []
    for g in gammas:
        d = design_optimal_fdf(m, t, [nu], gamma=g, reduce=None)
        _, _, Vt = np.linalg.svd(observability_matrix(d.A, d.C))
        angles.append(float(np.max(subspace_angles(Vt[-k:].T, S2))))
    assert all(b < a for a, b in itertools.pairwise(angles)), angles
    assert angles[-1] < 1e-3


@pytest.mark.parametrize("seed", [4, 5, 6])
def test_optimal_fdf_random_states_in_ker_C(seed):
    """Nuisance directions in ker C (rank C E = 0 < rank E): exact UIO impossible, approximate works."""
    rng = np.random.default_rng(seed)
    m = _random_discrete(rng, 6, 1, 4, faults=["actuator:u0"])
    _, _, Vt = np.linalg.svd(m.C)
    e = Vt[4:].T @ rng.normal(size=2)  # one direction in ker C
    m = m.with_faults(("hidden", e, None))
    with pytest.raises(ConditionError):
        design_uio(m, "actuator:u0", ["hidden"])
    d = design_optimal_fdf(m, "actuator:u0", ["hidden"], gamma=1e-8)
    worst, dc, _ = _ratio(d, m, "actuator:u0", ["hidden"])
    assert worst <= 1e-3 and dc <= 1e-3


def test_reduced_filter_keeps_dc_gain_and_blocking():
    m = _sensor_nuisance_system()
    d = design_optimal_fdf(m, "actuator:u0", ["sensor:y0"], gamma=1e-8)
    full = d.info["full"]
    assert full.order == m.n_states
    # dropped: the fast nuisance mode (|z| ~ 0) and a weakly observable complex pair
    dz, dobs = d.info["dropped_eigenvalues"], d.info["dropped_observability"]
    assert d.order == d.info["order"] == 2 and dz.size == 3
    assert np.sum(np.abs(dz) <= 0.05) == 1
    assert np.all(dobs < 1e-4) and np.all(d.info["kept_observability"] > 1e-2)
    # independent check of weak observability: for each dropped mode z the PBH matrix
    # [z I - A; C] is nearly rank deficient (its smallest singular value is tiny)
    for z in dz:
        sv = np.linalg.svd(np.vstack([z * np.eye(5) - full.A, full.C]), compute_uv=False)
        assert sv[-1] < 1e-4 * np.linalg.norm(full.C, 2)
    # residualisation keeps the filter's DC gain exactly (u, y -> r)
    Gu_f, Gy_f = filter_frequency_response(full, [0.0])
    Gu_r, Gy_r = filter_frequency_response(d, [0.0])
    np.testing.assert_allclose(Gy_r, Gy_f, atol=1e-9 * np.max(np.abs(Gy_f)))
    np.testing.assert_allclose(Gu_r, Gu_f, atol=1e-9 * max(1.0, np.max(np.abs(Gu_f))))
    worst, dc, _ = _ratio(d, m, "actuator:u0", ["sensor:y0"])
    assert worst <= 1e-3 and dc <= 1e-3
    # a reduced design is still plain matrices that round-trip through JSON
    d2 = FilterDesign.from_dict(json.loads(json.dumps(d.to_dict())))
    np.testing.assert_array_equal(d2.A, d.A)
    np.testing.assert_array_equal(d2.Dy, d.Dy)


def test_reduce_filter_truncate_and_bad_order():
    d = FilterDesign(np.diag([0.9, 0.01]), np.zeros((2, 0)), np.array([[0.1], [1.0]]),
                     np.array([[1.0, 2.0]]), np.zeros((1, 0)), np.zeros((1, 1)), 0.01, [], ["y"], ["r"])
    r = reduce_filter(d, method="truncate")
    assert r.order == 1 and r.Dy[0, 0] == 0.0
    r = reduce_filter(d)  # residualise: 2 * 1 / (1 - 0.01)
    assert abs(r.Dy[0, 0] - 2.0 / 0.99) < 1e-12
    with pytest.raises(ModelError):
        reduce_filter(d, 3)


def test_optimal_fdf_internal_form_matches_closed_form_error_dynamics():
    """e = x - x_hat: e+ = (A - L C) e + (B_g - L D_g) v, r = Hr (C e + D_g v)."""
    rng = np.random.default_rng(9)
    m = _random_discrete(rng, 5, 2, 3, faults=["actuator:u0", "sensor:y1"])
    m = _with_groups(m, rng, D=0.1 * rng.normal(size=(3, 2)), d=True, w=True)
    d = design_optimal_fdf(m, "actuator:u0", ["sensor:y1"], gamma=1e-4, reduce=None)
    L, Hr = d.info["L"], d.info["Hr"]
    M = internal_form(d, m)
    for g in ("u", "d", "f", "w"):
        Bg, Dg = m.B_of(g), m.D_of(g)
        if g == "u":
            G2 = np.zeros((F_BAND.size, Hr.shape[0], Bg.shape[1]))  # controls cancel exactly
        else:
            z = np.exp(2j * np.pi * F_BAND * m.dt)
            X = np.linalg.solve(z[:, None, None] * np.eye(5) - (m.A - L @ m.C), Bg - L @ Dg)
            G2 = Hr @ (m.C @ X + Dg)
        G1 = frequency_response(M, F_BAND, g)
        np.testing.assert_allclose(G1, G2, rtol=0, atol=1e-9 * max(1.0, np.max(np.abs(G2))))


@pytest.mark.parametrize("kind", ["uio", "optimal", "reduced"])
def test_internal_form_equals_filter_times_plant_response(kind):
    """Independent of the composition: G_r,g = G_ry G_yg (+ G_ru for the controls), frequency by frequency."""
    rng = np.random.default_rng(21)
    m = _random_discrete(rng, 6, 2, 4, faults=["actuator:u0", "actuator:u1", "sensor:y3"])
    m = _with_groups(m, rng, D=0.2 * rng.normal(size=(4, 2)), w=True)
    if kind == "uio":
        d = design_uio(m, "actuator:u0", ["actuator:u1"])
    else:
        d = design_optimal_fdf(m, "actuator:u0", ["sensor:y3"], gamma=1e-5,
                               reduce=None if kind == "optimal" else "residualize", fast_modulus=0.2)
    f = np.linspace(0.0, 40.0, 37)
    Gru, Gry = filter_frequency_response(d, f)
    M = internal_form(d, m)
    for g in ("u", "f", "w"):
        G2 = Gry @ frequency_response(m, f, g) + (Gru if g == "u" else 0.0)
        G1 = frequency_response(M, f, g)
        np.testing.assert_allclose(G1, G2, rtol=0, atol=1e-9 * max(1.0, np.max(np.abs(G2))))


def test_optimal_fdf_conditions():
    m = _sensor_nuisance_system()
    # nuisance output directions fill all outputs: residual dimension
    m3 = m.with_faults("sensor:y1", "sensor:y2")
    with pytest.raises(ConditionError) as ei:
        design_optimal_fdf(m3, "actuator:u0", ["sensor:y0", "sensor:y1", "sensor:y2"])
    assert ei.value.condition == "residual dimension"
    assert ei.value.details["outputs"] == 3
    # target identical to a nuisance: not visible
    m4 = m.with_faults(("copy", m.B[:, 0], None))
    with pytest.raises(ConditionError) as ei:
        design_optimal_fdf(m4, "actuator:u0", ["copy"])
    assert ei.value.condition == "target visibility"
    with pytest.raises(ModelError):
        design_optimal_fdf(m, "actuator:u0", ["sensor:y0"], gamma=0.0)
    with pytest.raises(ModelError):
        design_optimal_fdf(m, "actuator:u0", ["actuator:u0"])
    with pytest.raises(ModelError):
        design_uio(m, "actuator:u0", ["nonexistent"])


def test_continuous_model_is_discretised():
    rng = np.random.default_rng(12)
    Ac = rng.normal(size=(4, 4)) - 4 * np.eye(4)
    mc = LinearFaultModel(Ac, rng.normal(size=(4, 2)), rng.normal(size=(3, 4)),
                          faults=["actuator:u0", "actuator:u1"])
    with pytest.raises(ModelError):
        design_uio(mc, "actuator:u0", ["actuator:u1"])
    d = design_uio(mc, "actuator:u0", ["actuator:u1"], dt=0.02)
    assert d.dt == 0.02
    G = frequency_response(internal_form(d, mc), F_BAND, "f")  # internal_form discretises too
    assert np.max(np.abs(G[:, :, 1])) <= 1e-12 * np.max(np.abs(G[:, :, 0]))


# ----------------------------------------------------------------------------- front ends
def test_auto_method_and_filter_set():
    m = _sensor_nuisance_system()
    d = fault_detection_filter(m, "actuator:u0", ["sensor:y0"], gamma=1e-7)
    assert d.info["method"] == "optimal_fdf" and "rank(CE)" in d.info["uio_failed"]
    rng = np.random.default_rng(8)
    m2 = _random_discrete(rng, 6, 3, 4, faults=["actuator:u0", "actuator:u1", "actuator:u2"])
    fs = design_filter_set(m2, ["actuator:u0", "actuator:u1"], ["actuator:u2"], name="set1")
    assert list(fs) == ["actuator:u0", "actuator:u1"]
    for t, d in fs.items():
        assert d.info["method"] == "uio"
        assert d.info["nuisance"] == [s for s in ("actuator:u0", "actuator:u1") if s != t] + ["actuator:u2"]
        assert d.residual_names[0].startswith(f"set1/{t}:")
        G = frequency_response(internal_form(d, m2), F_BAND, "f")
        i = m2.fault_names.index(t)
        others = [j for j in range(3) if j != i]
        assert np.max(np.abs(G[:, :, others])) <= 1e-12 * np.max(np.abs(G[:, :, i]))


# ----------------------------------------------------------------------------- runtime
def _simulate(m, runs, T, rng):
    """Plant simulation with random controls and a step in every fault (independent of the filter)."""
    u = rng.normal(size=(runs, T, m.B.shape[1]))
    f = np.zeros((runs, T, len(m.fault_names)))
    f[:, T // 2:, :] = rng.normal(size=(runs, 1, len(m.fault_names)))
    x = np.zeros((runs, m.n_states))
    y = np.empty((runs, T, m.n_outputs))
    for k in range(T):
        y[:, k] = x @ m.C.T + u[:, k] @ m.D.T + f[:, k] @ m.D_of("f").T
        x = x @ m.A.T + u[:, k] @ m.B.T + f[:, k] @ m.B_of("f").T
    return u, y, f


@pytest.mark.parametrize("kind", ["uio", "reduced"])
def test_batch_equals_streaming_bitwise(kind):
    rng = np.random.default_rng(31)
    m = _random_discrete(rng, 5, 2, 3, faults=["actuator:u0", "actuator:u1"])
    d = design_uio(m, "actuator:u0", ["actuator:u1"]) if kind == "uio" else \
        design_optimal_fdf(m, "actuator:u0", ["actuator:u1"], gamma=1e-6)
    runs, T = 3, 400
    u, y, _ = _simulate(m, runs, T, rng)
    t = np.arange(T) * m.dt
    sig = Signals(t, np.concatenate([u, y], axis=2), [*m.inputs, *m.outputs])
    gen = FaultDetectionFilter(d)
    batch = gen.run(sig).values
    gen.reset(runs)
    stream = np.stack([gen.step(u[:, k], y[:, k]) for k in range(T)], axis=1)
    np.testing.assert_array_equal(batch, stream)


def test_runtime_residual_matches_internal_form_simulation():
    """Filter driven by simulated plant data equals the internal form simulated directly."""
    rng = np.random.default_rng(32)
    m = _random_discrete(rng, 5, 2, 3, faults=["actuator:u0", "actuator:u1"])
    d = design_uio(m, "actuator:u0", ["actuator:u1"])
    runs, T = 2, 300
    u, y, f = _simulate(m, runs, T, rng)
    sig = Signals(np.arange(T) * m.dt, np.concatenate([u, y], axis=2), [*m.inputs, *m.outputs])
    r = FaultDetectionFilter(d).run(sig).values
    M = internal_form(d, m)
    z = np.zeros((runs, M.n_states))
    r2 = np.empty_like(r)
    for k in range(T):
        r2[:, k] = z @ M.C.T + u[:, k] @ M.D.T + f[:, k] @ M.D_of("f").T
        z = z @ M.A.T + u[:, k] @ M.B.T + f[:, k] @ M.B_of("f").T
    np.testing.assert_allclose(r, r2, atol=1e-9 * np.max(np.abs(r2)))
    # before the faults the (decoupled) residual is zero; after them the target drives it
    assert np.max(np.abs(r[:, : T // 2])) < 1e-9
    assert np.max(np.abs(r[:, T // 2:])) > 1e-3


def test_runtime_rejects_wrong_sample_rate():
    rng = np.random.default_rng(33)
    m = _random_discrete(rng, 3, 1, 2, faults=["actuator:u0"])
    d = design_optimal_fdf(m, "actuator:u0", [], gamma=1.0, reduce=None)
    sig = Signals(np.arange(10) * 0.02, np.zeros((10, 3)), [*m.inputs, *m.outputs])
    with pytest.raises(ModelError):
        FaultDetectionFilter(d).run(sig)


# ----------------------------------------------------------------------------- optimality and noise
def test_optimal_gain_minimises_the_stationary_error_covariance():
    """P from the Riccati equation is the stationary covariance of e = x - x_hat for the model with
    nuisance intensity Q2 / gamma, and no other gain L gives a smaller trace (brute force)."""
    rng = np.random.default_rng(41)
    m = _sensor_nuisance_system()
    Qw = np.diag(rng.uniform(0.1, 1.0, 5)) * 1e-3
    V = np.diag(rng.uniform(0.5, 2.0, 3)) * 1e-2
    gamma = 1e-3
    d = design_optimal_fdf(m, "actuator:u0", ["sensor:y0"], gamma=gamma, Qw=Qw, V=V, reduce=None)
    F2 = fault_directions(m, "sensor:y0")
    Q = Qw + F2 @ F2.T / gamma

    def sigma(L):
        Acl = m.A - L @ m.C
        return solve_discrete_lyapunov(Acl, Q + L @ V @ L.T)

    L = d.info["L"]
    S = sigma(L)
    np.testing.assert_allclose(S, d.info["P"], rtol=1e-7, atol=1e-9 * np.max(np.abs(S)))
    t0 = np.trace(S)
    for _ in range(20):
        dL = rng.normal(size=L.shape) * 1e-3 * np.max(np.abs(L))
        assert np.trace(sigma(L + dL)) > t0


def test_residual_covariance_matches_impulse_response_sum():
    rng = np.random.default_rng(42)
    m = _with_groups(_random_discrete(rng, 4, 1, 3, faults=["actuator:u0", "sensor:y2"]), rng, w=True)
    d = design_optimal_fdf(m, "actuator:u0", ["sensor:y2"], gamma=1e-4, reduce=None)
    R = residual_covariance(d, m)
    # brute force: sum_k h_k h_k' over the impulse response of noise -> residual (simulated)
    M = internal_form(d, m)
    Bw, Dw = M.B_of("w"), M.D_of("w")
    acc = Dw @ Dw.T
    X = Bw.copy()
    for _ in range(5000):
        h = M.C @ X
        acc += h @ h.T
        X = M.A @ X
    np.testing.assert_allclose(R, acc, rtol=1e-8, atol=1e-12)


def test_stacked_filters_equal_the_members():
    rng = np.random.default_rng(43)
    m = _random_discrete(rng, 5, 2, 3, faults=["actuator:u0", "actuator:u1"])
    fs = design_filter_set(m, ["actuator:u0", "actuator:u1"], method="optimal", gamma=1e-6)
    big = stack_designs(list(fs.values()))
    runs, T = 2, 200
    u, y, _ = _simulate(m, runs, T, rng)
    sig = Signals(np.arange(T) * m.dt, np.concatenate([u, y], axis=2), [*m.inputs, *m.outputs])
    parts = np.concatenate([FaultDetectionFilter(d).run(sig).values for d in fs.values()], axis=2)
    fused = FaultDetectionFilter(big).run(sig)
    assert fused.names == [s for d in fs.values() for s in d.residual_names]
    np.testing.assert_allclose(fused.values, parts, rtol=0, atol=1e-12 * np.max(np.abs(parts)))


def test_designs_carry_their_internal_form():
    m = _sensor_nuisance_system()
    for d in (design_optimal_fdf(m, "actuator:u0", ["sensor:y0"], gamma=1e-6),
              design_optimal_fdf(m, "actuator:u0", ["sensor:y0"], gamma=1e-6, reduce=None)):
        assert d.internal is not None and d.internal.n_states == m.n_states + d.order
        assert d.internal.outputs == d.residual_names and d.internal.fault_names == m.fault_names
        np.testing.assert_allclose(dc_gain(d.internal, "f"), dc_gain(internal_form(d, m), "f"), atol=1e-12)
    rng = np.random.default_rng(44)
    m2 = _random_discrete(rng, 4, 2, 3, faults=["actuator:u0", "actuator:u1"])
    d = design_uio(m2, "actuator:u0", ["actuator:u1"])
    assert np.max(np.abs(dc_gain(d.internal, "f")[:, 1])) < 1e-12


def test_unstable_nuisance_zero_rules_out_the_uio_but_not_the_optimal_filter():
    """Nuisance e2 with y1 = x1 + x2 has the invariant zero a = 1.2 (x1 moves, y does not): the
    UIO's unobservable mode of (C, A1) is unstable, yet the stochastic filter blocks the nuisance."""
    A = np.diag([1.2, 0.5, 0.3])
    C = np.array([[1.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    m = LinearFaultModel(A, [[0.0], [0.0], [1.0]], C, dt=0.1,
                         faults=["actuator:u0", ("n", [0.0, 1.0, 0.0], None)])
    with pytest.raises(ConditionError) as ei:
        design_uio(m, "actuator:u0", ["n"])
    assert ei.value.condition == "detectability of (C, A1)"
    d = design_optimal_fdf(m, "actuator:u0", ["n"], gamma=1e-8, reduce=None)
    np.testing.assert_allclose(d.info["nuisance_invariant_zeros"].real, [1.2], atol=1e-9)
    assert d.info["spectral_radius"] < 1
    worst, dc, _ = _ratio(d, m, "actuator:u0", ["n"])
    assert worst <= 1e-3 and dc <= 1e-3


# ----------------------------------------------------------------------------- output-space sensor faults
def _redundant_sensor_system():
    """Two sensors on the same state: C has rank 2 < 3 outputs, e2 is not in range(C)."""
    A = np.array([[0.95, 0.05, 0.0], [-0.04, 0.9, 0.1], [0.0, 0.02, 0.8]])
    B = np.array([[0.0], [0.0], [0.1]])
    C = np.array([[1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    return LinearFaultModel(A, B, C, dt=0.01, faults=["actuator:u0", "sensor:y1", "sensor:y2"])


@pytest.mark.parametrize("design", ["uio", "optimal"])
def test_sensor_nuisance_outside_range_of_C_is_projected_out(design):
    m = _redundant_sensor_system()
    E, Y = fault_direction_split(m, "sensor:y1")
    assert E.shape[1] == 0 and Y.shape[1] == 1
    with pytest.raises(ConditionError) as ei:
        fault_directions(m, "sensor:y1")
    assert ei.value.condition == "sensor direction"
    if design == "uio":
        with pytest.raises(ConditionError):
            design_uio(m, "actuator:u0", ["sensor:y1"], sensor="state")
        d = design_uio(m, "actuator:u0", ["sensor:y1"])
    else:
        d = design_optimal_fdf(m, "actuator:u0", ["sensor:y1"], gamma=1e-6, reduce=None)
    assert d.info["output_nuisance_directions"] == 1
    # the filter does not read y1 at all: its y1 columns are zero (P e2 = 0)
    np.testing.assert_allclose(d.By[:, 1], 0.0, atol=1e-12)
    np.testing.assert_allclose(d.Dy[:, 1], 0.0, atol=1e-12)
    G = frequency_response(internal_form(d, m), F_BAND, "f")
    assert np.max(np.abs(G[:, :, 1])) <= 1e-12 * np.max(np.abs(G[:, :, 0]))
    assert np.min(np.linalg.norm(G[:, :, 0], axis=1)) > 1e-3
    # the other sensor fault is still seen
    assert np.max(np.abs(G[:, :, 2])) > 1e-2


def test_output_treatment_of_an_in_range_sensor_fault_keeps_more_residuals():
    m = _sensor_nuisance_system()
    ds = design_optimal_fdf(m, "actuator:u0", ["sensor:y0"], gamma=1e-8, reduce=None, sensor="state")
    do = design_optimal_fdf(m, "actuator:u0", ["sensor:y0"], gamma=1e-8, reduce=None, sensor="output")
    assert len(ds.residual_names) == 1 and len(do.residual_names) == 2
    for d in (ds, do):
        worst, dc, _ = _ratio(d, m, "actuator:u0", ["sensor:y0"])
        assert worst <= 1e-3 and dc <= 1e-3
    # with the output treatment the sensor is simply not read
    np.testing.assert_allclose(do.By[:, 0], 0.0, atol=1e-12)
    np.testing.assert_allclose(do.Dy[:, 0], 0.0, atol=1e-12)


def test_internal_form_of_a_filter_reading_a_subset_of_channels():
    """A filter designed on a sub-model (three outputs of four) composed with the full model equals
    it composed with the sub-model, with zero response to the unread output's fault."""
    rng = np.random.default_rng(45)
    m = _random_discrete(rng, 5, 1, 4, faults=["actuator:u0", "sensor:y0", "sensor:y1", "sensor:y2"])
    sub = m.select_outputs(["y0", "y2", "y3"])
    d = design_uio(sub, "actuator:u0", ["sensor:y0"])
    G_sub = frequency_response(internal_form(d, sub), F_BAND, "f")
    G_full = frequency_response(internal_form(d, m), F_BAND, "f")
    np.testing.assert_allclose(G_full, G_sub, atol=1e-12 * np.max(np.abs(G_sub)))
    assert np.max(np.abs(G_full[:, :, 2])) == 0.0  # the fault on y1, which the filter does not read
    assert np.max(np.abs(G_full[:, :, 1])) <= 1e-12 * np.max(np.abs(G_full[:, :, 0]))
    with pytest.raises(ModelError):
        internal_form(d, LinearFaultModel(m.A, m.B, m.C, dt=m.dt, outputs=["a", "b", "c", "d"]))


def test_step_rejects_a_run_count_other_than_reset():
    m = _sensor_nuisance_system()
    gen = FaultDetectionFilter(design_optimal_fdf(m, "actuator:u0", ["sensor:y0"], gamma=1e-6))
    gen.reset(2)
    with pytest.raises(ModelError):
        gen.step(np.zeros((3, 2)), np.zeros((3, 3)))
