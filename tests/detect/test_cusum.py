"""PeerCUSUM (issue 27, item 2): a two-sided CUSUM on each peer-check residual, checked against a
brute-force CUSUM; it isolates a shift below the peer check's threshold, merges with the peer
check, passes other members through, refuses bad input, and round-trips as an artifact."""

import numpy as np
import pytest

from fdikit import DataError, Signals
from fdikit.detect import PeerCUSUM, design_peer_cusum


def _inputs(e, peer=None, iso=None):
    """PeerCUSUM inputs (runs, T, 3 M) from residuals e (runs, T, M)."""
    peer = np.zeros_like(e) if peer is None else peer
    iso = np.zeros_like(e) if iso is None else iso
    return np.concatenate([e, peer, iso], axis=2)


def _brute(x, mu, nu):
    up = lo = 0.0
    out = []
    for v in x:
        up = max(0.0, up + v - mu - nu)
        lo = max(0.0, lo - v + mu - nu)
        out.append(max(up, lo))
    return np.array(out)


def test_statistic_is_the_two_sided_cusum_and_isolates_a_small_shift():
    rng = np.random.default_rng(1)
    T = 2000
    e = 0.1 * rng.standard_normal((1, T, 3))
    e[0, 1000:, 1] += 0.15                          # b: a shift of 1.5 sigma from sample 1000
    names = ["a", "b", "c"]
    nom = Signals(np.arange(900) * 0.02, _inputs(e[:, :900]), [f"peer:{m}{s}" for s in (":r", "", ":isolated")
                                                             for m in names])
    cu = design_peer_cusum(nom, {"g": names}, skip=50)
    s = Signals(np.arange(T) * 0.02, _inputs(e), cu.input_names)
    out = cu.run(s)
    # the statistic: the brute-force CUSUM over the threshold
    for j, m in enumerate(names):
        ref = _brute(e[0, :, j], cu.mean[m], cu.nu[m]) / cu.thresholds[m]
        assert np.allclose(out[f"cusum:{m}"][0], ref, rtol=1e-12, atol=1e-12)
    # no isolation on the nominal part; b isolated (only b) within 100 samples of the shift
    iso = np.stack([out[f"cusum:{m}:isolated"][0] for m in names])
    assert iso[:, :1000].max() == 0
    k = int(np.flatnonzero(iso[1])[0])
    assert 1000 <= k < 1100
    assert iso[[0, 2], 1000:].max() == 0
    # the peer check's statistic and isolation are merged in
    peer = np.zeros_like(e)
    peer[0, 10, 2] = 3.0
    out2 = cu.run(Signals(s.t, _inputs(e, peer, peer >= 1), cu.input_names))
    assert out2["cusum:c:stat"][0, 10] == 3.0 and out2["cusum:c:isolated"][0, 10] == 1.0


def test_step_equals_run_and_passthrough_and_round_trip():
    rng = np.random.default_rng(2)
    cu = PeerCUSUM({"g": ["a", "b"]}, {"a": 0.0, "b": 0.1}, {"a": 0.2, "b": 0.2}, {"a": 2.0, "b": 3.0},
                   warmup=5, passthrough=["w"])
    x = np.abs(rng.standard_normal((2, 300, len(cu.input_names))))   # peer statistics are >= 0
    x[:, :, :3] -= 0.8                                             # the residuals are signed
    s = Signals(np.arange(300) * 0.01, x, cu.input_names)
    batch = cu.run(s).values
    cu.reset(2)
    stream = np.stack([cu.step(x[:, k]) for k in range(300)], axis=1)
    assert np.array_equal(batch, stream)
    out = cu.run(s)
    assert np.all(out["cusum:w"] == 0)
    assert np.array_equal(out["cusum:w:stat"], s["peer:w"]) and np.array_equal(out["cusum:w:isolated"],
                                                                                s["peer:w:isolated"])
    assert np.all(out["cusum:a"][:, :5] == 0)                      # the warm-up takes nothing in
    cu2 = PeerCUSUM.from_dict(cu.to_dict())
    assert np.array_equal(cu2.run(s).values, batch)


def test_bad_input_is_named():
    cu = PeerCUSUM({"g": ["a", "b"]}, {"a": 0.0, "b": 0.0}, {"a": 0.1, "b": 0.1}, {"a": 1.0, "b": 1.0})
    cu.reset(1)
    x = np.zeros((1, 6))
    x[0, 4] = np.nan
    with pytest.raises(DataError, match="peer:a:isolated"):
        cu.step(x)
    with pytest.raises(DataError, match="thresholds"):
        PeerCUSUM({"g": ["a"]}, {"a": 0.0}, {"a": 0.1}, {"a": 0.0})
    with pytest.raises(DataError, match="lacks members"):
        PeerCUSUM({"g": ["a", "b"]}, {"a": 0.0}, {"a": 0.1, "b": 0.1}, {"a": 1.0, "b": 1.0})
    with pytest.raises(DataError, match="passthrough"):
        PeerCUSUM({"g": ["a"]}, {"a": 0.0}, {"a": 0.1}, {"a": 1.0}, passthrough=["a"])


def test_a_shift_of_a_member_that_is_not_announced_isolates_none():
    # c is a peer only (e.g. a yaw rate computed from the wheels): its shift is the largest, so
    # neither a nor b is isolated, although their CUSUMs grow too
    cu = PeerCUSUM({"g": ["a", "b", "c"]}, dict.fromkeys("abc", 0.0), dict.fromkeys("abc", 0.1),
                   dict.fromkeys("abc", 1.0), announce=["a", "b"])
    assert cu.input_names == ["peer:a:r", "peer:b:r", "peer:c:r", "peer:a", "peer:b", "peer:a:isolated",
                              "peer:b:isolated"]
    x = np.zeros((1, 100, 7))
    x[0, 10:, 0] = 0.3
    x[0, 10:, 2] = 0.6
    out = cu.run(Signals(np.arange(100) * 0.01, x, cu.input_names))
    assert out["cusum:a"][0, -1] > 1.0
    assert out["cusum:a:isolated"].max() == 0 and out["cusum:b:isolated"].max() == 0
    x[0, 10:, 2] = 0.0                       # without c's shift, a is isolated
    out = cu.run(Signals(np.arange(100) * 0.01, x, cu.input_names))
    assert out["cusum:a:isolated"][0, -1] == 1.0


def test_transfer_lets_a_peer_only_moved_by_the_faulty_member_not_hide_it():
    # c (a peer only, tighter threshold) moves by half of a's shift, as its median-of-peers reference
    # does: without a transfer it hides a; with the transfer bound (|c_1| k h_a / h_c = 1 * 0.5 * 1 / 0.25
    # = 2) a is isolated while c's CUSUM stays within twice a's; a larger shift of c itself still blocks
    mean, nu = dict.fromkeys("abc", 0.0), dict.fromkeys("abc", 0.05)
    h = {"a": 1.0, "b": 1.0, "c": 0.25}
    x = np.zeros((1, 200, 7))
    x[0, 10:, 0] = 0.3                       # a: a shift of 0.3
    x[0, 10:, 2] = 0.15                      # c: moved by half of it
    names = [f"peer:{m}:r" for m in "abc"] + ["peer:a", "peer:b", "peer:a:isolated", "peer:b:isolated"]
    s = Signals(np.arange(200) * 0.01, x, names)
    plain = PeerCUSUM({"g": list("abc")}, mean, nu, h, announce=["a", "b"]).run(s)
    assert plain["cusum:a"][0, -1] > 1.0 and plain["cusum:a:isolated"].max() == 0
    T = {"a": {"c": 2.0}, "b": {"c": 2.0}, "c": {"a": 0.5, "b": 0.5}}
    cu = PeerCUSUM({"g": list("abc")}, mean, nu, h, announce=["a", "b"], transfer=T)
    out = cu.run(s)
    k = int(np.flatnonzero(out["cusum:a:isolated"][0])[0])
    assert out["cusum:a"][0, k] >= 1.0 and out["cusum:a"][0, k - 1] < 1.0     # from a's own level 1 on
    assert out["cusum:b:isolated"].max() == 0
    x2 = x.copy()
    x2[0, 10:, 2] = 0.6                      # c moved by twice a's shift: more than a's fault explains
    out2 = cu.run(Signals(s.t, x2, s.names))
    assert out2["cusum:a"][0, -1] > 1.0 and out2["cusum:a:isolated"].max() == 0
    # the peer only's own fault-free level (up to its threshold) is allowed on top of the transfer: c
    # at 0.88 before a's fault, then moved by 0.5 per sample against the bound's 2.2 x 0.25 = 0.55: without
    # the "+ 1" it would block a until 0.88 + 0.5 n <= 0.55 n (n >= 18 samples), with it from g_a >= 1
    T3 = {"a": {"c": 2.2}, "b": {"c": 2.2}, "c": {"a": 0.25, "b": 0.25}}
    x3 = x.copy()
    x3[0, 8:10, 2] = 0.16                    # c's fault-free bump: 2 x 0.44
    x3[0, 10:, 2] = 0.175
    cu3 = PeerCUSUM({"g": list("abc")}, mean, nu, h, announce=["a", "b"], transfer=T3)
    out3 = cu3.run(Signals(s.t, x3, names))
    assert _brute(x3[0, :, 2], 0.0, 0.05)[9] / h["c"] == pytest.approx(0.88)      # c is not an output
    k3 = int(np.flatnonzero(out3["cusum:a:isolated"][0])[0])
    assert out3["cusum:a"][0, k3 - 1] < 1.0 <= out3["cusum:a"][0, k3] and k3 - 10 < 18
    # batch == streaming, round trip, repr
    cu.reset(1)
    stream = np.stack([cu.step(x[:, j]) for j in range(200)], axis=1)
    assert np.array_equal(stream, out.values)
    cu2 = PeerCUSUM.from_dict(cu.to_dict())
    assert cu2.transfer == cu.transfer and np.array_equal(cu2.run(s).values, out.values)
    assert "transfer=" in repr(cu)
    with pytest.raises(DataError, match="not two members"):
        PeerCUSUM({"g": list("abc")}, mean, nu, h, transfer={"a": {"z": 1.0}})
    with pytest.raises(DataError, match=">= 0"):
        PeerCUSUM({"g": list("abc")}, mean, nu, h, transfer={"a": {"c": -1.0}})


def test_design_transfer_is_the_median_bound_of_the_peer_gain():
    rng = np.random.default_rng(3)
    names = ["a", "b", "c"]
    e = 0.1 * rng.standard_normal((1, 900, 3))
    nom = Signals(np.arange(900) * 0.02, _inputs(e), [f"peer:{m}{s}" for s in (":r", "", ":isolated")
                                                      for m in names])
    coef = {"a": [0.0, 0.5], "b": [0.0, -2.0], "c": [0.0, 1.2]}
    cu = design_peer_cusum(nom, {"g": names}, skip=50, announce=["a", "b"], coef=coef)
    h = cu.thresholds
    # 2 peers each (even): k = 1/2; only announced <-> peer-only pairs
    assert cu.transfer == {"a": {"c": 1.2 * 0.5 * h["a"] / h["c"]}, "b": {"c": 1.2 * 0.5 * h["b"] / h["c"]},
                           "c": {"a": 0.5 * 0.5 * h["c"] / h["a"], "b": 2.0 * 0.5 * h["c"] / h["b"]}}
    assert design_peer_cusum(nom, {"g": names}, skip=50, announce=["a", "b"]).transfer is None
    with pytest.raises(DataError, match="peer gain of 'c'"):
        design_peer_cusum(nom, {"g": names}, skip=50, announce=["a", "b"], coef={"a": [0.0, 1.0]})
