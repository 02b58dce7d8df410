"""Issue 16, item 6: every traceback and silent case becomes a clear error, each with its own test.

Output paths are checked before any computation (the computation is replaced by a function that
fails the test if it is reached), bad arguments name the option, files are written with the
process's umask, and a config that maps two channels from one source column is refused.
"""

from __future__ import annotations

import io
import json
import os
import stat

import numpy as np
import pytest

from fdikit.cli import main
from fdikit.errors import DataError

TWO_MASS = """
[monitor]
artifacts = "designs"
on_invalid = "hold"
[log]
time = "t"
[channels.u]
[channels.pos1]
[channels.pos2]
[[generators]]
artifact = "obs"
"""

def _array_design():
    """A design whose artifact holds NPZ arrays (the ABS parity residual r1, its Butterworth
    sections), made here: a clean checkout has no designed examples."""
    from fdikit.systems.abs.residuals import ParityR1

    return ParityR1(1e-3)



def _fails_if_called(*args, **kwargs):  # pragma: no cover - reaching it is the failure
    raise AssertionError("the computation started before the output paths were checked")


def _run(capsys, *argv):
    code = main([str(a) for a in argv])
    return code, capsys.readouterr().err


# ----------------------------------------------------------------------------- reconstruct --h 0
@pytest.mark.parametrize("flag,value,needle", [("--h", "0", "--h must be a positive"),
                                               ("--h", "-1e-5", "--h must be a positive"),
                                               ("--t-final", "nan", "--t-final must be a positive"),
                                               ("--settle", "20", "--settle = 20.0 s must be smaller")])
def test_reconstruct_bad_step_is_a_clear_error(capsys, monkeypatch, flag, value, needle):
    import fdikit.systems.aircraft.reconstruction as rec

    monkeypatch.setattr(rec, "run_aircraft", _fails_if_called)
    code, err = _run(capsys, "reconstruct", "aircraft", f"{flag}={value}")
    assert code == 2 and needle in err, err
    assert "Traceback" not in err


# ----------------------------------------------------------------------------- Hold thresholds
def test_hold_threshold_count_differs_from_channel_count():
    from fdikit.detect import Hold

    with pytest.raises(DataError, match=r"3 thresholds given for 2 channels \['a', 'b'\]"):
        Hold(["a", "b"], [1.0, 2.0, 3.0])
    with pytest.raises(DataError, match="one threshold, or one per channel"):
        Hold(["a", "b"], [[1.0, 2.0]])
    with pytest.raises(DataError, match="must be a number"):
        Hold(["a"], "high")
    assert Hold(["a", "b"], [1.0]).threshold.tolist() == [1.0, 1.0]     # one for all still works
    assert Hold(["a", "b"], [1.0, 2.0]).threshold.tolist() == [1.0, 2.0]


# ----------------------------------------------------------------------------- save_artifact
def test_save_artifact_creates_a_missing_folder_and_names_a_bad_one(tmp_path):
    from fdikit.detect import Hold
    from fdikit.monitor import load_artifact, save_artifact

    p = save_artifact(tmp_path / "new" / "deeper" / "hold", Hold(["r"], 0.5, Z=2))
    assert p.exists() and load_artifact(p).Z == 2
    (tmp_path / "plain_file").write_text("x")
    with pytest.raises(DataError, match="is a file, not a folder"):
        save_artifact(tmp_path / "plain_file" / "hold", Hold(["r"], 0.5))
    leftovers = [f for f in tmp_path.rglob("*.tmp")]
    assert leftovers == []


def test_save_state_into_a_missing_folder_is_a_clear_error(tmp_path):
    from fdikit.monitor import save_state

    with pytest.raises(DataError, match="the folder .* does not exist"):
        save_state(tmp_path / "nope" / "ck.npz", {"x": np.zeros(2)})


# ----------------------------------------------------------------------------- umask
@pytest.mark.parametrize("mask", [0o022, 0o027, 0o002])
def test_artifacts_and_checkpoints_follow_the_umask(tmp_path, mask):

    from fdikit.detect import Hold
    from fdikit.monitor import save_artifact, save_state

    r1 = _array_design()
    old = os.umask(mask)
    try:
        a = save_artifact(tmp_path / "hold", Hold(["r"], 0.5))
        g = save_artifact(tmp_path / "r1", r1)
        c = save_state(tmp_path / "ck.npz", {"x": np.arange(3.0)})
    finally:
        os.umask(old)
    want = 0o666 & ~mask
    for f in (a, g.with_suffix(".npz"), c):
        assert stat.S_IMODE(f.stat().st_mode) == want, (f, oct(f.stat().st_mode))


# ----------------------------------------------------------------------------- output paths
@pytest.fixture
def two_mass(tmp_path):
    """A config whose artifacts do not exist: reaching build_monitor would be a different error."""
    cfg = tmp_path / "m.toml"
    cfg.write_text(TWO_MASS)
    log = tmp_path / "log.csv"
    log.write_text("t,u,pos1,pos2\n0,0,0,0\n0.01,0,0,0\n")
    (tmp_path / "a_file").write_text("x")
    return cfg, log, tmp_path


@pytest.mark.parametrize("option,where,needle", [
    ("--events", "missing/ev.jsonl", "does not exist"),
    ("--stats", "missing/st.parquet", "does not exist"),
    ("--plot", "missing/fig.png", "does not exist"),
    ("--plot", "fig.unknown", "must end in"),
    ("--report", "missing/r.html", "does not exist"),
    ("--report", "r.txt", "must end in .html"),
    ("--events", "a_file/ev.jsonl", "is a file, not a folder"),
    ("--stats", ".", "is a folder, not a file"),
])
def test_monitor_checks_output_paths_before_computing(capsys, monkeypatch, two_mass, option, where, needle):
    import fdikit.monitor.config as config

    cfg, log, d = two_mass
    monkeypatch.setattr(config, "build_monitor", _fails_if_called)
    monkeypatch.setattr(config, "read_log", _fails_if_called)
    code, err = _run(capsys, "monitor", log, "--config", cfg, option, d / where)
    assert code == 2 and needle in err and option in err, err


def test_follow_checks_checkpoint_and_events_before_reading(capsys, monkeypatch, two_mass):
    import fdikit.monitor.config as config

    cfg, log, d = two_mass
    monkeypatch.setattr(config, "build_monitor", _fails_if_called)
    code, err = _run(capsys, "monitor", log, "--config", cfg, "--follow", "--checkpoint", d / "no" / "ck.npz")
    assert code == 2 and "--checkpoint" in err and "does not exist" in err, err
    code, err = _run(capsys, "monitor", log, "--config", cfg, "--follow", "--events", d / "no" / "e.jsonl")
    assert code == 2 and "--events" in err, err


def test_abs_reconstruct_demo_report_fleet_example_log_check_outputs_first(capsys, monkeypatch, tmp_path):
    import fdikit.commands.demo as demo
    import fdikit.systems.abs.campaign as campaign
    import fdikit.systems.abs.plant as plant
    import fdikit.systems.aircraft.reconstruction as rec

    monkeypatch.setattr(plant, "simulate", _fails_if_called)
    monkeypatch.setattr(campaign, "run_campaign", _fails_if_called)
    monkeypatch.setattr(rec, "run_aircraft", _fails_if_called)
    monkeypatch.setattr(demo, "sections", lambda: {"linear": _fails_if_called})
    (tmp_path / "f").write_text("x")
    missing = tmp_path / "missing"
    cases = [
        (("abs", "simulate", "--plot", missing / "a.png"), "--plot"),
        (("abs", "campaign", "--report", missing / "a.html"), "--report"),
        (("reconstruct", "aircraft", "--plot", missing / "a.png"), "--plot"),
        (("reconstruct", "aircraft", "--report", missing / "a.html"), "--report"),
        (("demo", "--report", missing / "a.html"), "--report"),
        (("report", missing / "a.html"), "OUT"),
        (("example-log", tmp_path / "none.toml", "--out", tmp_path / "f" / "logs"), "--out"),
    ]
    for argv, option in cases:
        code, err = _run(capsys, *argv)
        assert code == 2 and option in err, (argv, err)
        assert "does not exist" in err or "not a folder" in err, (argv, err)


def test_fleet_out_under_a_file_is_refused_before_planning(capsys, two_mass):
    cfg, _, d = two_mass
    code, err = _run(capsys, "fleet", d, "--config", cfg, "--out", d / "a_file" / "out")
    assert code == 2 and "--out" in err and "not a folder" in err, err


def test_check_output_paths_tries_a_real_write(tmp_path, monkeypatch):
    """Root passes every permission check: the helper creates (and removes) a file to know."""
    import argparse
    import tempfile

    from fdikit.commands._output import check_output_paths

    def denied(*a, **k):
        raise PermissionError(13, "Permission denied")

    monkeypatch.setattr(tempfile, "TemporaryFile", denied)
    with pytest.raises(DataError, match="cannot write into the folder .*Permission denied"):
        check_output_paths(argparse.Namespace(events=str(tmp_path / "e.jsonl")), "events")
    assert list(tmp_path.iterdir()) == []


# ----------------------------------------------------------------------------- shared source column
SHARED = """
[channels.pos1]
source = "P"
{a}
[channels.pos2]
source = "P"
{b}
[[generators]]
artifact = "obs"
"""


def test_two_channels_from_one_source_column_are_refused(tmp_path):
    from fdikit.monitor.config import load_config

    p = tmp_path / "m.toml"
    p.write_text(SHARED.format(a="", b=""))
    with pytest.raises(DataError, match=r"channels \['pos1', 'pos2'\] all read the source column 'P'"):
        load_config(p)
    p.write_text(SHARED.format(a="", b="shared_source = true"))
    with pytest.raises(DataError, match="shared_source = true"):
        load_config(p)
    p.write_text(SHARED.format(a="shared_source = true", b="shared_source = true"))
    cfg = load_config(p)
    assert [c.source for c in cfg.channels] == ["P", "P"]


def test_config_plausibility_and_episode_keys_are_validated(tmp_path):
    from fdikit.monitor.config import load_config

    base = "[channels.y]\n{ch}\n[monitor]\n{mon}\n[log]\n{log}\n[[generators]]\nartifact = 'g'\n" \
           "[decision]\nchannels = ['a']\n{dec}\n"
    p = tmp_path / "m.toml"
    bad = [({"ch": "min = 2.0\nmax = 1.0"}, r"\[channels.y\] min = 2.0 must be below max = 1.0"),
           ({"ch": "max_rate = 0"}, r"\[channels.y\].max_rate must be > 0"),
           ({"ch": "spike = -1"}, r"\[channels.y\].spike must be > 0"),
           ({"ch": "spike_window = 10"}, "spike_window needs spike"),
           ({"ch": "min = 'low'"}, r"\[channels.y\].min must be int or float"),
           ({"mon": "max_gap = 0"}, r"\[monitor\].max_gap must be a finite number > 0"),
           ({"mon": "warmup = -1"}, r"\[monitor\].warmup must be a finite number >= 0"),
           ({"log": "time_unit = 'min'"}, r"\[log\].time_unit must be one of"),
           ({"dec": "clear_level = 0.9"}, "clear_level = 0.9 must be finite and not above level = 0.5"),
           ({"dec": "sizes = { b = 'r' }"}, r"\[decision\].sizes names channel 'b'"),
           ({"dec": "processor = 'x'"}, "takes 'channels' or 'processor', not both")]
    for parts, needle in bad:
        fill = {"ch": "", "mon": "", "log": "", "dec": "", **parts}
        p.write_text(base.format(**fill))
        with pytest.raises(DataError, match=needle):
            load_config(p)
    p.write_text(base.format(ch="min = -1\nmax = 1\nmax_rate = 5\nspike = 8\nspike_window = 20",
                             mon="max_gap = 0.05\nwarmup = 1.0\nmax_abs = 1e9", log="time_unit = 'ns'",
                             dec="clear_level = 0.25\nclear_after = 0.5\nsizes = { a = 'y' }"))
    cfg = load_config(p)
    assert cfg.channels[0].plausibility == {"min": -1.0, "max": 1.0, "max_rate": 5.0, "spike": 8.0,
                                            "window": 20}
    assert cfg.runtime == {"max_gap": 0.05, "warmup": 1.0, "max_abs": 1e9}
    assert cfg.time_unit == "ns" and cfg.decision["sizes"] == {"a": "y"}


def test_monitor_json_error_is_one_line_on_stderr(capsys, two_mass):
    cfg, log, d = two_mass
    code, err = _run(capsys, "monitor", log, "--config", cfg, "--json", "--events", d / "no" / "e.jsonl")
    out = capsys.readouterr().out
    assert code == 2 and out == "" and err.count("\n") == 1, (out, err)
    json.dumps(err)  # plain text, no traceback


def test_hold_step_refuses_nan_without_touching_its_state():
    from fdikit.detect import Hold

    h = Hold(["a", "b"], 1.0, Z=2)
    h.reset(1)
    h.step([2.0, 0.0])
    before = h.get_state()
    with pytest.raises(DataError, match="input channel 'b' is not finite"):
        h.step([2.0, np.nan])
    assert h.get_state()["_count"].tolist() == before["_count"].tolist()
    assert h.step([2.0, 0.0]).tolist() == [[1.0, 0.0]]


def test_config_folder_rate_and_level_are_clear_errors(tmp_path, capsys, two_mass):
    from fdikit.monitor.config import load_config

    (tmp_path / "adir").mkdir()
    with pytest.raises(DataError, match="is a folder, not a config file"):
        load_config(tmp_path / "adir")
    p = tmp_path / "ranges.toml"
    dec = "[decision]\nchannels = ['a']\n"
    for extra, needle in (("[log]\nrate = 0", r"\[log\].rate must be a positive"),
                          ("[log]\nrate = nan", r"\[log\].rate must be a positive"),
                          (dec + "level = 1.5", r"\[decision\].level must be in \(0, 1\]"),
                          (dec + "level = 0", r"\[decision\].level must be in")):
        p.write_text(f"[channels.y]\n[[generators]]\nartifact = 'g'\n{extra}\n")
        with pytest.raises(DataError, match=needle):
            load_config(p)
    cfg, _, d = two_mass
    code, err = _run(capsys, "monitor", d / "nope.csv", "--config", cfg, "--follow")
    assert code == 2 and "nope.csv: no such log file" in err, err


def test_corrupt_or_foreign_artifact_files_are_clear_errors(tmp_path):

    from fdikit.detect import Hold
    from fdikit.monitor import load_artifact, save_artifact

    r1 = _array_design()
    p = save_artifact(tmp_path / "r1", r1)
    npz = p.with_suffix(".npz")
    good = npz.read_bytes()
    npz.write_bytes(good[:200])
    with pytest.raises(DataError, match="missing, corrupt or unreadable"):
        load_artifact(p)
    with np.load(io.BytesIO(good)) as z:
        arrays = {k: z[k] for k in z.files}
    np.savez(npz, **arrays, zz=np.ones(2))
    with pytest.raises(DataError, match=r"holds arrays \['zz'\] that key 'arrays' .* does not list"):
        load_artifact(p)
    h = save_artifact(tmp_path / "hold", Hold(["r"], 0.5))
    m = json.loads(h.read_text())
    m["class"] = "os:system"
    h.write_text(json.dumps(m))
    with pytest.raises(DataError, match="'os:system', which is not an fdikit design class"):
        load_artifact(h)
