"""The secondary SMO LMIs (46)-(47) in their reduced form (issue 31: large plants): the same
program with smaller cones, checked against the full LMIs evaluated at the returned point."""

import warnings

import numpy as np
import pytest

from fdikit.design import smo_lmi
from fdikit.errors import DataError
from fdikit.model.random_systems import as_fault_model, random_fault_system
from fdikit.residuals.smo import design_reconstructor


@pytest.fixture(scope="module")
def secondary_system():
    A, M, C, Q = random_fault_system(2)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rec = design_reconstructor(as_fault_model(A, M, C, Q), check=False, hinf_check=False)
    fs = rec.details["fictitious"]
    return fs.A, fs.M, fs.C, fs.Q, 10.0 * np.eye(fs.C.shape[0]), rec.info["gamma_o"]


def _full_lmis(A, M, C, Q, D1, gamma_o, g):
    """Largest eigenvalues of (46), of (47) with its D1 rows, and smallest of P and P11 (numpy)."""
    nb, pb = A.shape[0], C.shape[0]
    q, h = M.shape[1], Q.shape[1]
    k = nb - pb
    P, W = g.P, g.W
    A1, A3, Q1, Q2 = A[:k, :k], A[k:, :k], Q[:k], Q[k:]
    P11, P12 = P[:k, :k], P[:k, k:]
    blk = P11 @ A1 + A1.T @ P11 + P12 @ A3 + A3.T @ P12.T
    L46 = np.block([[blk, -(P11 @ Q1 + P12 @ Q2), -(W @ A3).T],
                    [-(P11 @ Q1 + P12 @ Q2).T, -g.gamma * np.eye(h), (W @ Q2).T],
                    [-(W @ A3), W @ Q2, -g.gamma * np.eye(q)]])
    Dd = np.hstack([D1, np.zeros((pb, h))])
    Bd = np.hstack([np.zeros((nb, pb)), Q])
    R = np.linalg.inv(Dd @ Dd.T)
    E = np.hstack([-(W @ A3), np.zeros((q, pb))])
    H = np.hstack([np.zeros((q, pb)), W @ Q2])
    L47 = np.block([[P @ A + A.T @ P - gamma_o * C.T @ R @ C, -(P @ Bd), E.T],
                    [-(P @ Bd).T, -gamma_o * np.eye(pb + h), H.T],
                    [E, H, -gamma_o * np.eye(q)]])
    ev = [np.linalg.eigvalsh(0.5 * (X + X.T)) for X in (L46, L47, P, P11)]
    return ev[0].max(), ev[1].max(), ev[2].min(), ev[3].min()


def test_reduced_form_meets_the_full_lmis_with_the_same_gamma(secondary_system):
    A, M, C, Q, D1, go = secondary_system
    full = smo_lmi.secondary_smo_lmi(A, M, C, Q, D1=D1, gamma_o=go, form="full")
    red = smo_lmi.secondary_smo_lmi(A, M, C, Q, D1=D1, gamma_o=go, form="reduced")
    assert full.solver["form"] == "full" and red.solver["form"] == "reduced"
    eps = 1e-7
    m46, m47, pmin, p11min = _full_lmis(A, M, C, Q, D1, go, red)
    # the full (46)-(47), P > 0 and P11 > 0 hold at the reduced solution (margin eps / 2)
    assert m46 <= -eps / 2 and m47 <= -eps / 2 and pmin >= eps / 2 and p11min >= eps / 2
    # the same program: the same optimum (to the solver's accuracy on a degenerate optimum)
    assert red.gamma == pytest.approx(full.gamma, rel=0.05, abs=1e-6)
    assert np.linalg.eigvals(A - red.Gl @ C).real.max() < 0


def test_auto_keeps_the_full_form_on_small_plants(secondary_system):
    A, M, C, Q, D1, go = secondary_system
    assert A.shape[0] <= smo_lmi.SECONDARY_FULL_MAX_STATES
    auto = smo_lmi.secondary_smo_lmi(A, M, C, Q, D1=D1, gamma_o=go)
    full = smo_lmi.secondary_smo_lmi(A, M, C, Q, D1=D1, gamma_o=go, form="full")
    assert auto.solver["form"] == "full" and auto.gamma == full.gamma  # bitwise


def test_a_bad_form_is_named(secondary_system):
    A, M, C, Q, D1, go = secondary_system
    with pytest.raises(DataError, match="form must be"):
        smo_lmi.secondary_smo_lmi(A, M, C, Q, D1=D1, gamma_o=go, form="fast")
