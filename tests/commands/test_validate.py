"""``fdikit validate CONFIG LOGS...``: claims re-measured on nominal logs, exit codes, one JSON
object, clear errors (issue 26)."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pandas as pd
import pytest

from fdikit.cli import main
from fdikit.demo.example_logs import write_example_logs
from fdikit.monitor.config import load_config, run_design

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def two_mass(tmp_path_factory):
    d = tmp_path_factory.mktemp("validate")
    shutil.copy(ROOT / "examples" / "two-mass" / "monitor.toml", d / "monitor.toml")
    run_design(load_config(d / "monitor.toml"))
    logs = [write_example_logs(d / "monitor.toml", d / f"logs{s}", seed=100 + s)["logs"] for s in (1, 2)]
    return d, [lg["nominal"] for lg in logs], logs[0]["fault"]


def test_nominal_logs_confirm_the_claims(two_mass, capsys):
    d, nominal, _ = two_mass
    assert main(["validate", str(d / "monitor.toml"), *nominal]) == 0
    text = capsys.readouterr().out
    assert "family (any threshold)" in text and "no claim is contradicted" in text
    assert main(["validate", str(d / "monitor.toml"), *nominal, "--json"]) == 0
    lines = [ln for ln in capsys.readouterr().out.splitlines() if ln.strip()]
    assert len(lines) == 1
    out = json.loads(lines[0])
    assert out["exit_code"] == 0 and out["contradicted"] == [] and len(out["logs"]) == 2
    fam = next(c for c in out["claims"] if c["kind"] == "family")
    assert fam["per"] == "run" and fam["interval"][1] > 0 and fam["measured"]["events"] == 0
    assert fam["measured"]["interval"][1] == pytest.approx(1 - 0.025 ** 0.5)   # Clopper-Pearson, 0 of 2


def test_a_log_with_a_fault_contradicts_them(two_mass, capsys):
    d, _, fault = two_mass
    assert main(["validate", str(d / "monitor.toml"), fault, "--json"]) == 1
    out = json.loads(capsys.readouterr().out)
    verdicts = {c["name"]: c["verdict"] for c in out["claims"]}
    assert verdicts["threshold r:pos2"] == "above" and verdicts["decision (announcements)"] == "above"
    assert "family (any threshold)" in out["contradicted"]


def test_clear_errors(two_mass, tmp_path, capsys):
    d, nominal, _ = two_mass
    assert main(["validate", str(d / "monitor.toml"), str(tmp_path / "nope.csv")]) == 2
    assert "nope.csv: no such log file" in capsys.readouterr().err
    bad = tmp_path / "no_p2.csv"
    pd.read_csv(nominal[0]).drop(columns=["P2"]).to_csv(bad, index=False)
    assert main(["validate", str(d / "monitor.toml"), str(bad)]) == 2
    assert "P2" in capsys.readouterr().err
    shutil.copy(d / "monitor.toml", tmp_path / "fresh.toml")
    assert main(["validate", str(tmp_path / "fresh.toml"), nominal[0]]) == 2
    assert "run 'fdikit design" in capsys.readouterr().err
    assert main(["validate", str(tmp_path / "missing.toml"), nominal[0]]) == 2
    assert "no such config file" in capsys.readouterr().err


def test_help_states_the_exit_codes(capsys):
    with pytest.raises(SystemExit):
        main(["validate", "--help"])
    text = capsys.readouterr().out
    assert "Exit code: 0 when no claim is contradicted, 1 when" in text.replace("\n", " ").replace("  ", " ")
