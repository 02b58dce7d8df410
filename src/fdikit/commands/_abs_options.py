"""Options shared by the ``fdikit abs`` actions."""

from __future__ import annotations

import argparse

__all__ = ["add_manoeuvre_args", "snr_db"]


def snr_db(text: str) -> float | None:
    if text.lower() in ("none", "off", "inf"):
        return None
    try:
        return float(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"--snr expects a number of dB or 'none', got {text!r}") from exc


def add_manoeuvre_args(p: argparse.ArgumentParser) -> None:
    """``--noise-hold`` and ``--pedal-ramp``: shared by ``abs simulate`` and ``abs campaign``."""
    p.add_argument("--noise-hold", type=float, default=None,
                   help="process-noise hold time, s (default: a new noise sample every 1 ms integration "
                   "step; 0.01: one per 10 ms measurement sample, the alternative reading of Section III-A)")
    p.add_argument("--pedal-ramp", type=float, default=None, metavar="SECONDS",
                   help="ramp time of the pedal force, s: an opt-in experiment where the force rises "
                   "linearly to K_p over SECONDS after the brake is applied, then is held (default: the "
                   "step of eq. (4))")
