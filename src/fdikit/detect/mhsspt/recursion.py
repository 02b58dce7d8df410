"""The compiled log-domain Shiryayev recursion (:func:`mhsspt_update`, the step shared with the
fused car monitor) over many streams, and its outputs: posterior probabilities and
hypothesis-group sums.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

__all__ = ["NEGLIGIBLE_NATS", "mhsspt_update"]


#: Terms more than 40 nats below the largest are dropped from the log-sum-exp sums of the
#: recursion: exp(-40) = 4.2e-18, so 1 + exp(-40) rounds to 1 (a two-term log-sum-exp is then
#: bitwise the larger term) and even 26 such terms change a sum dominated by 1 by less than half
#: a unit in the last place. It saves the exp and log of every hypothesis far from the lead.
NEGLIGIBLE_NATS = 40.0


@njit(cache=True)
def _logaddexp(a, b):  # pragma: no cover - compiled
    """log(exp(a) + exp(b)); the smaller term dropped when it is below the larger's rounding."""
    if a < b:
        a, b = b, a
    if a == -np.inf:
        return -np.inf
    d = b - a
    if d < -NEGLIGIBLE_NATS:
        return a
    return a + math.log(1.0 + math.exp(d))


@njit(cache=True)
def mhsspt_update(logF, ll, phi, P, h0, h1, log1mp, logp_pi, logq, log1mq):  # pragma: no cover - compiled
    """One step of the log-domain Shiryayev recursion for hypotheses ``h0..h1-1`` (``h0`` is H0).

    ``logF`` (log posteriors) is updated in place from the log likelihoods ``ll``; ``P`` receives
    the posterior probabilities (0 for hypotheses more than :data:`NEGLIGIBLE_NATS` below the
    most probable); ``phi`` is scratch. Shared by :class:`MHSSPT` and the fused car monitor.

    Examples
    --------
    >>> logF, ll = np.array([0.0, -np.inf]), np.array([0.0, np.log(4.0)])
    >>> P = np.empty(2)
    >>> mhsspt_update(logF, ll, np.empty(2), P, 0, 2, np.log1p(-0.2), np.array([-np.inf, np.log(0.2)]),
    ...               -np.inf, 0.0)
    >>> P.round(6).tolist()          # (0.8 * 1, 0.2 * 4) / 1.6
    [0.5, 0.5]
    """
    # propagation (notes, residual-processing: phi_0, phi_j)
    if logq == -np.inf:  # q = 0: phi_0 = F_0 (1 - p) exactly
        phi[h0] = logF[h0] + log1mp
    else:
        m = -np.inf
        for j in range(h0 + 1, h1):
            if logF[j] > m:
                m = logF[j]
        lse_f = -np.inf
        if m > -np.inf:
            sf = 0.0
            for j in range(h0 + 1, h1):
                x = logF[j] - m
                if x > -NEGLIGIBLE_NATS:
                    sf += math.exp(x)
            lse_f = m + math.log(sf)
        phi[h0] = _logaddexp(logF[h0] + log1mp, logq + lse_f)
    lf0 = logF[h0]
    for j in range(h0 + 1, h1):
        phi[j] = _logaddexp(logF[j] + log1mq, lf0 + logp_pi[j])
    # Bayes update and normalisation
    m = -np.inf
    for j in range(h0, h1):
        phi[j] += ll[j]
        if phi[j] > m:
            m = phi[j]
    s = 0.0
    for j in range(h0, h1):
        x = phi[j] - m
        if x > -NEGLIGIBLE_NATS:
            e = math.exp(x)
            P[j] = e
            s += e
        else:
            P[j] = 0.0
    lz = m + math.log(s)
    for j in range(h0, h1):
        logF[j] = phi[j] - lz
        P[j] = P[j] / s


@njit(cache=True)
def _mhsspt_recursion_stream(r, loglik, logF, log1mp, logp_pi, logq, log1mq, out):  # pragma: no cover
    """Stream ``r``: loglik[r] (T, H) -> out[r] log posteriors; logF[r] updated in place."""
    T, H = loglik.shape[1], loglik.shape[2]
    phi = np.empty(H)
    P = np.empty(H)
    lf = logF[r]
    for k in range(T):
        mhsspt_update(lf, loglik[r, k], phi, P, 0, H, log1mp, logp_pi, logq, log1mq)
        for j in range(H):
            out[r, k, j] = lf[j]


@njit(cache=True)
def _mhsspt_recursion(loglik, logF, log1mp, logp_pi, logq, log1mq, out):  # pragma: no cover
    """loglik (R, T, H) -> out (R, T, H) log posteriors; logF (R, H) is updated in place; streams in turn."""
    for r in range(loglik.shape[0]):
        _mhsspt_recursion_stream(r, loglik, logF, log1mp, logp_pi, logq, log1mq, out)


@njit(cache=True, parallel=True)
def _mhsspt_recursion_parallel(loglik, logF, log1mp, logp_pi, logq, log1mq, out):  # pragma: no cover
    """As :func:`_mhsspt_recursion`, streams in parallel threads (the same arithmetic per stream)."""
    for r in prange(loglik.shape[0]):
        _mhsspt_recursion_stream(r, loglik, logF, log1mp, logp_pi, logq, log1mq, out)


@njit(cache=True)
def _emit(o, P, lf, gmat, probs):  # pragma: no cover - compiled
    """One sample's outputs of a fused table kernel: the normalised posteriors the update just
    formed, then the group sums (``probs``: no second exp per hypothesis), or the log posteriors."""
    H = lf.shape[0]
    if probs:
        for j in range(H):
            o[j] = P[j]
        for g in range(gmat.shape[0]):
            acc = 0.0
            for e in range(gmat.shape[1]):
                if gmat[g, e] >= 0:
                    acc += o[gmat[g, e]]
            o[H + g] = acc
    else:
        for j in range(H):
            o[j] = lf[j]


@njit(cache=True)
def _probabilities_row(L, gmat, out, n):  # pragma: no cover - compiled
    """Row n: exp of the log posteriors (0 below exp's range, as exp itself gives), then group sums."""
    H = L.shape[1]
    for j in range(H):
        v = L[n, j]
        out[n, j] = math.exp(v) if v > -746.0 else 0.0
    for g in range(gmat.shape[0]):
        acc = 0.0
        for e in range(gmat.shape[1]):
            if gmat[g, e] >= 0:
                acc += out[n, gmat[g, e]]
        out[n, H + g] = acc


@njit(cache=True)
def _probabilities(L, gmat, out):  # pragma: no cover - compiled
    """Posterior probabilities and group sums: L (N, H) log posteriors -> out (N, H + G)."""
    for n in range(L.shape[0]):
        _probabilities_row(L, gmat, out, n)


@njit(cache=True, parallel=True)
def _probabilities_parallel(L, gmat, out):  # pragma: no cover - compiled
    """As :func:`_probabilities`, rows in parallel threads."""
    for n in prange(L.shape[0]):
        _probabilities_row(L, gmat, out, n)
