"""fdikit.codegen: the generated C equals the Python monitor (issue 29).

Per generated stage, monitors built on random systems run on random logs with faults, NaN samples
and a gap: the C (double) gives bitwise the Python streaming outputs, statuses and events; the
float32 variant is measured. A NaN sample is refused in C as in Python without changing the
state; checkpoints move between C and Python and continue bitwise; a design changed after
generation is detected; unsupported stages are refused by name; the example config runs under
the address and undefined-behaviour sanitizers.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from fdikit import Signals
from fdikit.codegen import (
    CMonitor,
    c_to_py_state,
    compile_shared,
    config_digest,
    emit_monitor,
    find_compiler,
    generate,
    run_driver,
)
from fdikit.detect import GLRT, MHSSPT, FeatureNorms, Hold, TimeGated, UniformMeanGaussian
from fdikit.errors import DataError
from fdikit.isolate import SignatureDecision
from fdikit.model import LinearFaultModel
from fdikit.monitor import Decision, Monitor
from fdikit.monitor.plausibility import Plausibility
from fdikit.residuals import FaultDetectionFilter, FilterDesign, ObserverResidual, design_observer_residual

from .equivalence import (
    assert_stream_equal,
    c_events,
    c_then_python,
    changed_fields,
    f32_error,
    nan_sample,
    py_stream,
    python_then_c,
    same,
    sanitized_driver,
)
from .equivalence import generated as _build  # (the name the other codegen tests import)

pytestmark = pytest.mark.skipif(find_compiler() is None, reason="no C compiler (cc, gcc or clang) on PATH")

ROOT = Path(__file__).resolve().parents[2]
DT = 0.01


# ------------------------------------------------------------------ helpers
def _stable(rng, n, rho=0.85):
    A = rng.normal(size=(n, n))
    return A * rho / max(abs(np.linalg.eigvals(A)))


def _fdf_monitor(seed=0, **kw):
    """A random filter (3 states, 1 input, 2 outputs, 3 residuals), the norm of its residuals,
    a hold and an isolation by signature, a decision."""
    rng = np.random.default_rng(seed)
    n, q = 3, 3
    d = FilterDesign(_stable(rng, n), rng.normal(size=(n, 1)), rng.normal(size=(n, 2)),
                     rng.normal(size=(q, n)),
                     rng.normal(size=(q, 1)) * 0.1, rng.normal(size=(q, 2)), DT, ["u"], ["y0", "y1"],
                     ["r0", "r1", "r2"])
    d.A[0, 2] = 0.0   # a structural zero (skipped by the sparse rows)
    gen = FaultDetectionFilter(d)
    feats = FeatureNorms({"n01": ["r0", "r1"], "n2": ["r2"], "n12": ["r1", "r2"]}, DT, tau=0.03)
    hold = Hold(feats.output_names, [1.5, 1.2, 1.8], Z=3)
    iso = SignatureDecision([[0, 1, 1], [1, 0, 1], [1, 1, 0]], ["fa", "fb", "fc"], hold.output_names)
    dec = Decision(iso.output_names, 0.75, {c: c[6:] for c in iso.output_names}, clear_after=0.1)
    return Monitor([gen], [feats, hold, iso], dec, on_invalid="hold", **kw)


def _observer_monitor(seed=1, **kw):
    """An observer residual on a random plant, a GLRT, a signed hold, a time gate, a decision
    with a size channel."""
    rng = np.random.default_rng(seed)
    m = LinearFaultModel(_stable(rng, 3, 0.95), rng.normal(size=(3, 1)), rng.normal(size=(2, 3)), dt=DT,
                         inputs=["u"], outputs=["y0", "y1"])
    gen = ObserverResidual(design_observer_residual(m, method="poles", poles=[0.3, 0.4, 0.5]))
    glrt = GLRT(gen.output_names, mu0=[0.01, -0.02], sigma2=[0.04, 0.05], W=15)
    hold = Hold(glrt.output_names, [6.0, 7.0], Z=2)
    signed = Hold(gen.output_names, [0.5, 0.4], Z=4, absolute=False)
    gate = TimeGated(glrt.output_names, [5.0, 5.0], T=0.2)
    alarms = [*hold.output_names, *signed.output_names]
    dec = Decision(alarms, 0.5, {a: f"h{i}" for i, a in enumerate(alarms)}, clear_level=0.25,
                   clear_after=0.05,
                   size_channels={hold.output_names[0]: "r:y0"})
    return Monitor([gen], [glrt, hold, signed, gate], dec, on_invalid="hold", **kw)


def _mhsspt_monitor(q=0.01, **kw):
    """The random filter's features into an exact MHSSPT (three faults, a group), a decision on
    the posteriors."""
    base = _fdf_monitor()
    feats = base.processors[0]
    s = [0.3, 0.3, 0.3]
    dens = {"none": UniformMeanGaussian([0, 0, 0], s, s),
            "fa": UniformMeanGaussian([0, 1, 1], [0.3, 5, 5], s),
            "fb": UniformMeanGaussian([1, 0, 1], [5, 0.3, 5], s),
            "fc": UniformMeanGaussian([1, 1, 0], [5, 5, 0.3], s)}
    mh = MHSSPT(feats.output_names, dens, p=1e-3, q=q, groups={"ab": ["fa", "fb"]})
    dec = Decision(mh.output_names[1:4], 0.9, clear_after=0.1)
    return Monitor(base.generators, [feats, mh], dec, on_invalid="hold", **kw)


def _log(mon, seed=0, T=1500, gap=True):
    """Random inputs with faults (biases on the measurements), NaN and huge samples, and a gap."""
    rng = np.random.default_rng(seed)
    names = list(mon.input_names)
    x = rng.normal(scale=0.2, size=(T, len(names)))
    ys = [i for i, n in enumerate(names) if n.startswith("y")]
    x[300:500, ys[0]] += 2.5
    x[800:900, ys[-1]] -= 3.0
    x[1100:1200, ys] += 2.0
    x[120, ys[0]] = np.nan
    x[121:124, 0] = 1e300
    x[650, 0] = np.inf
    t = np.arange(T) * DT
    if gap:
        t[1000:] += 0.07   # seven samples missing
    return t, x, names


_REF: dict = {}


def _reference(built, which, seed):
    """The random log of ``seed`` and the Python streaming result on it (computed once)."""
    if (which, seed) not in _REF:
        mon = built[which][0]
        t, x, names = _log(mon, seed)
        _REF[which, seed] = (t, x, names, *py_stream(mon, t, x, names))
    return _REF[which, seed]


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("codegen")
    return {"fdf": (_fdf_monitor(), *_build(_fdf_monitor(), tmp, "fdk_fdf")),
            "obs": (_observer_monitor(), *_build(_observer_monitor(), tmp, "fdk_obs")),
            "mhsspt": (_mhsspt_monitor(), *_build(_mhsspt_monitor(), tmp, "fdk_mh"))}


# ------------------------------------------------------------------ per stage: C equals Python
@pytest.mark.parametrize("which", ["fdf", "obs", "mhsspt"])
@pytest.mark.parametrize("seed", [0, 1])
def test_c_equals_python_streaming(built, which, seed):
    _mon, _gen, c64, c32, _em = built[which]
    t, x, _names, py_out, py_status, py_ev = _reference(built, which, seed)
    assert_stream_equal(c64, t, x, (py_out, py_status, py_ev))
    assert len(py_ev) >= 4
    assert {1, 2} <= set(py_status.tolist())   # held samples and warm-up were exercised
    # float32: statistics within float resolution of the channel's scale; events compared
    err = f32_error(c32, t, x, py_out)
    assert err < 1e-3, err
    assert np.array_equal(c32.run(t, x)["status"], py_status)


@pytest.mark.parametrize("which", ["fdf", "obs", "mhsspt"])
def test_c_equals_python_batch(built, which):
    mon, _gen, c64, _c32, _em = built[which]
    t, x, names = _log(mon, 3)
    res = mon.run(Signals(t, x[None], names, check=False))
    out = c64.run(t, x)
    py = np.concatenate([res.residuals.values[0], res.statistics.values[0]], axis=1)
    assert np.allclose(out["out"], py, rtol=1e-12, atol=0)
    evs = sorted((e.k, e.kind, e.hypothesis, e.episode) for e in (*res.events, *res.cleared))
    assert sorted(e[:4] for e in c_events(out)) == evs


def test_each_stage_alone_equals_python(tmp_path):
    """One processor at a time behind an identity-like filter: the stage's own numbers."""
    rng = np.random.default_rng(5)
    d = FilterDesign(np.zeros((0, 0)), np.zeros((0, 0)), np.zeros((0, 2)), np.zeros((2, 0)), np.zeros((2, 0)),
                     np.eye(2), DT, [], ["a", "b"], ["ra", "rb"])
    stages = {"glrt": GLRT(["ra", "rb"], mu0=[0.1, -0.1], sigma2=[0.5, 2.0], W=7),
              "feat": FeatureNorms({"n": ["ra", "rb"]}, DT, 0.0),
              "hold": Hold(["ra", "rb"], [1.0, 0.5], Z=2, absolute=False),
              "gate": TimeGated(["ra", "rb"], [0.8, 1.2], T=0.05)}
    t = np.arange(400) * DT
    x = rng.normal(size=(400, 2)) + np.where(np.arange(400)[:, None] > 200, 1.0, 0.0)
    for key, st in stages.items():
        mon = Monitor([FaultDetectionFilter(d)], [st], None, on_invalid="hold")
        _gen, c64, _c32, _em = _build(mon, tmp_path / key, f"fdk_{key}", f32=False)
        py_out, py_status, _ = py_stream(mon, t, x, ["a", "b"])
        res = c64.run(t, x)
        assert np.array_equal(res["out"], py_out), key
        assert np.array_equal(res["status"], py_status), key


# ------------------------------------------------------------------ NaN refused, state unchanged
@pytest.mark.parametrize("which", ["fdf", "obs", "mhsspt"])
def test_nan_refused_without_changing_state(built, which):
    mon, _gen, c64, _c32, em = built[which]
    t, x, names = _log(mon, 4, gap=False)
    py_stream(mon, t[:400], x[:400], names)
    before, after = nan_sample(c64, t, x, 400, 1)
    bad = x[400].copy()
    bad[1] = np.nan
    py_before = mon.state()
    mon.step(float(t[400]), bad[None], names)
    assert mon.last_status == "cannot_judge"
    a = c_to_py_state(c64.layout, after, mon, em)
    p = mon.state()
    for g_c, g_p, g_b in zip(a["generators"] + a["processors"], p["generators"] + p["processors"],
                             py_before["generators"] + py_before["processors"]):
        assert same(g_c, g_p)   # the C state as Python reads it is Python's own state after the sample
        assert same(g_p, g_b)   # and Python kept its state
    names_changed = changed_fields(c64.layout, before, after)
    assert names_changed <= {"k", "held", "held_t", "t_prev"}, names_changed   # no stage state moved
    assert (a["k"], a["held"], a["held_t"], a["t_prev"]) == (p["k"], p["held"], p["held_t"], p["t_prev"])


def test_time_going_back_and_raise_mode(built, tmp_path):
    """Time not increasing is held (hold mode) as in Python; in raise mode an invalid sample or
    time returns an error code where Python raises, and neither changes the state."""
    mon, _gen, c64, _c32, _em = built["fdf"]
    t, x, names = _log(mon, 7, gap=False)
    t, x = t[:300], x[:300]
    c64.run(t[:200], x[:200])
    py_stream(mon, t[:200], x[:200], names)
    st, _o, _e = c64.step(t[150], x[200])
    mon.step(float(t[150]), x[200][None], names)
    assert st == 1 and mon.last_status == "cannot_judge"
    rest = c64.run(t[200:], x[200:], reset=False)
    py = [mon.step(float(t[k]), x[k][None], names) for k in range(200, 300)]
    assert np.array_equal(rest["out"], np.array([np.concatenate([r[0], s[0]]) for r, s, _ in py]))
    strict = _fdf_monitor()
    strict.on_invalid = "raise"
    _g, cs, _c, _em2 = _build(strict, tmp_path, "fdk_strict", f32=False)
    cs.run(t[:100], x[:100])
    before = cs.checkpoint()
    bad = x[100].copy()
    bad[2] = np.nan
    assert cs.step(t[100], bad)[0] == -2          # FDK_ERR_VALUE
    assert cs.step(t[50], x[100])[0] == -1        # FDK_ERR_TIME
    assert cs.step(np.nan, x[100])[0] == -1
    assert np.array_equal(cs.checkpoint(), before)
    py_stream(strict, t[:100], x[:100], names)
    with pytest.raises(DataError):
        strict.step(float(t[100]), bad[None], names)


def test_command_prints_one_json_object(own_system, tmp_path, capsys):
    import json

    from fdikit.cli import main

    ex, _tmp, _gen = own_system
    argv = ["codegen", str(ex / "monitor.toml"), "--out", str(tmp_path / "gen"), "--compile", "--json"]
    assert main(argv) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["stages"] == ["FaultDetectionFilter", "FeatureNorms", "Hold", "SignatureDecision"]
    assert out["compiled"]["double"]["state_bytes"] > out["compiled"]["float"]["state_bytes"] > 0
    assert out["design_hash"] == _gen["design_hash"]


# ------------------------------------------------------------------ checkpoints between C and Python
@pytest.mark.parametrize("which", ["fdf", "obs", "mhsspt"])
@pytest.mark.parametrize("cut", [130, 1003])
def test_checkpoint_c_to_python_and_back(built, which, cut):
    mon, _gen, c64, _c32, em = built[which]
    t, x, _names, full_out, full_status, full_ev = _reference(built, which, 0)
    # C first, Python continues
    assert np.array_equal(c_then_python(mon, c64, em, t, x, cut)[1], full_out[cut:])
    # Python first, C continues
    res, _back = python_then_c(mon, c64, em, t, x, cut)
    assert np.array_equal(res["out"], full_out[cut:])
    assert np.array_equal(res["status"], full_status[cut:])
    assert c_events(res) == [e for e in full_ev if e[0] >= cut]
    # and the C checkpoint restores in C
    c64.run(t[:cut], x[:cut])
    buf = c64.checkpoint()
    again = CMonitor(c64.lib._name, c64.layout)
    again.restore(buf)
    assert np.array_equal(again.checkpoint(), buf)


# ------------------------------------------------------------------ refused by name
class _Doubler(Hold):
    pass


def test_unsupported_stages_refused_by_name():
    from fdikit.base.stage import ResidualProcessor

    class Mystery(ResidualProcessor):
        input_names = ("r0",)
        output_names = ("m",)

        def reset(self, runs=1):
            pass

        def _step(self, r):
            return r

    base = _fdf_monitor()
    with pytest.raises(DataError, match="stage Mystery cannot be generated yet"):
        emit_monitor(Monitor(base.generators, [Mystery()]))
    with pytest.raises(DataError, match="stage _Doubler cannot be generated yet"):
        emit_monitor(Monitor(base.generators, [_Doubler(["r0"], 1.0)]))
    mh = _mhsspt_monitor().processors[1]
    tab = MHSSPT(mh.input_names, dict(zip(mh.hypotheses, mh.densities)), p=1e-3, tabulate=0.125)
    # (tabulated densities are generated since: tests/codegen/test_codegen_mhsspt_tab.py)
    assert "fdk_mhsspt_update_p" in emit_monitor(Monitor(base.generators, [base.processors[0], tab])).source
    # (plausibility rules are generated since: tests/codegen/test_codegen_plausibility.py)
    assert "s->pl_ref" in emit_monitor(Monitor(base.generators,
                                               plausibility={"y0": Plausibility(min=-1.0, max=1.0)})).source


# ------------------------------------------------------------------ the example config
@pytest.fixture(scope="module")
def own_system(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("own")
    ex = tmp / "own-system"
    shutil.copytree(ROOT / "examples" / "own-system", ex, ignore=shutil.ignore_patterns("designs"))
    from fdikit.monitor.config import load_config, run_design

    run_design(load_config(ex / "monitor.toml"))
    subprocess.run([sys.executable, str(ex / "simulate_logs.py"), str(tmp / "logs"), "--minutes", "0.6"],
                   check=True, capture_output=True)
    res = generate(ex / "monitor.toml", tmp / "c", name="fdk_own")
    return ex, tmp, res


def test_example_config_events_equal(own_system):
    from fdikit.monitor.config import build_monitor, load_config, map_channels, read_log

    ex, tmp, _gen = own_system
    cfg = load_config(ex / "monitor.toml")
    mon = build_monitor(cfg)
    c64 = CMonitor(compile_shared([tmp / "c" / "fdk_own.c"], tmp / "c" / "lib64.so"),
                   tmp / "c" / "fdk_own.layout.json")
    c32 = CMonitor(compile_shared([tmp / "c" / "fdk_own_f32.c"], tmp / "c" / "lib32.so"),
                   tmp / "c" / "fdk_own_f32.layout.json")
    c64.check_design(config_digest(cfg))
    n_onsets = 0
    for stem in ("nominal", "sensor_w_meas", "actuator_V"):
        log = tmp / "logs" / f"{stem}.csv"
        sig = map_channels(cfg, read_log(cfg, log))
        x = sig.values[0][:, sig.index(c64.layout["inputs"])]
        py_out, _status, py_ev = py_stream(mon, sig.t, x, c64.layout["inputs"])
        res = c64.run(sig.t, x)
        assert np.array_equal(res["out"], py_out), log.name
        assert c_events(res) == py_ev, log.name
        r32 = c32.run(sig.t, x)
        assert [e[:4] for e in c_events(r32)] == [e[:4] for e in py_ev], log.name   # float32: same events
        n_onsets += sum(e[1] == "onset" for e in py_ev)
    assert n_onsets >= 2   # each fault log announces its fault


def test_changed_design_detected(own_system):
    from fdikit.monitor.config import load_config

    ex, tmp, _gen = own_system
    c64 = CMonitor(compile_shared([tmp / "c" / "fdk_own.c"], tmp / "c" / "libchk.so"),
                   tmp / "c" / "fdk_own.layout.json")
    cfg = load_config(ex / "monitor.toml")
    c64.check_design(config_digest(cfg))
    hold = ex / "designs" / "hold.json"
    text = hold.read_text()
    try:
        hold.write_text(text.replace('"Z": 5', '"Z": 6') if '"Z": 5' in text else text + " ")
        with pytest.raises(DataError, match="design changed after generation"):
            c64.check_design(config_digest(load_config(ex / "monitor.toml")))
    finally:
        hold.write_text(text)


def test_under_sanitizers(built, tmp_path):
    """The generated code as a program under -fsanitize=address,undefined (no recovery): the same
    numbers and events as Python on a log with NaN, huge values and a gap."""
    which = "mhsspt"   # the most C: filter, features, erfc/log/exp densities, the recursion, episodes
    _mon, gen, _c64, _c32, _em = built[which]
    layout = gen["layout"]
    exe = sanitized_driver(gen, tmp_path)
    t, x, _names, py_out, py_status, py_ev = _reference(built, which, 0)
    res = run_driver(exe, layout, t, x)
    assert np.array_equal(res["out"], py_out)
    assert np.array_equal(res["status"], py_status)
    assert c_events(res) == py_ev and py_ev
    assert "runtime error" not in res["stderr"]
