"""N4SID / PO-MOESP subspace identification pooled over many records.

The arithmetic is that of the maintained ``nfoursid`` package (Verhaegen & Verdult, *Filtering and
system identification*, pp. 329 and 333): block Hankel matrices of the inputs and outputs, the QR
factor of ``[U_f; U_p; Y_p; Y_f]``, the estimate ``R32 R22^+ [U; Y]`` of the extended observability
times the state sequence, its SVD, and the least-squares fit of ``[x+; y]`` on ``[x; u]`` whose
residual covariance gives the noise covariances ``Q``, ``R``, ``S``. ``nfoursid`` takes one
uniform record; here the Hankel columns of every record are put side by side and the state
regression pairs samples of one record only, so no column spans the boundary of two records.
With one record the numbers are those of ``nfoursid``'s ``NFourSID``.
"""

from __future__ import annotations

import numpy as np

from .records import Segment

__all__ = ["block_rows_fit", "n4sid_pooled", "samples_needed"]


def samples_needed(i: int, channels: int, records: int = 1) -> int:
    """Pooled samples N4SID needs for ``i`` block rows of ``channels`` inputs+outputs: Hankel
    columns at least twice its ``2 i channels`` rows, plus a margin (``4 i channels + 10`` for one
    record; every further record loses ``2 i - 1`` columns at its ends)."""
    return 4 * i * channels + 10 + (records - 1) * (2 * i - 1)


def block_rows_fit(samples: int, channels: int, records: int, wanted: int) -> int:
    """The largest number of block rows ``<= wanted`` the pooled samples support (0 if none)."""
    for i in range(wanted, 0, -1):
        if samples >= samples_needed(i, channels, records):
            return i
    return 0


def n4sid_pooled(segs: list[Segment], orders: list[int], block_rows: int):
    """Models of every order in ``orders`` from the pooled records.

    Returns
    -------
    models : dict
        order -> ``(A, B, C, D, Q, R, S)``; ``Q`` (n, n), ``R`` (p, p), ``S`` (n, p) the covariances
        of the state and output residuals of the fit (``cov([w; v]) = [[Q, S], [S', R]]``).
    singular_values : ndarray
        Singular values of ``R32`` (order selection by their gap).
    """
    from nfoursid.utils import Utils

    i = block_rows
    uh = [Utils.block_hankel_matrix(s.u, i) for s in segs]
    yh = [Utils.block_hankel_matrix(s.y, i) for s in segs]
    u_past = np.concatenate([h[:, :-i] for h in uh], axis=1)
    u_future = np.concatenate([h[:, i:] for h in uh], axis=1)
    y_past = np.concatenate([h[:, :-i] for h in yh], axis=1)
    y_future = np.concatenate([h[:, i:] for h in yh], axis=1)
    u_instrumental_y = np.concatenate([u_future, u_past, y_past, y_future])
    _q, r = map(lambda matrix: matrix.T, np.linalg.qr(u_instrumental_y.T, mode="reduced"))
    p, m = segs[0].y.shape[1], segs[0].u.shape[1]
    y_rows, u_rows = p * i, m * i
    R32 = r[-y_rows:, u_rows:-y_rows]
    R22 = r[u_rows:-y_rows, u_rows:-y_rows]
    sv = np.linalg.svd(R32)[1]                                  # as nfoursid's R32 decomposition
    # nfoursid recomputes a full SVD of the observability estimate for every order; its singular
    # vectors do not depend on the order, so one economy SVD serves all orders
    obs = R32 @ np.linalg.pinv(R22) @ np.concatenate([np.concatenate(uh, axis=1), np.concatenate(yh, axis=1)])
    _u, s, Vh = np.linalg.svd(obs, full_matrices=False)
    bounds = np.cumsum([0] + [h.shape[1] for h in uh])
    models = {}
    for n in orders:
        x_all = np.diag(np.power(s[:n], 0.5)) @ Vh[:n]
        xy, xu = [], []
        for k, sg in enumerate(segs):
            x = x_all[:, bounds[k]:bounds[k + 1]][:, :-1]
            last_y, last_u = sg.y[i:, :].T, sg.u[i:, :].T
            xy.append(np.concatenate([x[:, 1:], last_y[:, :-1]]))
            xu.append(np.concatenate([x[:, :-1], last_u[:, :-1]]))
        x_and_y = np.concatenate(xy, axis=1)
        x_and_u = np.concatenate(xu, axis=1)
        abcd = (np.linalg.pinv(x_and_u @ x_and_u.T) @ x_and_u @ x_and_y.T).T
        residuals = x_and_y - abcd @ x_and_u
        cov = residuals @ residuals.T / residuals.shape[1]
        cov = (cov + cov.T) / 2
        models[n] = (abcd[:n, :n], abcd[:n, n:], abcd[n:, :n], abcd[n:, n:], cov[:n, :n], cov[n:, n:],
                     cov[:n, n:])
    return models, sv
