"""The C of a monitor's plausibility rules (:class:`~fdikit.monitor.plausibility.PlausibilityChecker`):
range, rate and spike tests judged before any state changes, the last valid sample, the
predecessor and the ring buffer of increments as state, in the Python checker's order of
floating-point operations (medians of the sorted window, the mean of the two middle values)."""

from __future__ import annotations

from typing import Any

import numpy as np

from ..errors import DataError
from .stages import Field, lit

__all__ = ["PlausibilityEmitter", "plausibility_from_py", "plausibility_to_py"]

#: The median of ``n`` values (sorted in place, insertion sort: no recursion) as numpy forms it.
MEDIAN_HELPER = """
static double fdk_median(double *a, int n)
{
    int i, j;
    double v;
    for (i = 1; i < n; ++i) {
        v = a[i];
        for (j = i - 1; j >= 0 && a[j] > v; --j) a[j + 1] = a[j];
        a[j + 1] = v;
    }
    if (n % 2) return a[n / 2];
    return (a[n / 2 - 1] + a[n / 2]) / 2.0;
}

/* 1.4826 MAD of w[0..n) about med; where it is 0, 1.4826 times the median of the non-zero
   deviations (fdikit.monitor.plausibility._robust_scale); dev is scratch of n values */
static double fdk_robust_scale(const double *w, int n, double med, double *dev)
{
    int i, m = 0;
    double s;
    for (i = 0; i < n; ++i) dev[i] = fabs(w[i] - med);
    s = 1.4826 * fdk_median(dev, n);
    if (s != 0.0) return s;
    for (i = 0; i < n; ++i) if (dev[i] > 0.0) dev[m++] = dev[i];
    return m ? 1.4826 * fdk_median(dev, m) : 0.0;
}
"""


class PlausibilityEmitter:
    """The plausibility rules of a :class:`~fdikit.monitor.Monitor` (its ``_checker``) as C.

    Parameters
    ----------
    checker : PlausibilityChecker
        The monitor's checker (one run).
    dt : float
        The monitor's sample period (the spike test's ``n``).
    """

    def __init__(self, checker: Any, dt: float):
        self.obj = checker
        self.dt = float(dt)
        self.C = len(checker.names)
        self.S = int(checker.spike_idx.size)
        self.W = int(checker.W)
        #: the median helpers only where a spike rule needs them (an unused static function is a
        #: warning, an error under -Werror)
        self.helpers = MEDIAN_HELPER if self.S else ""

    def f(self, name: str) -> str:
        return f"s->pl_{name}"

    def fields(self) -> list[Field]:
        return [Field("pl_ref", "f64", self.C), Field("pl_t_ref", "f64", 1), Field("pl_prev", "f64", self.C),
                Field("pl_t_prev", "f64", 1), Field("pl_prev_ok", "i64", 1),
                Field("pl_win", "f64", max(self.S * max(self.W, 1), 1)), Field("pl_n_win", "i64", 1)]

    def reset_code(self) -> str:
        f = self.f
        return "\n".join([
            f"    for (i = 0; i < {self.C}; ++i) {{ {f('ref')}[i] = NAN; {f('prev')}[i] = NAN; }}",
            f"    {f('t_ref')}[0] = NAN; {f('t_prev')}[0] = NAN; {f('prev_ok')}[0] = 0; {f('n_win')}[0] = 0;",
            f"    for (i = 0; i < {max(self.S * max(self.W, 1), 1)}; ++i) {f('win')}[i] = 0.0;"])

    def check_code(self) -> str:
        """Statements setting ``invalid = 1`` when the (finite) sample ``x`` at ``t`` breaks a
        rule; no state changes (:meth:`PlausibilityChecker.check`)."""
        ck, f = self.obj, self.f
        lines = ["    if (!invalid) {"]
        for c in range(self.C):
            if np.isfinite(ck.lo[c]):
                lines.append(f"        if (x[{c}] < {lit(ck.lo[c])}) invalid = 1;")
            if np.isfinite(ck.hi[c]):
                lines.append(f"        if (x[{c}] > {lit(ck.hi[c])}) invalid = 1;")
        if ck.sequential:
            lines.append(f"        int prev_usable = isfinite({f('t_prev')}[0]);")
        if ck.rate_idx.size:
            lines += [f"        if (!invalid && isfinite({f('t_ref')}[0])) {{",
                      f"            double el = t - {f('t_ref')}[0];"]
            for c in ck.rate_idx:
                lim = lit(ck.rate[c])
                lines += [f"            if (fabs(x[{c}] - {f('ref')}[{c}]) > {lim} * el && !(prev_usable && "
                          f"fabs(x[{c}] - {f('prev')}[{c}]) <= {lim} * (t - {f('t_prev')}[0]))) invalid = 1;"]
            lines.append("        }")
        if self.S:
            W = self.W
            lines += [f"        if (!invalid && prev_usable && {f('n_win')}[0] >= {W} "
                      f"&& isfinite({f('t_ref')}[0])) {{",
                      f"            double seg[{W}], dev[{W}], med, sc, lim, n;",
                      "            int i, o;",
                      f"            n = nearbyint((t - {f('t_ref')}[0]) / {lit(self.dt)});",
                      "            if (!(n >= 1.0)) n = 1.0;"]
            for j, (c, k, w) in enumerate(zip(ck.spike_idx, ck.spike_k, ck.spike_w)):
                w = int(w)
                # the channel's last w increments (oldest first: the ring's order does not matter
                # to a median)
                lines += [f"            for (i = 0; i < {w}; ++i) "
                          f"{{ o = (int)(({f('n_win')}[0] - {w} + i) % {W}); "
                          f"seg[i] = {f('win')}[{j * W} + o]; }}",
                          f"            med = fdk_median(seg, {w});",
                          f"            sc = fdk_robust_scale(seg, {w}, med, dev);",
                          f"            lim = {lit(k)} * sc;",
                          f"            if (fabs(x[{c}] - {f('prev')}[{c}] - med) > lim && "
                          f"fabs(x[{c}] - {f('ref')}[{c}] - n * med) > lim * sqrt(n) && sc > 0.0) "
                          "invalid = 1;"]
            lines.append("        }")
        lines.append("    }")
        return "\n".join(lines)

    def gap_code(self) -> str:
        """Samples are missing before this one: its predecessor is unusable."""
        return f"        {self.f('t_prev')}[0] = NAN; {self.f('prev_ok')}[0] = 0;"

    def observe_code(self) -> str:
        """Record the sample (``invalid`` tells whether it was accepted), as
        :meth:`PlausibilityChecker.observe`."""
        f, C, W = self.f, self.C, self.W
        lines = ["    {", "        int i, finite = 1;", "        if (!invalid) {"]
        if self.S:
            lines += [f"            if ({f('prev_ok')}[0] && isfinite({f('t_prev')}[0])) {{",
                      f"                int o = (int)({f('n_win')}[0] % {W});"]
            lines += [f"                {f('win')}[{j * W} + o] = x[{c}] - {f('ref')}[{c}];"
                      for j, c in enumerate(self.obj.spike_idx)]
            lines += [f"                {f('n_win')}[0] += 1;", "            }"]
        lines += [f"            for (i = 0; i < {C}; ++i) {f('ref')}[i] = x[i];",
                  f"            {f('t_ref')}[0] = t;", "        }",
                  f"        for (i = 0; i < {C}; ++i) "
                  f"{{ if (!isfinite(x[i])) finite = 0; {f('prev')}[i] = x[i]; }}",
                  f"        {f('t_prev')}[0] = finite ? t : NAN;",
                  f"        {f('prev_ok')}[0] = !invalid;", "    }"]
        return "\n".join(lines)

    def layout(self) -> dict[str, Any]:
        """What the harness needs to map the C state to :meth:`PlausibilityChecker.state`."""
        return {"spike_channels": self.S, "W": self.W, "dt": self.dt}


def plausibility_to_py(info: dict[str, Any], arrays: dict[str, np.ndarray]) -> dict[str, Any]:
    """The ``pl_*`` fields of a C checkpoint as :meth:`PlausibilityChecker.state` (one run);
    ``info`` is the layout's ``plausibility`` entry."""
    S, W1 = int(info["spike_channels"]), max(int(info["W"]), 1)
    win = arrays["pl_win"][:S * W1].astype(float).reshape(1, S, W1)
    return {"ref": arrays["pl_ref"].astype(float).reshape(1, -1), "t_ref": float(arrays["pl_t_ref"][0]),
            "prev": arrays["pl_prev"].astype(float).reshape(1, -1), "t_prev": float(arrays["pl_t_prev"][0]),
            "prev_ok": bool(arrays["pl_prev_ok"][0]), "win": win, "n_win": int(arrays["pl_n_win"][0]),
            "dt": float(info["dt"]), "runs": 1}


def plausibility_from_py(state: dict[str, Any]) -> dict[str, np.ndarray]:
    """:meth:`PlausibilityChecker.state` (one run) as the ``pl_*`` fields of a C checkpoint."""
    if int(state["runs"]) != 1:
        raise DataError(f"the generated monitor holds one run; the plausibility state has {state['runs']}")
    return {"pl_ref": np.ravel(state["ref"]), "pl_t_ref": np.array([state["t_ref"]]),
            "pl_prev": np.ravel(state["prev"]), "pl_t_prev": np.array([state["t_prev"]]),
            "pl_prev_ok": np.array([state["prev_ok"]]), "pl_win": np.ravel(state["win"]),
            "pl_n_win": np.array([state["n_win"]])}
