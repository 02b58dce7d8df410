"""Your own system in ten minutes (issue 15, item 7): the README tutorial, run as written.

The README's tutorial block is parsed and every command in it is run, in a copy of
examples/own-system: design from the declarative config, example logs, the monitor on each log.
Every fault must be detected and isolated after its onset, and the nominal log must stay quiet.
"""

from __future__ import annotations

import io
import json
import os
import re
import shlex
import shutil
import subprocess
import sys
from contextlib import redirect_stdout
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
README = ROOT / "README.md"
EXAMPLE = ROOT / "examples" / "own-system"


def _tutorial_commands() -> list[str]:
    text = README.read_text()
    m = re.search(r"<!-- tutorial -->(.*?)<!-- /tutorial -->", text, re.S)
    assert m, "the README has no tutorial block (<!-- tutorial --> ... <!-- /tutorial -->)"
    cmds = [ln.strip() for ln in m.group(1).splitlines() if ln.strip().startswith(("fdikit ", "python "))]
    assert len(cmds) >= 3, cmds
    return cmds


def _run(cmd: str, cwd: Path) -> subprocess.CompletedProcess:
    argv = shlex.split(cmd)
    if argv[0] == "fdikit":
        argv = [sys.executable, "-m", "fdikit.cli", *argv[1:]]
    elif argv[0] == "python":
        argv = [sys.executable, *argv[1:]]
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    return subprocess.run(argv, cwd=cwd, capture_output=True, text=True, timeout=600, env=env)


@pytest.mark.skipif(not EXAMPLE.exists() or not README.exists(),
                    reason="examples/own-system or README absent")
def test_readme_tutorial_runs_as_written(tmp_path):
    shutil.copytree(EXAMPLE, tmp_path / "examples" / "own-system",
                    ignore=shutil.ignore_patterns("designs", "__pycache__"))
    for cmd in _tutorial_commands():
        res = _run(cmd, tmp_path)
        assert res.returncode == 0, f"{cmd}\n{res.stderr[-3000:]}"
    report = json.loads((tmp_path / "examples/own-system/designs/design_report.json").read_text())
    assert report["faults"] == ["actuator:V", "sensor:i_meas", "sensor:w_meas", "sensor:temp_meas"]
    assert "isolable pairs: 6" in report["isolability"]          # every pair of the 4 faults
    logs = sorted((tmp_path / "logs").glob("*.csv"))
    assert len(logs) == 5
    from fdikit.cli import main

    for log in logs:   # in this process (the README's own monitor command ran as a subprocess above)
        buf = io.StringIO()
        with redirect_stdout(buf):
            rc = main(["monitor", str(log), "--config", str(tmp_path / "examples/own-system/monitor.toml"),
                       "--json"])
        assert rc == 0
        out = json.loads(buf.getvalue().strip().splitlines()[-1])
        if log.stem == "nominal":
            assert out["n_events"] == 0, out["first_event"]
            continue
        fault = log.stem.replace("_", ":", 1)
        first = out["first_event"]
        assert first is not None, f"{fault} was not detected"
        assert first["hypothesis"] == fault, f"{fault} isolated as {first['hypothesis']}"
        assert 30.0 <= first["t"] < 32.0, f"{fault}: detected at {first['t']} s (onset 30 s)"
