"""The fdikit command: --version, --help, and demo --json printing exactly one JSON object."""

import json
import subprocess
import sys

import fdikit


def fdikit_cmd(*args, timeout=600):
    return subprocess.run([sys.executable, "-m", "fdikit.cli", *args], capture_output=True, text=True,
                          timeout=timeout)


def test_version_and_help():
    out = fdikit_cmd("--version")
    assert out.returncode == 0 and fdikit.__version__ in out.stdout
    out = fdikit_cmd("--help")
    assert out.returncode == 0 and "demo" in out.stdout


def test_demo_linear_json_detects_the_sensor_bias():
    out = fdikit_cmd("demo", "--only", "linear", "--json")
    assert out.returncode == 0, out.stderr
    lines = [ln for ln in out.stdout.splitlines() if ln.strip()]
    assert len(lines) == 1, out.stdout
    summary = json.loads(lines[0])["linear"]
    assert summary["detected"] == "sensor:pos2"
    assert summary["false_alarms_before_onset"] == 0
    assert 0 < summary["delay_s"] < 1.0


def test_abs_campaign_is_wired_and_prints_one_json_object():
    out = fdikit_cmd("abs", "campaign", "--runs", "20", "--seed", "3", "--json", "--no-progress")
    assert out.returncode == 0, out.stderr
    lines = [ln for ln in out.stdout.splitlines() if ln.strip()]
    assert len(lines) == 1
    d = json.loads(lines[0])
    for key in ("pd", "pf", "dmatrix", "sensitivity", "specificity", "wall_seconds"):
        assert key in d, key
    assert 0.0 <= d["specificity"] <= 1.0
