"""luo-et-al Fig. 15 shows a trend (issue 18): the Pd of G_P1 for F1.2 and F2.2 rises with the
SNR and with the GLRT window, and is not the same in every cell (the figure once showed Pd = 1 over
its whole grid, i.e. no contour at all). The checks read the numbers behind the figure, not pixels.
"""

from __future__ import annotations

import argparse

import numpy as np
import pytest

from fdikit.commands.abs_figures import (
    FIG15_MAGNITUDES,
    FIG15_PFA,
    FIG15_SNRS,
    FIG15_T_DETECT,
    FIG15_WINDOWS,
)


def _check_trend(g: dict, *, tol_snr: float, tol_w: float, rise_w: float, w_monotone_to: int = 50) -> None:
    """Pd not constant, monotone-ish in SNR and in W (up to ``w_monotone_to``, beyond which this
    plant's Pd is flat or slightly lower: see ``FIG15_SNRS``), rising from the smallest window to
    W = 30."""
    snrs, ws = list(g["snr_db"]), list(g["W"])
    assert snrs == sorted(snrs) and ws == sorted(ws)
    j30 = ws.index(30)
    for c in ("F1.2", "F2.2"):
        z = np.asarray(g["pd"][c], float)
        assert z.shape == (len(snrs), len(ws))
        assert np.ptp(z) >= 0.5, f"{c}: Pd hardly changes over the grid:\n{z}"
        # the noise: low at the lowest SNR, ~1 at the highest, never falling by more than tol_snr
        assert z[0].max() <= 0.7, f"{c}: Pd already high at {snrs[0]} dB:\n{z}"
        assert z[-1].min() >= 0.95, f"{c}: Pd not ~1 at {snrs[-1]} dB:\n{z}"
        assert np.all(np.diff(z, axis=0) >= -tol_snr), f"{c}: Pd falls as the SNR rises:\n{z}"
        # the window: rises from the smallest window to W = 30, and never falls by more than tol_w
        k = ws.index(w_monotone_to) + 1
        assert np.all(np.diff(z[:, :k], axis=1) >= -tol_w), f"{c}: Pd falls as W grows:\n{z}"
        assert np.all(z[:, j30] >= z[:, 0] - 0.05), f"{c}: Pd at W = 30 below W = {ws[0]}:\n{z}"
        assert float(np.sum(z[:, j30] - z[:, 0])) >= rise_w, f"{c}: Pd does not rise with W:\n{z}"
    assert np.max(g["pf"]) <= 0.02


def test_fig15_grid_spans_the_paper_and_the_transition():
    # the paper's levels and windows are in the grid, and so are lower SNRs and smaller windows
    assert {17.0, 20.0, 23.0} <= set(FIG15_SNRS) and min(FIG15_SNRS) < 10.0
    assert {30, 40, 50} <= set(FIG15_WINDOWS) and min(FIG15_WINDOWS) < 30
    assert FIG15_T_DETECT == 7.0 and FIG15_MAGNITUDES == {"F1.2": -0.05, "F2.2": -0.25}


def test_fig15_trend_small():
    """A small grid of the figure's own settings (3 SNRs x 3 windows, 60 runs per class; ~5 s).

    With 100 design runs the W = 50 threshold varies too much for a tight check beyond W = 30 (the
    default-size test below checks the whole range)."""
    from fdikit.systems.abs.campaign import gp1_grid

    g = gp1_grid(
        (0.0, 6.0, 23.0),
        (10, 20, 30),
        runs=60,
        nominal_runs=30,
        design_runs=100,
        seed=0,
        pfa=FIG15_PFA,
        t_detect=FIG15_T_DETECT,
        magnitudes=FIG15_MAGNITUDES,
    )
    assert g["magnitudes"] == FIG15_MAGNITUDES and g["runs"] == 60 and g["nominal_runs"] == 30
    _check_trend(g, tol_snr=0.1, tol_w=0.1, rise_w=0.1, w_monotone_to=30)


def test_gp1_grid_default_draws_sizes():
    from fdikit.systems.abs.campaign import gp1_grid

    g = gp1_grid((23.0,), (50,), runs=3, design_runs=5, pfa=0.2)
    assert g["magnitudes"] == {"F1.2": None, "F2.2": None} and g["nominal_runs"] == 3


@pytest.mark.slow
def test_fig15_figure_default_size():
    """The figure as ``fdikit abs figure 15`` draws it, at its default size (~20 s)."""
    from fdikit.commands.abs_figures import FIGURES
    from fdikit.report.figures import _plt

    class _Steps:
        def step(self, _):
            pass

    args = argparse.Namespace(runs=200, design_runs=300, seed=0, snr=23.0)
    fig, g = FIGURES[15][0](args, _Steps())
    _plt().close(fig)
    assert g["snr_db"] == list(FIG15_SNRS) and g["W"] == list(FIG15_WINDOWS)
    _check_trend(g, tol_snr=0.05, tol_w=0.15, rise_w=0.2)
