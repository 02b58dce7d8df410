"""The CAN front end of a generated monitor as C99 (issue 29): the DBC decoder of the signals a
config reads, generated from cantools' message and signal definitions (frame id, start bit,
length, byte order, sign, scale, offset), and the streaming gridder of follow mode
(:class:`fdikit.io.stream.FrameGridder`) with its causal rule, so that a program reading candump
lines steps the generated monitor on the samples ``fdikit monitor --follow`` steps.

The gridder's rule, as the Python one: time 0 is the first frame of any message; the grid starts at
the latest first frame of the signals and runs at ``[log].rate``; a sample is released once every
signal has a frame after it; values are the last frame at or before the grid time (the causal
hold, the default; a frame at most :data:`fdikit.io.can.HOLD_TOL` after it counts as at it) and
invalid (NaN) when that frame is older than ``max_gap`` source periods (the median of the last 256
intervals), or, with ``method="linear"``, linear interpolations between the neighbouring frames,
invalid when the bracket spans more than ``max_gap`` source periods; a run of such samples is
held back and dropped when at one of them every signal is in a gap; frames going back in time,
or more than ``max_jump`` s after the previous one, are refused. The config's channel scale and
offset then map the signals to the monitor's inputs. Only ``<math.h>`` and ``<stdint.h>``; every
buffer sized at generation time (a frame that would overflow one is refused with an error code).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from ..errors import DataError
from .stages import lit

__all__ = ["emit_can_frontend", "generate_can"]

#: Frames kept per signal (the bracket of the next grid time and what arrives before every signal
#: has passed it), intervals for the median period, grid samples held back in a gap run.
FRAMES, INTERVALS, PENDING = 64, 256, 512


def _signal_code(k: int, msg: Any, sig: Any) -> str:
    """C statements decoding signal ``k`` of a frame into ``v[k]`` (NaN when the payload is short)."""
    if getattr(sig, "is_float", False):
        raise DataError(f"signal {msg.name}.{sig.name} is a float signal; the C decoder handles integers")
    if sig.length > 64 or msg.length > 8:
        raise DataError(f"signal {msg.name}.{sig.name}: the C decoder handles classic CAN (8 bytes, <= 64 "
                        "bits)")
    mask = "UINT64_MAX" if sig.length == 64 else f"((UINT64_C(1) << {sig.length}) - 1)"
    if sig.byte_order == "little_endian":
        need = (sig.start + sig.length + 7) // 8
        raw = f"(le >> {sig.start}) & {mask}"
    else:
        msb = (sig.start // 8) * 8 + (7 - sig.start % 8)       # big-endian bit index of the MSB
        lsb = msb + sig.length - 1
        need = lsb // 8 + 1
        raw = f"(be >> {63 - lsb}) & {mask}"
    lines = [f"    /* {msg.name}.{sig.name}: start {sig.start}, {sig.length} bits, {sig.byte_order}, "
             f"{'signed' if sig.is_signed else 'unsigned'}, scale {sig.scale}, offset {sig.offset} */",
             f"    if (len < {need}) v[{k}] = NAN; else {{", f"        uint64_t r = {raw};"]
    if sig.is_signed and sig.length < 64:
        lines.append(f"        int64_t x = (r >> {sig.length - 1}) ? (int64_t)(r | ~{mask}) : (int64_t)r;")
    elif sig.is_signed:
        lines.append("        int64_t x = (int64_t)r;")
    else:
        lines.append("        uint64_t x = r;")
    lines += [f"        v[{k}] = (double)x * {lit(float(sig.scale))} + {lit(float(sig.offset))};", "    }"]
    return "\n".join(lines)


#: The causal hold's value (FrameGridder._value, method "previous"): the last frame, NaN and a gap
#: when it is older than max_gap median periods (the median only when the age could exceed it: the
#: median is at least the smallest interval).
_HOLD_VALUE = """    if (gt - t[i] > 0.0) {
        for (mn = HUGE_VAL, i0 = 0; i0 < g->niv[s]; ++i0) if (g->iv[s][i0] < mn) mn = g->iv[s][i0];
        if (gt - t[i] > MAX_GAP * mn) {
            lim = MAX_GAP * fdk_period(g, s);
            if (gt - t[i] > lim) { *gap = 1; return NAN; }
        }
    }
    return isfinite(v[i]) ? v[i] : NAN;
"""


def emit_can_frontend(dbc: Any, sources: list[str], rate: float, channels: list[tuple[int, float, float]], *,
                      name: str = "fdk_can", max_gap: float = 3.0,
                      max_jump: float = 3600.0, method: str = "previous") -> tuple[str, str]:
    """The C99 header and source of a CAN decoder and gridder.

    Parameters
    ----------
    dbc : path or cantools Database
    sources : list of str
        ``"MESSAGE.SIGNAL"`` names, the gridder's signals (in this order).
    rate : float
        Grid rate (Hz).
    channels : list of (int, float, float)
        Per monitor input, in the monitor's input order: the index of its source in ``sources``,
        its scale and its offset (input = scale * signal - offset).
    name : str
        C prefix.
    max_gap, max_jump : float
        As :class:`~fdikit.io.stream.FrameGridder`.
    method : {"previous", "linear"}
        The gridding rule, as :class:`~fdikit.io.stream.FrameGridder` (causal hold by default).

    Returns
    -------
    (str, str)
        ``<name>.h`` and ``<name>.c``.
    """
    from ..io.can import HOLD_TOL, _load_dbc, _resolve

    if method not in ("previous", "linear"):
        raise DataError(f"unknown resampling method {method!r}; use 'previous' or 'linear'")
    hold = method == "previous"

    if not name.isidentifier():
        raise DataError(f"the C name prefix must be an identifier, got {name!r}")
    if not (math.isfinite(rate) and rate > 0):
        raise DataError(f"rate must be a positive number of Hz, got {rate!r}")
    res = _resolve(_load_dbc(dbc), sources)
    S, N, U = len(sources), len(channels), name.upper()
    by_id: dict[int, list[tuple[int, Any, Any]]] = {}
    for k, (_full, msg, sig) in enumerate(res):
        by_id.setdefault(int(msg.frame_id), []).append((k, msg, msg.get_signal_by_name(sig.name)))
    h = f"""/* {name}.h: generated by fdikit.codegen.can from a DBC and a monitor config. Do not edit.
 * signals: {', '.join(sources)}
 * grid {rate:g} Hz; {N} monitor inputs (scale * signal - offset). */
#ifndef {U}_H
#define {U}_H
#include <stdint.h>

#define {U}_N_SIG {S}
#define {U}_N_IN {N}
#define {U}_FRAMES {FRAMES}
#define {U}_INTERVALS {INTERVALS}
#define {U}_PENDING {PENDING}
#define {U}_ERR_TIME (-1)      /* a non-finite time, time going back, or a jump beyond max_jump */
#define {U}_ERR_FULL (-2)      /* a buffer sized at generation time would overflow */
#define {U}_ERR_OUT (-3)       /* more samples than the caller's buffer holds */

typedef struct {{
    double t;                  /* grid time (s from the first frame) */
    double x[{max(N, 1)}];                /* the monitor's inputs (NaN where invalid) */
    int valid;                 /* 0: a signal was in a gap or undecodable */
}} {name}_sample;

typedef struct {{
    double ft[{S}][{FRAMES}], fv[{S}][{FRAMES}];   /* frames kept per signal (time, value) */
    int nf[{S}];
    double iv[{S}][{INTERVALS}];                   /* the last intervals per signal (ring) */
    int niv[{S}], piv[{S}];
    int has_first[{S}];
    double first[{S}];
    int has_t0, has_last, has_start;
    double t0, t_last, start;
    int64_t k, frames;
    {name}_sample pend[{PENDING}];
    int pend_dead[{PENDING}];
    int npend;
}} {name}_grid;

void {name}_init({name}_grid *g);
int {name}_grid_size(void);
/* the signals of one frame: v[source] set where the frame carries it (NaN if its payload is short);
   returns the number of signals it carries */
int {name}_decode(uint32_t id, const uint8_t *data, int len, double *v, int *hit);
/* one frame (absolute time, s): the grid samples it completes into out (at most cap), or an error */
int {name}_push({name}_grid *g, double t, uint32_t id, const uint8_t *data, int len,
        {name}_sample *out, int cap);
/* at the end of the stream: the samples that sit on the last frames */
int {name}_flush({name}_grid *g, {name}_sample *out, int cap);
#endif
"""
    dec = []
    for fid, sigs in sorted(by_id.items()):
        dec += [f"    case {fid}u: {{  /* {sigs[0][1].name} */"]
        dec += ["        uint64_t le = 0, be = 0;", "        int i;",
                "        for (i = 0; i < 8; ++i) {", "            uint64_t b = i < len ? data[i] : 0u;",
                "            le |= b << (8 * i); be |= b << (8 * (7 - i));", "        }",
                "        (void)le; (void)be;"]
        for k, msg, sig in sigs:
            dec.append("    " + _signal_code(k, msg, sig).replace("\n", "\n    "))
            dec.append(f"        hit[{k}] = 1;")
        dec += [f"        return {len(sigs)};", "    }"]
    mapping = "\n".join(f"            smp.x[{i}] = {lit(sc)} * val[{k}] - {lit(off)};"
                        for i, (k, sc, off) in enumerate(channels))
    c = f"""/* {name}.c: generated by fdikit.codegen.can. Do not edit. Only <math.h> and <stdint.h>. */
#include "{name}.h"
#include <math.h>

#define RATE {lit(rate)}
#define MAX_GAP {lit(max_gap)}
#define MAX_JUMP {lit(max_jump)}
#define HOLD_TOL {lit(HOLD_TOL if hold else 0.0)}

void {name}_init({name}_grid *g)
{{
    int i;
    for (i = 0; i < {S}; ++i) {{
        g->nf[i] = 0; g->niv[i] = 0; g->piv[i] = 0; g->has_first[i] = 0; g->first[i] = 0.0;
    }}
    g->has_t0 = 0; g->has_last = 0; g->has_start = 0; g->t0 = 0.0; g->t_last = 0.0; g->start = 0.0;
    g->k = 0; g->frames = 0; g->npend = 0;
}}

int {name}_grid_size(void) {{ return (int)sizeof({name}_grid); }}

int {name}_decode(uint32_t id, const uint8_t *data, int len, double *v, int *hit)
{{
    switch (id) {{
{chr(10).join(dec)}
    default:
        (void)data; (void)len; (void)v; (void)hit;
        return 0;
    }}
}}

/* the median of the intervals seen (numpy's: the mean of the two middle ones for an even count) */
static double fdk_period(const {name}_grid *g, int s)
{{
    double v[{INTERVALS}], x;
    int i, j, n = g->niv[s];
    if (n == 0) return HUGE_VAL;
    for (i = 0; i < n; ++i) {{
        x = g->iv[s][i];
        for (j = i; j > 0 && v[j - 1] > x; --j) v[j] = v[j - 1];
        v[j] = x;
    }}
    if (n % 2) return v[n / 2];
    return (v[n / 2 - 1] + v[n / 2]) / 2.0;
}}

/* signal s at grid time gt (FrameGridder._value, method "{method}"); *gap set for a gap */
static double fdk_value(const {name}_grid *g, int s, double gt, int *gap)
{{
    const double *t = g->ft[s], *v = g->fv[s];
    int n = g->nf[s], i = 0, i0;
    double lim, t0, t1, v0, v1, span, w, mn;
    *gap = 0;
    while (i + 1 < n && t[i + 1] <= gt + HOLD_TOL) ++i;
{_HOLD_VALUE if hold else ""}    i0 = i;
    if (i + 1 >= n) {{
        if (n < 2) return isfinite(v[i]) ? v[i] : NAN;
        i0 = i - 1;
    }}
    t0 = t[i0]; t1 = t[i0 + 1]; v0 = v[i0]; v1 = v[i0 + 1];
    span = t1 - t0;
    if (span > 0.0 && !(t[i] == gt)) {{
        /* the median only when the span could exceed it: it is at least the smallest interval */
        for (mn = HUGE_VAL, i = 0; i < g->niv[s]; ++i) if (g->iv[s][i] < mn) mn = g->iv[s][i];
        if (span > MAX_GAP * mn) {{
            lim = MAX_GAP * fdk_period(g, s);
            if (span > lim) {{ *gap = 1; return NAN; }}
        }}
    }}
    w = span > 0.0 ? (gt - t0) / span : 0.0;
    if ((!isfinite(v0) && w < 1.0) || (!isfinite(v1) && w > 0.0)) return NAN;
    return v0 + w * ((isfinite(v1) ? v1 : 0.0) - (isfinite(v0) ? v0 : 0.0));
}}

static int fdk_emit({name}_grid *g, int final, {name}_sample *out, int cap)
{{
    int n = 0, s, j, q, n_gap, bad;
    double gt, gn, val[{S}];
    if (!g->has_start) return 0;
    for (;;) {{
        gt = g->start + (double)g->k / RATE;
        for (s = 0; s < {S}; ++s) {{
            double last = g->ft[s][g->nf[s] - 1];
            if (last < gt || (last <= gt + HOLD_TOL && !final)) return n;
        }}
        n_gap = 0; bad = 0;
        for (s = 0; s < {S}; ++s) {{
            int gap;
            val[s] = fdk_value(g, s, gt, &gap);
            n_gap += gap;
            if (!(val[s] == val[s])) bad = 1;
        }}
        {{
            {name}_sample smp;
            smp.t = gt; smp.valid = !bad;
{mapping}
            if (n_gap) {{
                if (g->npend >= {PENDING}) return {U}_ERR_FULL;
                g->pend[g->npend] = smp; g->pend_dead[g->npend] = n_gap == {S}; g->npend += 1;
            }} else {{
                int dead = 0;
                for (q = 0; q < g->npend; ++q) dead |= g->pend_dead[q];
                if (!dead) for (q = 0; q < g->npend; ++q) {{
                    if (n >= cap) return {U}_ERR_OUT;
                    out[n++] = g->pend[q];
                }}
                g->npend = 0;
                if (n >= cap) return {U}_ERR_OUT;
                out[n++] = smp;
            }}
        }}
        g->k += 1;
        gn = g->start + (double)g->k / RATE;
        for (s = 0; s < {S}; ++s) {{   /* drop frames no later grid time can use */
            int d = 0;
            while (d + 2 < g->nf[s] && g->ft[s][d + 2] <= gn) ++d;
            if (d) {{
                for (j = d; j < g->nf[s]; ++j) {{
                    g->ft[s][j - d] = g->ft[s][j]; g->fv[s][j - d] = g->fv[s][j];
                }}
                g->nf[s] -= d;
            }}
        }}
    }}
}}

int {name}_push({name}_grid *g, double t, uint32_t id, const uint8_t *data, int len,
        {name}_sample *out, int cap)
{{
    double v[{S}], tr;
    int hit[{S}], s, j, any;
    if (!isfinite(t)) return {U}_ERR_TIME;
    if (g->has_last && t < g->t_last) return {U}_ERR_TIME;
    if (g->has_last && t - g->t_last > MAX_JUMP) return {U}_ERR_TIME;
    if (!g->has_t0) {{ g->t0 = t; g->has_t0 = 1; }}
    g->t_last = t; g->has_last = 1; g->frames += 1;
    for (s = 0; s < {S}; ++s) hit[s] = 0;
    if ({name}_decode(id, data, len, v, hit) == 0) return 0;
    tr = t - g->t0;
    for (s = 0; s < {S}; ++s) {{
        int n = g->nf[s];
        if (!hit[s]) continue;
        if (n && g->ft[s][n - 1] == tr) {{   /* the same time twice: equal merges, different is bad */
            double o = g->fv[s][n - 1];
            if (!(o == v[s] || (o != o && v[s] != v[s]))) g->fv[s][n - 1] = NAN;
            continue;
        }}
        if (n) {{
            g->iv[s][g->piv[s]] = tr - g->ft[s][n - 1];
            g->piv[s] = (g->piv[s] + 1) % {INTERVALS};
            if (g->niv[s] < {INTERVALS}) g->niv[s] += 1;
        }} else if (!g->has_first[s]) {{ g->first[s] = tr; g->has_first[s] = 1; }}
        if (n >= {FRAMES}) return {U}_ERR_FULL;
        g->ft[s][n] = tr; g->fv[s][n] = v[s]; g->nf[s] = n + 1;
    }}
    if (!g->has_start) {{
        any = 1;
        for (s = 0; s < {S}; ++s) any &= g->has_first[s];
        if (any) {{
            g->start = -HUGE_VAL;
            for (s = 0; s < {S}; ++s) if (g->first[s] > g->start) g->start = g->first[s];
            g->has_start = 1;
        }} else {{
            for (s = 0; s < {S}; ++s) if (g->nf[s] > 2) {{
                int d = g->nf[s] - 2;
                for (j = d; j < g->nf[s]; ++j) {{
                    g->ft[s][j - d] = g->ft[s][j]; g->fv[s][j - d] = g->fv[s][j];
                }}
                g->nf[s] = 2;
            }}
        }}
    }}
    return fdk_emit(g, 0, out, cap);
}}

int {name}_flush({name}_grid *g, {name}_sample *out, int cap)
{{
    int n = fdk_emit(g, 1, out, cap), q, dead = 0;
    if (n < 0) return n;
    for (q = 0; q < g->npend; ++q) dead |= g->pend_dead[q];
    if (!dead) for (q = 0; q < g->npend; ++q) {{
        if (n >= cap) return {U}_ERR_OUT;
        out[n++] = g->pend[q];
    }}
    g->npend = 0;
    return n;
}}
"""
    return h, c


def generate_can(config: str | Path, out_dir: str | Path, inputs: list[str], *, name: str = "fdk_can"
                 ) -> dict[str, Any]:
    """Write ``<name>.h`` / ``<name>.c``: the CAN front end of a config whose ``[log]`` is a CAN log
    (``dbc``, ``rate``), feeding the monitor inputs ``inputs`` (the generated monitor's layout
    ``inputs``) with the config's channel scale and offset.

    Returns
    -------
    dict
        ``files``, ``sources`` (the gridder's signals), ``inputs``.

    Raises
    ------
    DataError
        A config without ``[log].dbc`` or ``[log].rate``, an input the config does not define, a
        signal the decoder cannot handle (float signals, CAN FD payloads).
    """
    from ..monitor.config import config_path, load_config

    cfg = load_config(config)
    dbc, rate = cfg.log.get("dbc"), cfg.log.get("rate")
    if not dbc or rate is None:
        raise DataError(f"{cfg.path}: the CAN front end needs [log].dbc and [log].rate")
    sources = list(dict.fromkeys(c.source for c in cfg.channels))
    by_name = {c.name: c for c in cfg.channels}
    missing = [n for n in inputs if n not in by_name]
    if missing:
        raise DataError(f"monitor inputs {missing} are not channels of {cfg.path} ({sorted(by_name)})")
    chans = [(sources.index(by_name[n].source), float(by_name[n].scale), float(by_name[n].offset))
             for n in inputs]
    h, c = emit_can_frontend(config_path(cfg.path.parent, dbc, where=f"{cfg.path}: [log].dbc"), sources,
                             float(rate), chans, name=name, method=str(cfg.log.get("resample", "previous")))
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    (out / f"{name}.h").write_text(h)
    (out / f"{name}.c").write_text(c)
    return {"files": [str(out / f"{name}.h"), str(out / f"{name}.c")], "sources": sources,
            "inputs": list(inputs)}
