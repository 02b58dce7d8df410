"""The C of the monitor's episode rule (:class:`~fdikit.monitor.Decision`): one episode per
announced name, groups of names sharing one episode with their revisions as change events, the
event order of the Python streaming path, the wait of a group's unspecific name for its peer
evidence (``Decision.confirm_after`` / ``unconfirmed``), and the rule's state fields with their checkpoint
mapping to :meth:`Monitor.state` ``"episodes"``."""

from __future__ import annotations

from typing import Any

import numpy as np

from .stages import Field, rl

__all__ = ["EVENT_KINDS", "EpisodeCode"]

#: The event kind codes of the generated ``event.kind``.
EVENT_KINDS: dict[int, str] = {0: "cleared", 1: "onset", 2: "change"}


def _arr(name: str, vals: list[int]) -> str:
    return f"static const int {name}[{max(len(vals), 1)}] = {{{', '.join(map(str, vals)) or '0'}}};"


class EpisodeCode:
    """The generated episode rule of one decision (the streaming path's ``_decide``, exactly).

    Parameters
    ----------
    dec : Decision
    col : dict
        Pool column of every channel name (the monitor's ``_pool_names``).
    n_clear : int
        ``clear_after`` in samples.
    n_confirm : int
        ``confirm_after`` in samples (0: no wait, as the streaming path).

    Notes
    -----
    The units (a group, or a name outside every group), the names of each unit and the channels
    of each name are tables of the generated code; the state per unit is ``active``, ``below``
    (judged samples below the clear level), ``ep_id`` and ``cur`` (the name the episode has now,
    an index within its unit), and per name ``prev_on`` (on at the last judged sample; kept only
    when a unit has several channels, as in Python). With ``confirm_after``, per tentative name
    (a group's own name, ``Decision._tent``) ``confirm``: -1 idle, ``j >= 0`` waited ``j`` judged
    samples, -2 announced, -3 dropped until its alarm falls (the streaming path's ``_confirm``).
    """

    def __init__(self, dec: Any, col: dict[str, int], n_clear: int, n_confirm: int = 0):
        self.dec = dec
        self.n_clear = int(n_clear)
        self.tent = list(getattr(dec, "_tent", []))
        self.T = len(self.tent)
        # (the streaming path waits only with tentative names and a wait of at least one sample)
        self.n_confirm = int(n_confirm) if self.T else 0
        self.A = len(dec.alarm_channels)
        self.U = len(dec._unit_chans)
        self.H = sum(len(h) for h in dec._unit_hyps)
        self.simple = bool(dec._simple)
        self.dec_idx = [col[c] for c in dec.alarm_channels]
        self.size_idx = [-1 if (c := dec.size_channel(ch)) is None else col[c] for ch in dec.alarm_channels]
        self.h0 = [0]
        for hs in dec._unit_hyps:
            self.h0.append(self.h0[-1] + len(hs))
        self.unit_of = [0] * self.A
        self.hyp_of = [0] * self.A
        for u, hc in enumerate(dec._hyp_chans):
            for hi, chans in enumerate(hc):
                for a in chans:
                    self.unit_of[a], self.hyp_of[a] = u, self.h0[u] + hi
        self.own = [int(h == dec._unit_names[u]) for u, hs in enumerate(dec._unit_hyps) for h in hs]
        hyp = [dec.hypothesis(c) for c in dec.alarm_channels]
        self.order = sorted(range(self.A), key=lambda a: (hyp[a], a))

    # ------------------------------------------------------------------ state
    def fields(self) -> list[Field]:
        """The rule's state arrays (after the monitor's core fields)."""
        U, H = max(self.U, 1), max(self.H, 1)
        return [Field("active", "i64", U), Field("below", "i64", U), Field("ep_id", "i64", U),
                Field("cur", "i64", U), Field("prev_on", "i64", H),
                *([Field("confirm", "i64", self.T)] if self.n_confirm > 0 else [])]

    def cache_members(self) -> list[str]:
        """State struct members outside the checkpoint: the alarm channels on at the last judged
        sample (after the wait), valid since the last reset and not after a restore; the names' on
        and off (``prev_on``) follow from them, so an unchanged mask skips the names' pass."""
        if self.simple:
            return []
        return [f"    uint64_t ep_on_last[{self.W}];  /* (a cache: not in the checkpoint) */",
                "    int64_t ep_on_valid;"]

    def restore_code(self) -> str:
        """After a restore the cache is rebuilt at the next judged sample."""
        return "" if self.simple else "    s->ep_on_valid = 0;"

    def reset_code(self) -> str:
        cache = "" if self.simple else (f"    for (i = 0; i < {self.W}; ++i) s->ep_on_last[i] = 0;\n"
                                        "    s->ep_on_valid = 1;\n")
        return (cache + f"    for (i = 0; i < {max(self.U, 1)}; ++i) "
                "{ s->active[i] = 0; s->below[i] = 0; s->ep_id[i] = 0; s->cur[i] = 0; }\n"
                f"    for (i = 0; i < {max(self.H, 1)}; ++i) s->prev_on[i] = 0;"
                + (f"\n    for (i = 0; i < {self.T}; ++i) s->confirm[i] = -1;" if self.n_confirm > 0 else ""))

    def to_py(self, arrays: dict[str, np.ndarray], n_ep: int) -> dict[str, np.ndarray]:
        """The C fields as :meth:`Monitor.state` ``"episodes"`` (one run)."""
        U, H = self.U, self.H
        return {"active": arrays["active"][:U].astype(bool).reshape(1, U),
                "below": arrays["below"][:U].astype(np.int64).reshape(1, U),
                "id": arrays["ep_id"][:U].astype(np.int64).reshape(1, U),
                "count": np.array([n_ep], np.int64),
                "current": arrays["cur"][:U].astype(np.int64).reshape(1, U),
                "prev_on": arrays["prev_on"][:H].astype(bool).reshape(1, H),
                "confirm": (arrays["confirm"][:self.T].astype(np.int64) if "confirm" in arrays
                            else np.full(self.T, -1, np.int64)).reshape(1, self.T)}

    def from_py(self, ep: dict[str, Any]) -> dict[str, np.ndarray]:
        """:meth:`Monitor.state` ``"episodes"`` as the C fields (a checkpoint from before issue 27,
        without ``current``, restores as Python does: the names' state at zero)."""
        out = {"active": np.ravel(ep["active"]), "below": np.ravel(ep["below"]), "ep_id": np.ravel(ep["id"])}
        if "current" in ep:
            out["cur"] = np.ravel(ep["current"])
            out["prev_on"] = np.ravel(ep["prev_on"])
        if self.n_confirm > 0:
            out["confirm"] = np.ravel(ep["confirm"]) if "confirm" in ep else np.full(self.T, -1)
        return out

    # ------------------------------------------------------------------ code
    @property
    def W(self) -> int:
        """64-bit words of a channel mask (bit ``a % 64`` of word ``a // 64``: alarm channel ``a``)."""
        return max((self.A + 63) // 64, 1)

    def _masks(self, name: str, sets: list[list[int]]) -> str:
        """A table of channel masks, :attr:`W` words per set."""
        words = []
        for chans in sets:
            m = [0] * self.W
            for a in chans:
                m[a >> 6] |= 1 << (a & 63)
            words += m
        body = ", ".join(f"UINT64_C({w:#x})" for w in words) or "UINT64_C(0x0)"
        return f"static const uint64_t {name}[{max(len(words), 1)}] = {{{body}}};"

    def tables(self) -> list[str]:
        """The rule's constant tables (C source lines)."""
        d = self.dec
        u_off, u_ch = [0], []
        for chans in d._unit_chans:
            u_ch += chans
            u_off.append(len(u_ch))
        h_off, h_ch = [0], []
        for hc in d._hyp_chans:
            for chans in hc:
                h_ch += chans
                h_off.append(len(h_ch))
        return ["/* the episode rule: per alarm channel its unit (a group or a name) and name; per unit its",
                " * channels and first name; per name its channels; the event order (by name, channel);",
                " * the channels of each unit (and name) also as bit masks */",
                f"#define FDK_EP_W {self.W}",
                "#define FDK_EP_ON(m, a) ((m)[(a) >> 6] >> ((a) & 63) & 1u)",
                _arr("FDK_EP_UNIT", self.unit_of), _arr("FDK_EP_HYP", self.hyp_of),
                _arr("FDK_EP_UOFF", u_off), _arr("FDK_EP_UCH", u_ch), _arr("FDK_EP_H0", self.h0),
                _arr("FDK_EP_HOFF", h_off), _arr("FDK_EP_HCH", h_ch),
                self._masks("FDK_EP_UM", list(d._unit_chans)),
                *([] if self.simple else [_arr("FDK_EP_OWN", self.own),
                                          self._masks("FDK_EP_HM", [c for hc in d._hyp_chans for c in hc])]),
                _arr("FDK_EP_ORDER", self.order), _arr("FDK_EP_SIZE", self.size_idx),
                _arr("FDK_EP_DEC", self.dec_idx), *self._confirm_tables(), "",
                "static int fdk_ep_any(const uint64_t *m, const uint64_t *sel)",
                "{", "    int w;",
                "    for (w = 0; w < FDK_EP_W; ++w) if (m[w] & sel[w]) return 1;",
                "    return 0;", "}", ""]

    def _confirm_tables(self) -> list[str]:
        """Per tentative name the masks of its channels, of its group's specific names' and of the
        other groups' (:attr:`W` words each)."""
        if self.n_confirm <= 0:
            return []
        return [self._masks(f"FDK_CF_{key}", [list(t[i]) for t in self.tent])
                for i, key in enumerate(("M", "O", "X"))]

    def _confirm_code(self) -> list[str]:
        """The wait of ``confirm_after`` at one judged sample (``Decision._gate_step``): gates
        ``on`` and ``hi`` (not below the clear level) of the tentative names' channels, in the
        order of the tentative names."""
        end = -2 if self.dec.unconfirmed == "announce" else -3
        return [f"    for (i = 0; i < {self.T}; ++i) {{",
                "        int raw = fdk_ep_any(on, FDK_CF_M + i * FDK_EP_W);",
                "        int o_own = fdk_ep_any(on, FDK_CF_O + i * FDK_EP_W);",
                "        int o_oth = fdk_ep_any(on, FDK_CF_X + i * FDK_EP_W);",
                "        int64_t prev = s->confirm[i], w = prev == -1 ? 0 : prev, st = prev;",
                "        if (raw && w >= 0)",
                f"            st = o_own ? -2 : o_oth ? -3 : w >= {self.n_confirm} ? {end} : w + 1;",
                "        s->confirm[i] = raw ? st : -1;",
                "        if (s->confirm[i] != -2)",
                "            for (j = 0; j < FDK_EP_W; ++j) {",
                "                on[j] &= ~FDK_CF_M[i * FDK_EP_W + j]; hi[j] &= ~FDK_CF_M[i * FDK_EP_W + j];",
                "            }", "    }"]

    def function(self, name: str) -> list[str]:
        """``fdk_decide``: the rule at one judged sample (``pool`` the monitor's outputs).

        The alarm channels are read once into two bit masks (``on``: at or above the level; ``hi``:
        not below the clear level, NaN included), so a unit's or a name's test is a few word
        operations, and the event passes run only when a unit clears, opens or is renamed:
        the same events and state as the loops over every channel (the streaming path's
        ``_decide``)."""
        A, U, H = self.A, self.U, self.H
        lvl, low = rl(self.dec.level), rl(self.dec.low_level)
        c = ["static void fdk_event(" + name + "_event *e, int64_t k, double t, double value, double size,",
             "                      int64_t episode, int channel, int kind, int previous)", "{",
             "    e->k = k; e->t = t; e->value = value; e->size = size; e->episode = episode;",
             "    e->channel = (int32_t)channel; e->kind = (int32_t)kind;",
             "    e->previous = (int32_t)previous;", "}",
             "",
             f"static void fdk_decide({name}_state *s, double t, const fdk_real *pool,",
             f"                       {name}_event *events, int *n_events)", "{",
             "    uint64_t on[FDK_EP_W], hi[FDK_EP_W];",
             f"    int on_u[{U}], first[{U}], done[{U}], nw[{U}];",
             "    int a, u, i, j, any = 0, n_done = 0, n_nw = 0;"]
        if not self.simple:
            c += [f"    int rise[{H}], chg[{A}], h, n_rise = 0, n_chg = 0;"]
        c += ["    for (j = 0; j < FDK_EP_W; ++j) { on[j] = 0; hi[j] = 0; }",
              "    /* per alarm channel: at or above the level, not below the clear level */"]
        # (clear_level <= level, so a value at the level is not below the clear level: the usual
        # value, below both, costs one comparison; rounding to float keeps the order)
        nested = self.dec.low_level <= self.dec.level
        for a, p in enumerate(self.dec_idx):
            bit = f"UINT64_C({1 << (a & 63):#x})"
            if nested:
                c += [f"    if (!(pool[{p}] < {low})) {{ hi[{a >> 6}] |= {bit}; "
                      f"if (pool[{p}] >= {lvl}) on[{a >> 6}] |= {bit}; }}"]
            else:
                c += [f"    if (pool[{p}] >= {lvl}) on[{a >> 6}] |= {bit};",
                      f"    if (!(pool[{p}] < {low})) hi[{a >> 6}] |= {bit};"]
        if self.n_confirm > 0:
            c += self._confirm_code()
        if not self.simple:   # per name: on, and turned on since the last judged sample
            c += ["    /* (the same channels on as at the last judged sample: the names are as they were) */",
                  "    i = !s->ep_on_valid;",
                  "    for (j = 0; j < FDK_EP_W; ++j) if (on[j] != s->ep_on_last[j]) i = 1;",
                  "    if (i) {",
                  f"        for (h = 0; h < {H}; ++h) {{",
                  "            int o = fdk_ep_any(on, FDK_EP_HM + h * FDK_EP_W);",
                  "            rise[h] = o && !s->prev_on[h];",
                  "            n_rise += rise[h];",
                  "            s->prev_on[h] = o;", "        }",
                  "        for (j = 0; j < FDK_EP_W; ++j) s->ep_on_last[j] = on[j];",
                  "        s->ep_on_valid = 1;", "    }"]
        c += [f"    for (u = 0; u < {U}; ++u) {{",
              "        on_u[u] = fdk_ep_any(on, FDK_EP_UM + u * FDK_EP_W);",
              "        if (on_u[u] || s->active[u]) any = 1;", "    }",
              "    if (!any) return;",
              f"    for (u = 0; u < {U}; ++u) {{",
              "        int lo = !fdk_ep_any(hi, FDK_EP_UM + u * FDK_EP_W);",
              "        s->below[u] = (s->active[u] && lo) ? s->below[u] + 1 : 0;",
              f"        done[u] = s->active[u] && s->below[u] >= {self.n_clear};",
              "        nw[u] = on_u[u] && !s->active[u];",
              "        first[u] = -1;   /* an opening unit's first channel on */",
              "        if (nw[u])",
              "            for (j = FDK_EP_UOFF[u]; j < FDK_EP_UOFF[u + 1]; ++j)",
              "                if (FDK_EP_ON(on, FDK_EP_UCH[j])) { first[u] = FDK_EP_UCH[j]; break; }",
              "        n_done += done[u]; n_nw += nw[u];", "    }"]
        if not self.simple:   # a name of an open episode's group turned on: the episode is renamed
            c += [f"    for (u = 0; n_rise && u < {U}; ++u) {{",
                  "        if (!s->active[u] || done[u]) continue;",
                  "        for (h = FDK_EP_H0[u]; h < FDK_EP_H0[u + 1]; ++h) {",
                  "            if (!rise[h] || h - FDK_EP_H0[u] == s->cur[u] || FDK_EP_OWN[h]) continue;",
                  f"            if (!n_chg++) for (a = 0; a < {A}; ++a) chg[a] = -1;",
                  "            j = FDK_EP_HOFF[h];   /* its first channel on */",
                  "            while (j < FDK_EP_HOFF[h + 1] - 1 && !FDK_EP_ON(on, FDK_EP_HCH[j])) ++j;",
                  "            chg[FDK_EP_HCH[j]] = FDK_EP_HCH[FDK_EP_HOFF[FDK_EP_H0[u] + s->cur[u]]];",
                  "            s->cur[u] = h - FDK_EP_H0[u];", "        }", "    }"]
        size = "(FDK_EP_SIZE[a] >= 0 ? (double)pool[FDK_EP_SIZE[a]] : NAN)"
        c += ["    /* cleared events, onsets, then changes; each by (name, channel) */",
              f"    for (i = 0; n_done && i < {A}; ++i) {{",
              "        a = FDK_EP_ORDER[i]; u = FDK_EP_UNIT[a];",
              "        if (done[u] && a == FDK_EP_HCH[FDK_EP_HOFF[FDK_EP_H0[u] + s->cur[u]]])",
              "            fdk_event(&events[(*n_events)++], s->k[0], t, (double)pool[FDK_EP_DEC[a]], NAN,",
              "                      s->ep_id[u], a, 0, -1);",
              "    }",
              f"    for (u = 0; n_done && u < {U}; ++u)",
              "        if (done[u]) { s->active[u] = 0; s->below[u] = 0; }",
              f"    for (i = 0; n_nw && i < {A}; ++i) {{",
              "        a = FDK_EP_ORDER[i]; u = FDK_EP_UNIT[a];",
              "        if (nw[u] && first[u] == a) {",
              "            s->ep_id[u] = s->n_ep[0]; s->n_ep[0] += 1;",
              "            s->cur[u] = FDK_EP_HYP[a] - FDK_EP_H0[u];",
              "            fdk_event(&events[(*n_events)++], s->k[0], t, (double)pool[FDK_EP_DEC[a]],",
              f"                      {size}, s->ep_id[u], a, 1, -1);",
              "        }", "    }",
              f"    for (u = 0; n_nw && u < {U}; ++u) if (nw[u]) s->active[u] = 1;"]
        if not self.simple:
            c += [f"    for (i = 0; n_chg && i < {A}; ++i) {{",
                  "        a = FDK_EP_ORDER[i];",
                  "        if (chg[a] >= 0)",
                  "            fdk_event(&events[(*n_events)++], s->k[0], t, (double)pool[FDK_EP_DEC[a]],",
                  f"                      {size}, s->ep_id[FDK_EP_UNIT[a]], a, 2, chg[a]);",
                  "    }"]
        c += ["}", ""]
        return c

    def layout(self) -> dict[str, Any]:
        """What the harness needs to read the events (plain data)."""
        return {"event_kinds": {str(k): v for k, v in EVENT_KINDS.items()},
                "units": list(self.dec._unit_names), "n_units": self.U, "n_names": self.H,
                "n_tentative": self.T if self.n_confirm > 0 else 0}

