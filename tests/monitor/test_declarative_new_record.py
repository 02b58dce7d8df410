"""A declarative design's per-sample thresholds hold their rate on a NEW record (issue 26, item 9):
with three records or more, each threshold is at the quantile level whose mean left-out-record
rate meets the target, and the report states the claim "per sample on a new record" with a
t-interval over the records; fewer records keep the pooled design."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from fdikit import Signals
from fdikit.faults import Noise, Scenario
from fdikit.model import LinearFaultModel
from fdikit.monitor.declarative import design_monitor
from fdikit.monitor.declarative_thresholds import _new_record_levels
from fdikit.residuals import FaultDetectionFilter
from fdikit.sim import simulate

PLANT = LinearFaultModel([[-1.0]], [[1.0]], [[1.0]], inputs=["u"], outputs=["y"])
DESIGN = {"sample_time": 0.01,
          "plant": {"A": [[-1.0]], "B": [[1.0]], "C": [[1.0]], "inputs": ["u"], "outputs": ["y"]},
          "faults": {"names": ["sensor:y"]},
          "noise": {"measurement": {"y": 1e-2}, "process": 1e-4},
          "alarm": {"pfa": 0.1, "per": "sample", "hold": 1}, "accept_miscalibrated": True}


def _records(seed: int, n: int, high: float = 0.2, share: float = 0.25) -> dict[str, Signals]:
    """``n`` nominal records of 20 s; a random quarter of them sits at a sensor offset of +-``high``
    (twice the noise's sd), the others at none: records at their own levels."""
    sc = Scenario(duration=20.0, dt=0.01, inputs=lambda t: np.sin(0.5 * t),
                  noise=Noise(measurement=np.array([1e-2]), process=np.array([1e-4])))
    res = simulate(PLANT, sc, runs=n, seed=seed, keep=("y", "u"))
    rng = np.random.default_rng(seed + 100)
    off = np.where(rng.random(n) < share, high, 0.0) * rng.choice([-1.0, 1.0], n)
    return {f"record {seed}.{r}": Signals(res.y.t, np.c_[res.u.values[r], res.y.values[r] + off[r]][None],
                                          ["u", "y"], check=False) for r in range(n)}


def _design(recs):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return design_monitor(DESIGN, nominal=recs)


def _fresh_rate(d, seed: int) -> float:
    """Mean over 20 fresh records (each weighted alike) of the family's per-sample rate."""
    gen = FaultDetectionFilter(d["bank"])
    return float(np.mean([np.mean(np.any(d["hold"].run(d["features"].run(gen.run(s))).values[0][100:] > 0.5,
                                         axis=1)) for s in _records(1000 + seed, 20).values()]))


def test_a_new_record_meets_the_target_where_the_pooled_design_exceeds_it():
    """20 designs, each on 8 records at their own levels, each judged on 20 fresh records: the mean
    rate on a new record is at most the 10 % target, and inside the stated interval for 19 of 20.
    Fails on main: the pooled quantile measures 0.111 on fresh records (this measures 0.090)."""
    rates, inside = [], []
    for seed in range(20):
        d = _design(_records(seed, 8))
        fam = next(c for c in d["_report"]["claims"] if c["kind"] == "family")
        m = _fresh_rate(d, seed)
        rates.append(m)
        inside.append(fam["interval"][0] <= m <= fam["interval"][1])
    assert np.mean(rates) <= 0.1, np.mean(rates)
    assert np.mean(inside) >= 0.9, inside


def test_the_report_states_the_new_record_claim_and_what_it_rests_on():
    recs = _records(3, 8)
    d = _design(recs)
    rep = d["_report"]
    td = rep["threshold_design"]
    assert td["method"] == "new-record quantile (leave-one-record-out)"
    nr = td["new_record"]
    assert nr["supported"] and nr["claim"] == "per sample on a new record"
    fam = next(c for c in rep["claims"] if c["kind"] == "family")
    assert fam["per_what"] == "sample on a new record" and "8 nominal records" in fam["rests_on"]
    # the claim is the mean of the left-out records' rates at the chosen level, with its t-interval
    r = np.array(nr["family"]["per_record"])
    assert r.size == 8 and r.mean() <= 0.1 + 1e-12
    lo, hi = fam["interval"]
    assert lo <= r.mean() <= hi and np.isclose(hi - r.mean(), 2.3646 * r.std(ddof=1) / np.sqrt(8), rtol=1e-3)
    # every left-out record is measured at the chosen level of the others: its rate is in the report
    assert [row["rate"] for row in rep["record_check"]] == pytest.approx(r.tolist())
    assert np.isclose(fam["measured_records"]["rate"],
                      np.average(r, weights=[row["samples"] for row in rep["record_check"]]))
    # the thresholds are the chosen quantile level of the fit parts, not the pooled ones
    assert next(iter(rep["thresholds"].values())) != td["pooled_threshold"][0]


def test_fewer_than_three_records_keep_the_pooled_design():
    d = _design(dict(list(_records(4, 8).items())[:2]))
    td = d["_report"]["threshold_design"]
    assert "new_record" not in td and td["method"] != "new-record quantile (leave-one-record-out)"
    assert all("per_what" not in c for c in d["_report"]["claims"])


def test_a_target_no_level_meets_is_stated_not_hidden():
    """A left-out record far above the others alarms on every sample at any level: no threshold
    meets the target on a new record, and the helper says which feature and by how much."""
    rng = np.random.default_rng(0)

    def sig(x):
        return Signals(np.arange(x.size) * 0.1, x[None, :, None], ["f"], check=False)

    recs = [rng.standard_normal(300) + (8.0 if j == 0 else 0.0) for j in range(4)]
    folds = [([sig(x) for k, x in enumerate(recs) if k != j], sig(recs[j])) for j in range(4)]
    out = _new_record_levels(["f"], [sig(x) for x in recs], folds, 0.05, 0.95)
    assert out["supported"] is False and "'f'" in out["why"] and "target 0.05" in out["why"]
    ok = _new_record_levels(["f"], [sig(x) for x in recs[1:]],
                            [([sig(x) for k, x in enumerate(recs[1:]) if k != j], sig(recs[1 + j]))
                             for j in range(3)], 0.05, 0.95)
    assert ok["supported"] and ok["family"]["rate"] <= 0.05 and len(ok["thresholds"]) == 1


def test_smoothed_statistics_get_new_record_levels_at_the_deployed_constant():
    """An EWMA design is set for a new record too, its left-out records judged at the deployed
    constant; where the left-out designs are refused, the design says it kept the pooled thresholds."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        d = design_monitor({**DESIGN, "detect": {"smoothing": "ewma", "lambda": "auto"}},
                           nominal=_records(3, 8))
    td, claims = d["_report"]["threshold_design"], d["_report"]["claims"]
    assert td["method"] == "new-record quantile (leave-one-record-out)"
    assert all(c["smoothing"]["lambda"] == td["smoothing"]["lambda"] for c in claims)
    assert "EWMA" in claims[0]["rests_on"]
    with pytest.warns(UserWarning, match="on a new record .*only 0 of 8 records could be left out"):
        d = design_monitor({**DESIGN, "detect": {"smoothing": "ewma", "lambda": 0.5}}, nominal=_records(3, 8))
    td = d["_report"]["threshold_design"]
    assert td["new_record"]["supported"] is False and td["method"] == "split-conformal quantile of the EWMA"
