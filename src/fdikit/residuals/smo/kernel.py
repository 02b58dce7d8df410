"""Compiled kernels of the SMO runtime: one observer step with the switched term (24), the sliding
status of an observer, and the fixed-step integration of the primary and secondary observers."""

from __future__ import annotations

import numpy as np
from numba import njit


def _mv_py(A, x, out, add):
    """``out = A x`` (``add=False``) or ``out += A x``; no allocation."""
    for i in range(A.shape[0]):
        acc = 0.0
        for j in range(A.shape[1]):
            acc += A[i, j] * x[j]
        out[i] = out[i] + acc if add else acc


# The helpers are plain njit functions, not numba-IR inlined (``inline="always"``): IR inlining of
# the two observer steps and statuses made a cold compile of the runtime cost about 37 CPU s
# (issue 31, n = 60 budget); LLVM inlines them anyway, and the results are bitwise the same.
_mv = njit(cache=True)(_mv_py)


def _smo_step_py(h, A, B, C, Gl, Gn, rho, delta, SV, Smu, u, y, x, e, started, nu, dx, xt, w, wt,
                 implicit):
    """One step of ``x' = A x + B u - Gl e + Gn nu``, ``nu = -rho e / (||e|| + delta)``.

    Explicit Euler for the linear part; the switched term (24) is taken at the new time
    (implicit): with ``S = C Gn = Po^-1`` s.p.d. (``S = SV diag(Smu) SV^T``) and
    ``w = C (x + h (A x + B u - Gl e)) - y_new``, solve ``e+ = w - h rho S e+ / (||e+|| + delta)``
    for ``s = ||e+||`` by a safeguarded Newton iteration (bracket ``[0, ||w||]``, unique root).
    On the first sample the state is kept and ``e = C x - y``. ``dx, xt, w, wt`` are work arrays.

    With ``implicit=False`` the plain explicit Euler step is used instead: ``e = C x - y`` and
    ``nu(e)`` from the current state (output), then ``x += h (A x + B u - Gl e + Gn nu)``.
    """
    n, p = A.shape[0], C.shape[0]
    if not implicit:
        _mv(C, x, e, False)
        ne = 0.0
        for i in range(p):
            e[i] -= y[i]
            ne += e[i] * e[i]
        ne = np.sqrt(ne)
        for i in range(p):
            nu[i] = -rho * e[i] / (ne + delta)  # ng-tan-edwards-kuang, eq. (24)
        _mv(A, x, dx, False)
        _mv(Gn, nu, dx, True)
        for i in range(n):
            acc = 0.0
            for j in range(p):
                acc += Gl[i, j] * e[j]
            dx[i] -= acc
        if B.shape[1] > 0:
            _mv(B, u, dx, True)
        for i in range(n):
            x[i] += h * dx[i]
        return
    if started:
        _mv(A, x, dx, False)
        for i in range(n):
            acc = 0.0
            for j in range(p):
                acc += Gl[i, j] * e[j]
            dx[i] -= acc
        if B.shape[1] > 0:
            _mv(B, u, dx, True)
        for i in range(n):
            xt[i] = x[i] + h * dx[i]
        hh = h
    else:
        for i in range(n):
            xt[i] = x[i]
        hh = 0.0
    _mv(C, xt, w, False)
    nw2 = 0.0
    for i in range(p):
        w[i] -= y[i]
    for i in range(p):
        acc = 0.0
        for j in range(p):
            acc += SV[j, i] * w[j]
        wt[i] = acc
        nw2 += acc * acc
    nw = np.sqrt(nw2)
    if hh > 0.0 and nw > 0.0:
        g = hh * rho
        lo, hi = 0.0, nw
        # start: root of the scalar problem with the smallest eigenvalue (an upper bound)
        mu0 = Smu[0]
        b = delta + g * mu0 - nw
        s = 0.5 * (-b + np.sqrt(b * b + 4.0 * nw * delta))
        for _ in range(100):
            c = g / (s + delta)
            n2 = 0.0
            dn = 0.0
            for i in range(p):
                d = 1.0 + c * Smu[i]
                z = wt[i] / d
                n2 += z * z
                dn += z * z * Smu[i] / d
            N = np.sqrt(n2)
            F = s - N
            if F > 0.0:
                hi = s
            else:
                lo = s
            if abs(F) <= 1e-14 * (nw + delta) or hi - lo <= 1e-15 * (nw + delta):
                break
            dF = 1.0 - (dn * c / (s + delta)) / N if N > 0.0 else 1.0
            sn = s - F / dF if dF > 0.0 else -1.0
            if not (lo < sn < hi):
                sn = 0.5 * (lo + hi)
            s = sn
        c = g / (s + delta)
        for i in range(p):
            wt[i] = wt[i] / (1.0 + c * Smu[i])
        _mv(SV, wt, e, False)
    else:
        for i in range(p):
            e[i] = w[i]
    ne = 0.0
    for i in range(p):
        ne += e[i] * e[i]
    ne = np.sqrt(ne)
    for i in range(p):
        nu[i] = -rho * e[i] / (ne + delta)  # ng-tan-edwards-kuang, eq. (24)
    if started:
        _mv(Gn, nu, dx, True)
        for i in range(n):
            x[i] += h * dx[i]


_smo_step = njit(cache=True)(_smo_step_py)


def _status_py(e, SV, Smu, delta, level, Vprev, started, settle_n, e_old, h, rho, tlevel,
               thold=0.0):
    """Sliding status of one observer after its step; updates ``Vprev`` (``[e^T Po e, hold]``).

    ``SLIDING`` while ``||nu|| / rho = ||e|| / (||e|| + delta) <= level`` (inside the boundary
    layer); otherwise ``NOT_SLIDING`` while the Lyapunov function ``e^T Po e`` (``Po = S^-1``)
    decreases (reaching) and ``SATURATED`` when it does not (the injection is at its cap and
    cannot hold the error). After a sample outside the layer, the status stays ``NOT_SLIDING``
    for ``settle_n`` more samples inside it (``Vprev[1]`` counts them down): the reduced-order
    error that a loss of sliding leaves decays only with the sliding motion, so ``fhat`` is the
    equivalent injection again before it is the fault again.

    Transients inside the layer. The injection of a step is ``nu = nu_eq + Po (e+ - e) / h``
    (``nu_eq`` keeps the error where it is): while the error moves inside the layer (the reaching
    after a fault jump, faster than the layer can follow), ``nu`` and so ``fhat`` are not yet the
    equivalent injection. A step with ``||Po (e+ - e)|| / h > tlevel * rho`` (``e_old`` is the
    error before the step) is ``NOT_SLIDING`` too (``tlevel = 0``: off). It holds the status
    ``NOT_SLIDING`` for ``thold`` more samples (not the ``settle_n`` of a loss of the layer: the
    reduced-order error such a transient leaves is small): the move falls geometrically after a
    jump and the estimate is still a few per cent off for a sample or two after the move drops
    under ``tlevel`` (issue 31, random system 31: 5.7 % and 5.4 % at the release).

    Jumps of the injection itself. With a thin layer (``delta`` 1e-8 or below) the error barely
    moves inside it while ``nu_eq`` (and so ``fhat``) still takes a sample or two to follow a fault
    jump (the sampled plant delivers the jump's effect over two steps). A step whose injection
    ``nu = -rho e / (||e|| + delta)`` moves by more than ``tlevel * rho``
    (``||nu(e) - nu(e_old)||``) is ``NOT_SLIDING`` as well; a smooth fault moves it by orders
    of magnitude less per step. A disturbance fast enough to move the injection as much per
    step (``xi`` above about 1e3 rad/s at ``h = 1e-5`` on random systems) is flagged the same way:
    conservative, the estimate is not wrong there.
    """
    p = e.shape[0]
    if p == 0:
        return 0
    ne = 0.0
    V = 0.0
    dv = 0.0
    for i in range(p):
        ne += e[i] * e[i]
        acc = 0.0
        dacc = 0.0
        for j in range(p):
            acc += SV[j, i] * e[j]
            dacc += SV[j, i] * (e[j] - e_old[j])
        V += acc * acc / Smu[i]
        dacc /= Smu[i]
        dv += dacc * dacc
    ne = np.sqrt(ne)
    code = 0
    moving = started and tlevel > 0.0 and np.sqrt(dv) > tlevel * rho * h
    if started and tlevel > 0.0 and not moving:
        no = 0.0
        for i in range(p):
            no += e_old[i] * e_old[i]
        no = np.sqrt(no)
        dn = 0.0
        for i in range(p):
            d = e[i] / (ne + delta) - e_old[i] / (no + delta)
            dn += d * d
        moving = np.sqrt(dn) > tlevel
    if ne > level * (ne + delta):
        code = 1 if (not started or V < Vprev[0]) else 2
        Vprev[1] = settle_n
    elif moving:
        code = 1
        if Vprev[1] < thold:
            Vprev[1] = thold
    elif Vprev[1] > 0.0:
        Vprev[1] -= 1.0
        code = 1
    Vprev[0] = V
    return code


_status = njit(cache=True)(_status_py)


def _kernel_py(h, cascade, A1, B1, C1, Gl1, Gn1, rho1, del1, S1V, S1mu, Tv, r, Zsel, Af,
               A2, B2, C2, Gl2, Gn2, rho2, del2, S2V, S2mu, Wf,
               U, Y, x1, e1, x2, e2, vf, started, out, implicit, level, a_lp, flp, V1p, V2p,
               settle_n, tlevel, thold):
    """Fixed-step integration of the primary and secondary (or single) observers.

    Per sample ``k``: primary step with ``y[k]`` -> ``nu`` (15)-(18), (24); ``v = T^T Po^-1 nu``
    (23); ``ybar = [Z v1; v_f]`` with ``v_f`` advanced by Euler (27)-(28); secondary step with
    ``ybar`` (37)-(39); ``f^ = Wf nubar``, low-passed by ``flp = a_lp flp + (1 - a_lp) f^`` when
    ``a_lp > 0``. ``out[run, k]`` holds ``q`` reconstructions, then the combined, primary and
    secondary sliding status (:func:`_status`; ``tlevel`` its transient level, ``thold`` the
    samples a transient is held).
    """
    runs, T = Y.shape[0], Y.shape[1]
    n1, p1 = A1.shape[0], C1.shape[0]
    n2, p2 = A2.shape[0], C2.shape[0]
    q = Wf.shape[0]
    pr = p1 - r
    ybar = np.zeros(p2)
    nu1 = np.zeros(p1)
    nu2 = np.zeros(p2)
    v = np.zeros(p1)
    dx1, xt1, w1, wt1 = np.zeros(n1), np.zeros(n1), np.zeros(p1), np.zeros(p1)
    dx2, xt2, w2, wt2 = np.zeros(n2), np.zeros(n2), np.zeros(p2), np.zeros(p2)
    dvf = np.zeros(r)
    eo1, eo2 = np.zeros(p1), np.zeros(p2)
    for run in range(runs):
        for k in range(T):
            u = U[run, k]
            st0 = started[run]
            c1 = 0
            for i in range(p1):
                eo1[i] = e1[run, i]
            for i in range(p2):
                eo2[i] = e2[run, i]
            if cascade:
                _smo_step(h, A1, B1, C1, Gl1, Gn1, rho1, del1, S1V, S1mu, u, Y[run, k],
                          x1[run], e1[run], st0, nu1, dx1, xt1, w1, wt1,
                          implicit)
                c1 = _status(e1[run], S1V, S1mu, del1, level, V1p[run], st0, settle_n, eo1, h, rho1,
                             tlevel, thold)
                _mv(Tv, nu1, v, False)  # ng-tan-edwards-kuang, eq. (23)
                for i in range(Zsel.shape[0]):
                    ybar[i] = v[Zsel[i]]  # ng-tan-edwards-kuang, eq. (27)
                if r > 0:
                    if st0:
                        for i in range(r):
                            acc = 0.0
                            for j in range(r):
                                acc += Af[i, j] * (v[pr + j] - vf[run, j])
                            dvf[i] = acc
                        for i in range(r):
                            vf[run, i] += h * dvf[i]  # ng-tan-edwards-kuang, eq. (28)
                    for i in range(r):
                        ybar[p2 - r + i] = vf[run, i]
                _smo_step(h, A2, B2, C2, Gl2, Gn2, rho2, del2, S2V, S2mu, u, ybar,
                          x2[run], e2[run], st0, nu2, dx2, xt2, w2, wt2,
                          implicit)
            else:
                _smo_step(h, A2, B2, C2, Gl2, Gn2, rho2, del2, S2V, S2mu, u, Y[run, k],
                          x2[run], e2[run], st0, nu2, dx2, xt2, w2, wt2,
                          implicit)
            c2 = _status(e2[run], S2V, S2mu, del2, level, V2p[run], st0, settle_n, eo2, h, rho2,
                         tlevel, thold)
            started[run] = True
            for i in range(q):
                acc = 0.0
                for j in range(p2):
                    acc += Wf[i, j] * nu2[j]
                # f^ = W Tbar^-1 Pobar^-1 nubar_eq
                if a_lp > 0.0:
                    if st0:
                        flp[run, i] = a_lp * flp[run, i] + (1.0 - a_lp) * acc
                    else:
                        flp[run, i] = acc
                    out[run, k, i] = flp[run, i]
                else:
                    out[run, k, i] = acc
            out[run, k, q] = float(max(c1, c2))
            out[run, k, q + 1] = float(c1)
            out[run, k, q + 2] = float(c2)


_kernel = njit(cache=True)(_kernel_py)
