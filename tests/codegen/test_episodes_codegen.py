"""fdikit.codegen's episode rule (issue 29 after issues 27/28): the generated Decision gives the
Python streaming path's events exactly -- one episode per announced name (two channels of one
name: one onset, one cleared), groups whose type revisions are change events with the name they
replace, the component's own name never replacing a specific one -- and its state (the current
name, each name's previous on/off) crosses between C and Python checkpoints."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from fdikit import Signals
from fdikit.codegen import (
    CMonitor,
    c_to_py_state,
    compile_shared,
    driver_source,
    find_compiler,
    py_to_c_state,
    run_driver,
    subset_monitor,
)
from fdikit.detect import Hold
from fdikit.monitor import Decision, Monitor
from fdikit.residuals import FaultDetectionFilter, FilterDesign

from .test_codegen import DT, _build

pytestmark = pytest.mark.skipif(find_compiler() is None, reason="no C compiler (cc, gcc or clang) on PATH")

CH = ["a", "b", "c", "d", "e", "f"]
NAMES = {"a:alarm": "x:bias", "b:alarm": "x:gain", "c:alarm": "x", "d:alarm": "y", "e:alarm": "y",
         "f:alarm": "z:drift"}


def _monitor(groups=True):
    """Six inputs passed through as residuals, a signed hold each (Z = 1), a decision with a group
    (``x``: its own name and two types), a name of two channels (``y``) and a size channel."""
    n = len(CH)
    d = FilterDesign(np.zeros((0, 0)), np.zeros((0, 0)), np.zeros((0, n)), np.zeros((n, 0)), np.zeros((n, 0)),
                     np.eye(n), DT, [], CH, [f"r{c}" for c in CH])
    hold = Hold([f"r{c}" for c in CH], 0.5, Z=1, absolute=False)
    alarms = [f"{c}:alarm" for c in CH]
    names = {f"r{c}:alarm": NAMES[f"{c}:alarm"] for c in CH}
    dec = Decision([f"r{a}" for a in alarms], 0.5, names, clear_after=0.1,
                   size_channels={"x:gain": "rb"},
                   groups={"x": ["x", "x:bias", "x:gain"]} if groups else None)
    return Monitor([FaultDetectionFilter(d)], [hold], dec, on_invalid="hold", dt=DT)


def _scripted(T=800):
    """Alarms on at chosen samples (values 1.0 + channel / 10: the size channel of x:gain reads 1.1)."""
    x = np.zeros((T, len(CH)))
    on = {"d": [(100, 150)], "e": [(140, 200)],                       # one name, overlapping: one episode
          "c": [(300, 320), (360, 365)], "a": [(310, 355), (375, 420)], "b": [(350, 370)],
          "f": [(600, 610)]}
    for c, spans in on.items():
        for a, b in spans:
            x[a:b, CH.index(c)] = 1.0 + CH.index(c) / 10
    return np.arange(T) * DT, x


def _random(seed, T=3000):
    """Random bursts on every channel, a NaN sample and a gap."""
    rng = np.random.default_rng(seed)
    x = np.zeros((T, len(CH)))
    for j in range(len(CH)):
        for a in rng.integers(0, T - 50, size=25):
            x[a:a + rng.integers(1, 40), j] = rng.uniform(0.6, 2.0)
    x += rng.normal(scale=0.05, size=x.shape)
    x[700, 2] = np.nan
    t = np.arange(T) * DT
    t[2000:] += 0.05
    return t, x


def _py(mon, t, x, k0=0):
    if k0 == 0:
        mon.reset(1)
    out, ev = [], []
    for k in range(k0, len(t)):
        r, s, e = mon.step(float(t[k]), x[k][None], CH)
        out.append(np.concatenate([r[0], s[0]]))
        ev += [(e_.k, e_.kind, e_.hypothesis, e_.episode, e_.value, e_.size, e_.previous) for e_ in e]
    return np.array(out), ev


def _c(res):
    return [(e["k"], e["kind"], e["hypothesis"], e["episode"], e["value"], e["size"], e["previous"])
            for e in res["events"]]


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("episodes")
    mon = _monitor()
    return (mon, *_build(mon, tmp, "fdk_ep"))


def test_one_name_one_episode_and_group_changes(built):
    mon, _gen, c64, c32, _em = built
    t, x = _scripted()
    _out, py_ev = _py(mon, t, x)
    got = [(k, kind, h, ep, prev) for k, kind, h, ep, _v, _s, prev in py_ev]
    # y (channels d and e overlapping): one onset and one cleared
    assert got == [(100, "onset", "y", 0, None), (209, "cleared", "y", 0, None),
                   (300, "onset", "x", 1, None),
                   (310, "change", "x:bias", 1, "x"),        # a type replaces the component's own name
                   (350, "change", "x:gain", 1, "x:bias"),   # (x turning on again at 360: no change)
                   (375, "change", "x:bias", 1, "x:gain"),
                   (429, "cleared", "x:bias", 1, None),
                   (600, "onset", "z:drift", 2, None), (619, "cleared", "z:drift", 2, None)]
    assert py_ev[4][5] == 1.1 and py_ev[3][5] is None   # the size channel of x:gain (rb), none for x:bias
    res = c64.run(t, x)
    assert _c(res) == py_ev
    assert [e[:4] + e[6:] for e in _c(c32.run(t, x))] == [e[:4] + e[6:] for e in py_ev]


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_random_bursts_c_equals_python(built, seed):
    mon, _gen, c64, _c32, _em = built
    t, x = _random(seed)
    py_out, py_ev = _py(mon, t, x)
    res = c64.run(t, x)
    assert np.array_equal(res["out"], py_out)
    assert _c(res) == py_ev
    kinds = {e[1] for e in py_ev}
    assert kinds == {"onset", "cleared", "change"}
    # the batch path gives the same events (its own implementation of the rule)
    b = mon.run(Signals(t, x[None], CH, check=False))
    batch = sorted((e.k, e.kind, e.hypothesis, e.episode, e.previous)
                   for e in (*b.events, *b.cleared, *b.changes))
    assert batch == sorted(e[:4] + e[6:] for e in py_ev)


def test_simple_decision_without_groups_unchanged(tmp_path):
    """Without groups (and one channel per name) the rule is the per-channel one: no change events."""
    mon = Monitor(_monitor().generators, _monitor().processors,
                  Decision([f"r{c}:alarm" for c in CH], 0.5, {f"r{c}:alarm": c for c in CH}, clear_after=0.1),
                  on_invalid="hold", dt=DT)
    assert mon.decision._simple
    _gen, c64, _c32, _em = _build(mon, tmp_path, "fdk_simple", f32=False)
    t, x = _random(3)
    _out, py_ev = _py(mon, t, x)
    assert _c(c64.run(t, x)) == py_ev and {e[1] for e in py_ev} == {"onset", "cleared"}


@pytest.mark.parametrize("cut", [315, 355, 1234])
def test_checkpoint_with_group_state_crosses(built, cut):
    """Cut inside an open episode renamed by a change: the current name and the names' on/off
    carry over C -> Python and Python -> C, and the continuation's events are the same."""
    mon, _gen, c64, _c32, em = built
    t, x = _scripted(1500) if cut < 1000 else _random(4)
    full_out, full_ev = _py(mon, t, x)
    c64.run(t[:cut], x[:cut])
    st = c_to_py_state(c64.layout, c64.checkpoint(), mon, em)
    _py(mon, t[:cut], x[:cut])
    py_state = mon.state()
    for key in ("active", "below", "id", "count", "current", "prev_on"):
        assert np.array_equal(st["episodes"][key], py_state["episodes"][key]), key
    if cut < 1000:      # the open x episode (unit 0) names x:bias (315) or x:gain (355), not its onset's x
        assert st["episodes"]["active"][0, 0] and st["episodes"]["current"][0, 0] == {315: 0, 355: 1}[cut]
    mon.reset(1)
    mon.restore(st)
    out, ev = _py(mon, t, x, k0=cut)
    assert np.array_equal(out, full_out[cut:])
    assert ev == [e for e in full_ev if e[0] >= cut]
    _py(mon, t[:cut], x[:cut])
    fresh = CMonitor(c64.lib._name, c64.layout)
    fresh.restore(py_to_c_state(c64.layout, mon.state(), em))
    res = fresh.run(t[cut:], x[cut:], reset=False)
    assert _c(res) == [e for e in full_ev if e[0] >= cut]
    assert np.array_equal(res["out"], full_out[cut:])


def test_driver_program_reads_change_events(built, tmp_path):
    mon, gen, _c64, _c32, _em = built
    layout = gen["layout"]
    cdir = Path(gen["files"][0]).parent
    (tmp_path / "main.c").write_text(driver_source(layout))
    exe = compile_shared([tmp_path / "main.c", cdir / f"{layout['name']}.c"], tmp_path / "drv", shared=False,
                         extra=(f"-I{cdir}",))
    t, x = _scripted()
    _out, py_ev = _py(mon, t, x)
    assert _c(run_driver(exe, layout, t, x)) == py_ev


def test_subset_keeps_the_groups():
    mon = _monitor()
    sub = subset_monitor(mon, 1, alarms=["ra:alarm", "rc:alarm", "rd:alarm"])
    assert sub.decision.groups == {"x": ["x", "x:bias"]}
    assert subset_monitor(mon, 1, alarms=["rd:alarm"]).decision.groups is None


# ---------------------------------------------------------------- more than 64 alarm channels
#: 70 channels in 10 groups of 7 (the last group straddles the 64-bit word boundary of the
#: generated masks): the group's own name, a name of two channels, two more specific names and two
#: names outside every group.
WIDE = [f"w{j:02d}" for j in range(70)]


def _wide_monitor(confirm_after=0.0, unconfirmed="announce"):
    n = len(WIDE)
    d = FilterDesign(np.zeros((0, 0)), np.zeros((0, 0)), np.zeros((0, n)), np.zeros((n, 0)), np.zeros((n, 0)),
                     np.eye(n), DT, [], WIDE, [f"r{c}" for c in WIDE])
    hold = Hold([f"r{c}" for c in WIDE], 0.5, Z=1, absolute=False)
    kinds = ["", ":bias", ":bias", ":gain", ":drift"]
    names, groups = {}, {}
    for j in range(70):
        g, i = divmod(j, 7)
        names[f"r{WIDE[j]}:alarm"] = f"g{g}{kinds[i]}" if i < 5 else f"n{j}"
        groups[f"g{g}"] = [f"g{g}{k}" for k in dict.fromkeys(kinds)]
    dec = Decision([f"r{c}:alarm" for c in WIDE], 0.5, names, clear_after=0.1,
                   size_channels={"g9:gain": "rw01", "g0:bias": "rw66"}, groups=groups,
                   confirm_after=confirm_after, unconfirmed=unconfirmed)
    return Monitor([FaultDetectionFilter(d)], [hold], dec, on_invalid="hold", dt=DT)


def _wide_random(seed, T=2500):
    """Bursts per group (its channels switching on and off inside the burst) and a gap."""
    rng = np.random.default_rng(seed)
    x = rng.normal(scale=0.05, size=(T, len(WIDE)))
    for g in range(10):
        for a in rng.integers(0, T - 80, size=8):
            for j in rng.choice(7, size=rng.integers(1, 4), replace=False):
                b = a + rng.integers(0, 20)
                x[b:b + rng.integers(1, 50), 7 * g + j] = rng.uniform(0.6, 2.0)
    x[900, 66] = np.nan
    t = np.arange(T) * DT
    t[1500:] += 0.05
    return t, x


def _wide_py(mon, t, x, k0=0):
    if k0 == 0:
        mon.reset(1)
    out, ev = [], []
    for k in range(k0, len(t)):
        r, s, e = mon.step(float(t[k]), x[k][None], WIDE)
        out.append(np.concatenate([r[0], s[0]]))
        ev += [(e_.k, e_.kind, e_.hypothesis, e_.episode, e_.value, e_.size, e_.previous) for e_ in e]
    return np.array(out), ev


@pytest.fixture(scope="module")
def wide(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("wide")
    out = {}
    for key, kw in {"plain": {}, "drop": {"confirm_after": 0.1, "unconfirmed": "drop"}}.items():
        mon = _wide_monitor(**kw)
        out[key] = (mon, *_build(mon, tmp / key, f"fdk_wide_{key}", f32=False))
    return out


@pytest.mark.parametrize("key", ["plain", "drop"])
def test_more_than_64_channels_c_equals_python(wide, key):
    """Two words of channel masks: onsets, changes and cleared events of every group (the last
    straddling the words), sizes from either word, the wait of the groups' own names."""
    mon, gen, c64, _c32, em = wide[key]
    assert "#define FDK_EP_W 2" in (Path(gen["files"][0]).parent / f"fdk_wide_{key}.c").read_text()
    t, x = _wide_random(5)
    py_out, py_ev = _wide_py(mon, t, x)
    res = c64.run(t, x)
    assert np.array_equal(res["out"], py_out)
    assert _c(res) == py_ev
    kinds = {e[1] for e in py_ev}
    assert kinds == {"onset", "cleared", "change"} and len(py_ev) > 100
    assert {e[2].split(":")[0] for e in py_ev} >= {"g9", "g0", "n68"}
    assert any(e[5] is not None and e[2] == "g9:gain" for e in py_ev)
    # the state after the record (episodes, names on, waits) equals the streaming path's
    st = c_to_py_state(c64.layout, c64.checkpoint(), mon, em)
    for k, v in mon.state()["episodes"].items():
        assert np.array_equal(st["episodes"][k], v), k


def test_restore_over_another_record_rebuilds_the_names(built):
    """The C decision skips the names' pass while the same channels are on as at the last judged
    sample; a restored state (here over a C monitor that ran another record, ending with the same
    channels on) must not inherit that shortcut: the rise of x:bias after the cut is a change."""
    mon, _gen, c64, _c32, em = built
    T, cut = 400, 200
    t = np.arange(T) * DT
    xa, xb = np.zeros((T, len(CH))), np.zeros((T, len(CH)))
    xa[150:T, CH.index("c")] = xa[150:T, CH.index("a")] = 1.0   # record A: x and x:bias on before the cut
    xb[150:300, CH.index("c")] = 1.0                             # record B: x open, x:bias on at the cut
    xb[cut:260, CH.index("a")] = 1.0
    full_out, full_ev = _py(mon, t, xb)
    assert (cut, "change", "x:bias") in [e[:3] for e in full_ev]
    _py(mon, t[:cut], xb[:cut])
    c64.run(t[:cut], xa[:cut])
    c64.restore(py_to_c_state(c64.layout, mon.state(), em))
    res = c64.run(t[cut:], xb[cut:], reset=False)
    assert _c(res) == [e for e in full_ev if e[0] >= cut]
    assert np.array_equal(res["out"], full_out[cut:])
