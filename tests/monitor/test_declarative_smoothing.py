"""``[design.detect]`` smoothing = "ewma": the core's EWMA and its held-out limits reachable from a
declarative design (issue 26, item 9: the own-system TOML path).

The plant and its logs are those of :mod:`tests.monitor.test_declarative_thresholds`: a plant that is
not the declared one, whose filter residuals are coloured (correlated) noise.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from fdikit.base.artifacts import load_artifact
from fdikit.detect import EWMA, ewma_tau
from fdikit.errors import DataError
from fdikit.evaluate import validate
from fdikit.monitor.config import build_monitor, load_config, map_channels, read_log, run_design
from fdikit.monitor.declarative_smoothing import _record_tau, smoothing_from_config

from .test_declarative_thresholds import _config, _write_log

SMOOTH = '\n[design.detect]\nsmoothing = "ewma"\nlambda = {lam}\n'


@pytest.fixture(scope="module")
def logs(tmp_path_factory):
    d = tmp_path_factory.mktemp("smooth")
    (d / "fit").mkdir()
    return {"dir": d, "fit": [_write_log(d / "fit" / f"nominal_{k}.csv", k) for k in (1, 2)],
            "held_out": _write_log(d / "held_out.csv", 3)}


def _cfg(logs, name, lam='"auto"', pfa=0.1, nominal='nominal_log = ["fit/nominal_*.csv"]'):
    return load_config(_config(logs["dir"], name, extra=nominal + SMOOTH.format(lam=lam), pfa=pfa))


def test_the_detect_table_is_parsed_and_wrong_keys_are_named(logs):
    assert not smoothing_from_config({}).active
    s = smoothing_from_config({"detect": {"smoothing": "ewma"}})
    assert s.active and s.lam is None and s.candidates[0] == 0.05 and s.candidates[-1] == 1.0
    assert smoothing_from_config({"detect": {"smoothing": "ewma", "lambda": 1}}).lam == 1.0
    bad = [({"smoothing": "ewma", "lambda": 0.0}, r"\[design.detect\].lambda must be a number in \(0, 1\]"),
           ({"smoothing": "ewma", "lambda": "fast"}, r"lambda must be \"auto\" or a number"),
           ({"smoothing": "ewma", "lambda": True}, r"\[design.detect\].lambda must be a number"),
           ({"smoothing": "ewma", "candidates": [0.1, 2.0]}, r"candidates\[1\] must be a number in \(0, 1\]"),
           ({"smoothing": "ewma", "lambda": 0.1, "candidates": [0.1]}, "candidates is for lambda = \"auto\""),
           ({"smoothing": "none", "lambda": 0.1}, r"\[design.detect\].lambda needs smoothing = \"ewma\""),
           ({"smoothing": "kalman"}, r"smoothing must be \"none\" or \"ewma\", got 'kalman'"),
           ({"smooth": "ewma"}, r"unknown key 'smooth' in \[design.detect\]")]
    for table, msg in bad:
        with pytest.raises(DataError, match=msg):
            smoothing_from_config({"detect": table})
    # the config refuses a wrong key when it is loaded, before any design runs
    with pytest.raises(DataError, match=r"unknown key 'lamda' in \[design.detect\]"):
        load_config(_config(logs["dir"], "typo", extra='[design.detect]\nsmoothing = "ewma"\nlamda = 0.1\n'))
    recipe = logs["dir"] / "recipe.toml"
    recipe.write_text('[monitor]\nname = "r"\n[channels.x]\n[[generators]]\nartifact = "g"\n'
                      '[design]\nrecipe = "m:f"\n[design.detect]\nsmoothing = "ewma"\n')
    with pytest.raises(DataError, match=r"\[design.detect\] smooths a declarative \[design.plant\]"):
        load_config(recipe)
    assert _cfg(logs, "stages").processors == ["features", "smooth", "hold", "isolate"]
    assert load_config(_config(logs["dir"], "plain")).processors == ["features", "hold", "isolate"]
    # smoothed limits come from real logs only: no chi bound of simulated noise for an EWMA
    with pytest.raises(DataError, match=r"smoothing = \"ewma\" sets its limits on real nominal logs"):
        run_design(_cfg(logs, "nologs", nominal=""))


def test_a_smoothed_declarative_design_holds_its_rate_on_a_held_out_log(logs):
    """Auto picks the strongest smoothing the fit halves support (0.05 here, on 2 x 1.5 min at
    100 Hz); its per-threshold claims, measured on the held-out halves and then on a log the design
    never saw, hold; the EWMA statistic has a far lower limit than the raw feature (it averages the
    noise). Fails on main: [design.detect] is an unknown key there."""
    cfg = _cfg(logs, "auto")
    paths = run_design(cfg)
    rep = json.loads(paths["design_report"].read_text())
    sm = rep["smoothing"]
    assert sm["lambda"] == 0.05 and sm["chosen"].startswith("auto")
    assert sm["candidates"]["0.05"]["supported"] and list(sm["candidates"]) == ["0.05"]
    assert rep["threshold_design"]["method"] == "split-conformal quantile of the EWMA"
    assert all(t >= ewma_tau(0.05) for t in rep["threshold_design"]["tau"])
    th = [c for c in rep["claims"] if c["kind"] == "threshold"]
    assert len(th) == 4 and all(c["channels"][0].endswith(":ewma:alarm") for c in th)
    assert all(c["verdict"] == "inside" and c["smoothing"]["lambda"] == 0.05 for c in rep["claims"])
    assert all("EWMA lambda 0.05" in c["basis"] for c in rep["claims"])
    assert all("effective samples" in c["rests_on"] and "2 nominal record(s)" in c["rests_on"]
               for c in rep["claims"])
    out = validate(cfg, [logs["held_out"]])
    assert out["contradicted"] == [], [(c["name"], c["interval"], c["measured"]) for c in out["claims"]]
    fam = next(c for c in out["claims"] if c["kind"] == "family")
    assert 0.0 < fam["measured"]["rate"] <= 0.1
    raw = load_config(_config(logs["dir"], "raw", extra='nominal_log = ["fit/nominal_*.csv"]'))
    raw_rep = json.loads(run_design(raw)["design_report"].read_text())
    lim_raw = np.array(list(raw_rep["thresholds"].values()))
    lim_sm = np.array(list(rep["thresholds"].values()))
    start = np.array(sm["start"])
    assert np.all(lim_sm - start < 0.5 * (lim_raw - start))     # the smoothed margin is far smaller
    # a constant the data cannot support is refused, naming it and the effective samples
    with pytest.raises(DataError, match=r"EWMA at lambda = 0.01: lambda 0.01: \d+ effective samples"):
        run_design(_cfg(logs, "tiny", lam=0.01, pfa=0.01))
    # a target per hour with a hold goes to design_threshold on the smoothed features; these 3 min
    # cannot show 120 an hour: refused with the hours it needs, never the chi bound
    cfg = _cfg(logs, "hour", lam=0.2)
    cfg.path.write_text(cfg.path.read_text().replace('per = "sample"\nhold = 1', 'per = "hour"\nhold = 5')
                        .replace("pfa = 0.1", "pfa = 120.0"))
    with pytest.raises(DataError, match=r"\[design.detect\].* per hour \(hold 5\) .*lambda = 0.2.* h of"):
        run_design(load_config(cfg.path))


def test_the_smoothed_monitor_is_the_same_in_batch_and_streaming_and_its_artifact_round_trips(logs):
    cfg = _cfg(logs, "stream", lam=0.2)
    run_design(cfg)
    rep = json.loads((cfg.artifacts / "design_report.json").read_text())
    ew = load_artifact(cfg.artifacts / "smooth")
    assert isinstance(ew, EWMA) and ew.lam == 0.2
    np.testing.assert_array_equal(ew.start, rep["smoothing"]["start"])
    assert EWMA.from_dict(ew.to_dict()).to_dict() == ew.to_dict()
    sig = map_channels(cfg, read_log(cfg, logs["held_out"]))
    sig = type(sig)(sig.t[:3000], sig.values[:, :3000], sig.names)
    batch, stream = build_monitor(cfg).run(sig), build_monitor(cfg).stream(sig)
    np.testing.assert_array_equal(batch.statistics.values, stream.statistics.values)
    assert batch.events == stream.events
    names = batch.statistics.names
    assert any(n.endswith(":ewma") for n in names) and any(n.endswith(":ewma:alarm") for n in names)
    # the EWMA channel is the core's EWMA of the feature channel, from the design's start
    j = next(k for k, n in enumerate(names) if n.endswith(":ewma"))
    i = names.index(names[j][:-len(":ewma")])
    # (the monitor resets its processors when the filter's start-up warm-up ends: from there)
    feat, zm = batch.statistics.values[0][:, i], batch.statistics.values[0][:, j]
    x0 = rep["smoothing"]["start"][0]
    k0 = int(np.flatnonzero(zm == 0.2 * feat + (1.0 - 0.2) * x0)[-1])
    z = EWMA("f", 0.2, x0).run(type(sig)(sig.t[k0:], feat[None, k0:, None], ["f"])).values[0][:, 0]
    np.testing.assert_array_equal(zm[k0:], z)
    assert k0 < 500


def test_records_at_their_own_levels_count_as_few_effective_samples():
    """Nominal records whose levels differ (between-run variation that an EWMA does not average
    down) are credited with fewer effective samples than their within-record correlation alone."""
    rng = np.random.default_rng(0)
    same = [rng.normal(size=400) for _ in range(10)]
    shifted = [r + rng.normal() for r in same]
    assert _record_tau(same, 2.0) == pytest.approx(2.0, rel=0.2)
    assert _record_tau(shifted, 2.0) > 100.0
    assert _record_tau(shifted[:2], 2.0) == 2.0        # two records cannot show it
    assert _record_tau([], 3.0) == 3.0
