"""The config's ``[log]`` table on every route (issue 30): ``[log].time`` reaches the Parquet and
every table reader, ``[log].format = "can"`` / ``"candump"`` is honoured for a candump log named
``.csv``, in ``fdikit monitor``, the fleet and the design from logs; ``[monitor].artifacts``
naming a file is a clear error; ``design_hash`` follows the identification logs' contents
(issue 28)."""

from __future__ import annotations

import contextlib
import io
import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from fdikit.cli import main
from fdikit.errors import DataError

DBC = """VERSION ""

NS_ :

BS_:

BU_: ECU

BO_ 256 WHEELS: 6 ECU
 SG_ A : 0|16@1+ (0.01,0) [0|655.35] "m/s" ECU
 SG_ B : 16|16@1+ (0.01,0) [0|655.35] "m/s" ECU
 SG_ C : 32|16@1+ (0.01,0) [0|655.35] "m/s" ECU
"""

CONFIG = """
[monitor]
artifacts = "designs"

[log]
{log}

[channels.speed]
source = "{p}C"
[channels.wfl]
source = "{p}A"
[channels.wfr]
source = "{p}B"

[[generators]]
artifact = "diff"

[[processors]]
artifact = "hold"

[decision]
channels = ["r:diff:alarm"]
names = {{ "r:diff:alarm" = "wheels differ" }}
"""

N = 500
DT = 0.02


def _values():
    k = np.arange(N)
    a = 10.0 + 0.01 * np.round(100 * np.sin(0.01 * k)) / 100
    b = a.copy()
    b[300:] += 2.0   # a wheel reads 2 m/s more from sample 300: one episode
    return k * DT, a, b, np.full(N, 10.0)


def _monitor(folder: Path, log: str, prefix: str = "") -> Path:
    from fdikit.detect import Hold
    from fdikit.monitor import save_artifact
    from fdikit.residuals import FilterDesign

    a = float(np.exp(-DT / 0.2))
    diff = FilterDesign(np.array([[a]]), np.zeros((1, 1)), np.array([[1 - a, -(1 - a)]]), np.ones((1, 1)),
                        np.zeros((1, 1)), np.zeros((1, 2)), DT, ["speed"], ["wfl", "wfr"], ["r:diff"])
    (folder / "designs").mkdir(exist_ok=True)
    save_artifact(folder / "designs" / "diff", diff)
    save_artifact(folder / "designs" / "hold", Hold(["r:diff"], 0.5, Z=5))
    (folder / "car.dbc").write_text(DBC)
    cfg = folder / "m.toml"
    cfg.write_text(CONFIG.format(log=log, p=prefix))
    return cfg


def _parquet(path: Path) -> Path:
    t, a, b, c = _values()
    pd.DataFrame({"stamp": t, "A": a, "B": b, "C": c}).to_parquet(path)
    return path


def _candump(path: Path) -> Path:
    t, a, b, c = _values()
    lines = []
    for k in range(N):
        payload = b"".join(round(x[k] * 100).to_bytes(2, "little") for x in (a, b, c))
        lines.append(f"({1700000000 + t[k]:.6f}) can0 100#{payload.hex().upper()}")
    path.write_text("\n".join(lines) + "\n")
    return path


def _run_monitor(log: Path, cfg: Path) -> dict:
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        rc = main(["monitor", str(log), "--config", str(cfg), "--json"])
    assert rc == 0
    return json.loads(buf.getvalue())


def _fleet_row(log: Path, cfg: Path, out: Path) -> dict:
    from fdikit.fleet import plan
    from fdikit.fleet.process import process_log

    tasks = plan([str(log)], cfg, out)
    assert len(tasks) == 1
    return process_log(tasks[0])


# ------------------------------------------------------------------ 1. [log].time
def test_log_time_reaches_the_parquet_reader_in_the_monitor(tmp_path):
    cfg = _monitor(tmp_path, 'time = "stamp"')
    out = _run_monitor(_parquet(tmp_path / "drive.parquet"), cfg)
    assert out["samples"] == N and out["n_events"] == 1, out


def test_log_time_reaches_the_parquet_reader_in_the_fleet(tmp_path):
    cfg = _monitor(tmp_path, 'time = "stamp"')
    (tmp_path / "logs").mkdir()
    row = _fleet_row(_parquet(tmp_path / "logs" / "drive.parquet"), cfg, tmp_path / "out")
    assert row["status"] == "ok" and row["samples"] == N and row["episodes"] == 1, row


def test_a_parquet_without_the_time_column_names_the_config_key(tmp_path):
    cfg = _monitor(tmp_path, "")
    buf = io.StringIO()
    with contextlib.redirect_stderr(buf):
        assert main(["monitor", str(_parquet(tmp_path / "drive.parquet")), "--config", str(cfg)]) == 2
    assert "[log].time" in buf.getvalue(), buf.getvalue()


def test_log_time_reaches_the_design_logs(tmp_path):
    from fdikit.monitor.declarative import identification_from_config

    rng = np.random.default_rng(3)
    u = rng.normal(size=600)
    y = np.zeros(600)
    for k in range(1, 600):
        y[k] = 0.9 * y[k - 1] + 0.1 * u[k - 1]
    pd.DataFrame({"stamp": np.arange(600) * 0.1, "u": u, "y": y + 1e-3 * rng.normal(size=600)}).to_parquet(
        tmp_path / "nominal.parquet")
    spec = {"logs": ["nominal.parquet"], "inputs": ["u"], "outputs": ["y"], "order": 1}
    with pytest.raises(DataError, match="no time column"):
        identification_from_config(spec, tmp_path)
    ident = identification_from_config(spec, tmp_path, log={"time": "stamp"})
    assert ident.model.outputs == ["y"]


def test_run_design_reads_its_logs_as_the_log_table_says(tmp_path, monkeypatch):
    import fdikit.monitor.declarative as declarative
    from fdikit.monitor.config import load_config, run_design

    seen = {}

    def fake(design, base_dir, **kw):
        seen.update(kw)
        raise DataError("stop here")

    monkeypatch.setattr(declarative, "design_monitor", fake)
    cfg = _monitor(tmp_path, 'time = "stamp"')
    cfg.write_text(cfg.read_text() + '\n[design.plant]\nidentify = { logs = ["x.parquet"], inputs = ["u"], '
                   'outputs = ["y"] }\n')
    with pytest.raises(DataError, match="stop here"):
        run_design(load_config(cfg))
    assert seen["log"]["time"] == "stamp"


# ------------------------------------------------------------------ 2. [log].format
@pytest.mark.parametrize("fmt", ["can", "candump"])
def test_a_declared_can_format_reads_a_candump_log_named_csv(tmp_path, fmt):
    cfg = _monitor(tmp_path, f'format = "{fmt}"\ndbc = "car.dbc"\nrate = 50', prefix="WHEELS.")
    log = _candump(tmp_path / "drive.csv")
    out = _run_monitor(log, cfg)
    assert out["samples"] == N and out["n_events"] == 1, out


def test_a_declared_can_format_in_the_fleet(tmp_path):
    cfg = _monitor(tmp_path, 'format = "can"\ndbc = "car.dbc"\nrate = 50', prefix="WHEELS.")
    (tmp_path / "logs").mkdir()
    row = _fleet_row(_candump(tmp_path / "logs" / "drive.csv"), cfg, tmp_path / "out")
    assert row["status"] == "ok" and row["format"] == "candump" and row["episodes"] == 1, row


def test_a_declared_can_format_in_the_design_logs(tmp_path):
    from fdikit.monitor.declarative import _read_design_log

    _monitor(tmp_path, "")
    log = _candump(tmp_path / "drive.csv")
    s = _read_design_log(log, {"format": "can", "dbc": "car.dbc", "rate": 50}, tmp_path,
                         ["WHEELS.A", "WHEELS.B"], None)
    assert s.names == ["WHEELS.A", "WHEELS.B"] and s.n_samples == N


def test_a_declared_can_format_refuses_a_file_that_is_no_can_log(tmp_path):
    cfg = _monitor(tmp_path, 'format = "can"\ndbc = "car.dbc"', prefix="WHEELS.")
    log = tmp_path / "drive.csv"
    log.write_text("t,A,B,C\n0,1,1,1\n")
    buf = io.StringIO()
    with contextlib.redirect_stderr(buf):
        assert main(["monitor", str(log), "--config", str(cfg)]) == 2
    assert "declared one of ['blf', 'asc', 'candump']" in buf.getvalue(), buf.getvalue()


def test_an_unknown_log_format_is_refused_by_name(tmp_path):
    from fdikit.monitor.config import load_config

    cfg = _monitor(tmp_path, 'format = "xlsx"')
    with pytest.raises(DataError, match=r"\[log\].format must be one of .*'xlsx'"):
        load_config(cfg)


def test_log_formats_are_the_readers_formats():
    from fdikit.io.formats import FORMATS
    from fdikit.monitor.logs import LOG_FORMATS

    assert set(LOG_FORMATS) == {"auto", "can", *FORMATS}


# ------------------------------------------------------------------ 4. artifacts naming a file
def test_artifacts_naming_a_file_says_it_needs_a_folder(tmp_path):
    cfg = _monitor(tmp_path, "")
    (tmp_path / "designs.txt").write_text("not a folder")
    cfg.write_text(cfg.read_text().replace('artifacts = "designs"', 'artifacts = "designs.txt"'))
    buf = io.StringIO()
    with contextlib.redirect_stderr(buf):
        assert main(["monitor", str(_parquet(tmp_path / "d.parquet")), "--config", str(cfg)]) == 2
    err = buf.getvalue()
    assert "[monitor].artifacts" in err and "is a file" in err and "designs.txt" in err, err
    assert "need a folder" in err, err
    assert "FileExistsError" not in err


# ------------------------------------------------------------------ 8. design_hash (issue 28)
def test_design_hash_follows_the_identify_logs_contents(tmp_path):
    from fdikit.monitor.config import design_hash, load_config

    cfg = _monitor(tmp_path, 'time = "stamp"')
    (tmp_path / "a.csv").write_text("t,u,y\n0,1,2\n")
    (tmp_path / "b.csv").write_text("t,u,y\n0,1,2\n")
    cfg.write_text(cfg.read_text() + '\n[design.plant]\nidentify = { logs = ["a.csv", "b.csv"], '
                   'inputs = ["u"], outputs = ["y"] }\n')
    h0 = design_hash(load_config(cfg))
    assert design_hash(load_config(cfg)) == h0
    (tmp_path / "b.csv").write_text("t,u,y\n0,1,2.5\n")   # same name, new content
    h1 = design_hash(load_config(cfg))
    assert h1 != h0
    cfg.write_text(cfg.read_text().replace('time = "stamp"', 'time = "t"'))   # how the logs are read
    assert design_hash(load_config(cfg)) != h1


def test_follow_mode_honours_the_declared_format(tmp_path):
    from fdikit.monitor.live import LiveMonitor

    cfg = _monitor(tmp_path, 'format = "csv"\ndbc = "car.dbc"\nrate = 50', prefix="WHEELS.")
    assert LiveMonitor(cfg).kind == "csv"      # a DBC named, but the lines are declared CSV
    cfg = _monitor(tmp_path, 'format = "candump"\ndbc = "car.dbc"\nrate = 50', prefix="WHEELS.")
    assert LiveMonitor(cfg).kind == "candump"
