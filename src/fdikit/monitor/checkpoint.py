"""Checkpoint / restore of a Monitor's streaming state: the whole chain as plain data, written
atomically to a file and read back on an identically built Monitor."""

from __future__ import annotations

from typing import Any

import numpy as np

from ..base.state import load_state, save_state
from ..errors import DataError


class _Checkpointing:
    """Checkpoint / restore of the Monitor (a part of :class:`~fdikit.monitor.core.Monitor`)."""

    # ------------------------------------------------------------------ checkpoint / restore
    def state(self) -> dict[str, Any]:
        """The streaming state of the whole chain (plain data; see :meth:`restore`)."""
        if self._runs is None:  # nothing stepped yet: the initial state of one run
            self.reset(1)
        return {
            "k": self._k,
            "t_prev": self._t_prev,
            "held": self._held,
            "held_t": self._held_t,
            "missing": self._missing,
            "dt": self._dt,
            "warm_left": self._warm_left,
            "reset_due": self._reset_due,
            "warm_min": self._warm_min,
            "quiet": self._quiet,
            "episodes": {"active": self._active.copy(), "below": self._below.copy(),
                         "id": self._ep_id.copy(), "count": self._n_ep.copy(), "current": self._cur.copy(),
                         "prev_on": self._prev_on.copy(), "confirm": self._confirm.copy()},
            "plausibility": None if self._checker is None else self._checker.state(),
            "runs": self._runs,
            "generators": [g.get_state() for g in self.generators],
            "processors": [p.get_state() for p in self.processors],
            "last": None if self._last is None else [a.copy() for a in self._last],
            "channels": {"inputs": list(self.input_names), "residuals": list(self.residual_names),
                         "statistics": list(self.stat_names)},
        }

    def restore(self, state: dict[str, Any]) -> None:
        """Continue from a state captured by :meth:`state` on an identically built Monitor."""
        ch = state.get("channels", {})
        mine = {"inputs": list(self.input_names), "residuals": list(self.residual_names),
                "statistics": list(self.stat_names)}
        if ch != mine:
            raise DataError(f"checkpoint is for a monitor with channels {ch}, this one has {mine}")
        if len(state["generators"]) != len(self.generators) or \
                len(state["processors"]) != len(self.processors):
            raise DataError("checkpoint has a different number of generators or processors")
        if (state.get("plausibility") is None) != (self._checker is None):
            raise DataError("checkpoint and monitor differ in their plausibility rules")
        self.reset(int(state["runs"]))
        for g, s in zip(self.generators, state["generators"]):
            g.set_state(s)
        for p, s in zip(self.processors, state["processors"]):
            p.set_state(s)
        self._k, self._t_prev = int(state["k"]), state["t_prev"]
        if "dt" in state:
            self._set_dt(state["dt"])
            self._warm_left, self._reset_due = int(state["warm_left"]), bool(state["reset_due"])
            self._warm_min, self._quiet = int(state["warm_min"]), int(state["quiet"])
        self._held = int(state.get("held", 0))
        self._held_t = int(state.get("held_t", self._held))
        self._missing = int(state.get("missing", 0))
        A = self._active.shape[1]
        ep = state.get("episodes")
        if ep is not None:
            self._active = np.array(ep["active"], bool).reshape(self._runs, A)
            self._below = np.array(ep["below"], np.int64).reshape(self._runs, A)
            self._ep_id = np.array(ep["id"], np.int64).reshape(self._runs, A)
            self._n_ep = np.array(ep["count"], np.int64).reshape(self._runs)
            if "current" in ep:      # (a checkpoint before issue 27: no group names an episode)
                self._cur = np.array(ep["current"], np.int64).reshape(self._runs, A)
                self._prev_on = np.array(ep["prev_on"], bool).reshape(self._runs, self._prev_on.shape[1])
            if "confirm" in ep:      # (a checkpoint before Decision.confirm_after: nothing waits)
                self._confirm = np.array(ep["confirm"], np.int64).reshape(self._runs, self._confirm.shape[1])
        elif state.get("on") is not None:  # a checkpoint of the rising-edge rule: open = on
            self._active = np.array(state["on"], bool).reshape(self._runs, A)
        if self._checker is not None:
            self._checker.restore(state["plausibility"])
        last = state.get("last")
        self._last = None if last is None else (np.array(last[0]), np.array(last[1]))

    def save_checkpoint(self, path) -> None:
        """Write :meth:`state` to ``path`` atomically (temporary file + rename)."""
        save_state(path, self.state(), meta={"kind": "Monitor"})

    def load_checkpoint(self, path) -> None:
        """Restore from a file written by :meth:`save_checkpoint`."""
        state, meta = load_state(path)
        if meta.get("kind") != "Monitor":
            raise DataError(f"{path}: not a Monitor checkpoint (kind {meta.get('kind')!r})")
        self.restore(state)
