"""The README's snippets run as written (issue 30, item 7; so none can rot).

Every fenced ``bash`` / ``sh`` / ``console`` block is split into its commands (one a line, ``&&``
chains split, ``#`` comments dropped, ``$`` prompts of console blocks removed), and every command
is either run, in a copy of the repository's ``examples/``, ``benchmarks/`` and ``docs/`` beside a link to
``../shared`` (``fdikit`` is the fdikit these tests import, ``python`` this interpreter), or
skipped with one of the reasons listed in :data:`SKIP`, never silently: a README command that no
rule classifies fails :func:`test_every_readme_command_is_classified`. Optional parts written in
brackets (``[--json]``, ``[--plot fig.png]``) are left out. Commands in :data:`FAST` run in the
fast suite; the others are marked slow (Monte Carlo campaigns, designs, benchmarks). A command
that needs files an earlier README command makes runs that command first (:data:`NEEDS`).

Every ``python`` block runs as code, in this process, and prints something; the reconstruction
example reconstructs.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

import fdikit

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
TEXT = README.read_text() if README.exists() else ""
FENCE = re.compile(r"^```(\w*)[ \t]*\n(.*?)^```", re.S | re.M)

#: Commands that cannot run here, by rule (first match wins), each with its reason.
SKIP = [
    (r"^(\S*/)?pip install|^python -m venv", "needs pip and the network (installs packages)"),
    (r"^(\.venv/bin/)?pytest\b", "runs the test suite itself, of which this test is a part"),
    (r"^\.venv/bin/", "needs the .venv that 'python -m venv .venv && .venv/bin/pip install' makes "
                      "(pip and the network)"),
    (r"^candump\b", "needs can-utils (candump) and a live CAN interface"),
    (r"\b(CONFIG|CAN_CONFIG)\.toml\b|\bLOGS_DIR\b|\bDIR / compare\b",
     "a template: CONFIG.toml, CAN_CONFIG.toml, LOGS_DIR and DIR are placeholders for the user's own"),
]
#: The tutorial block is run as written by its own test.
TUTORIAL = "run as written by tests/monitor/test_own_system_tutorial.py (the tutorial block)"
#: Commands quick enough for the fast suite (a few seconds each).
FAST = {"fdikit --help", "fdikit car scenario --list", "fdikit car linearize --speed 20 --json"}
#: A command (regex on it) -> the README command (its start) that makes the files it reads.
NEEDS = [
    (r"logs/two-mass/", "fdikit example-log examples/two-mass/monitor.toml"),
    (r"^fdikit (monitor|codegen|report) .*examples/two-mass/monitor\.toml|^fdikit codegen examples/two-mass",
     "fdikit design examples/two-mass/monitor.toml"),
    (r"^fdikit report run\.html", "fdikit monitor logs/two-mass/fault.csv"),
]


def _tutorial_lines() -> set[str]:
    m = re.search(r"<!-- tutorial -->(.*?)<!-- /tutorial -->", TEXT, re.S)
    return {ln.strip() for ln in m.group(1).splitlines()} if m else set()


def readme_commands() -> list[str]:
    """Every command of the README's shell blocks, in order (see the module docstring)."""
    out = []
    for lang, body in FENCE.findall(TEXT):
        if lang not in ("bash", "sh", "console", "shell"):
            continue
        for line in body.replace("\\\n", " ").splitlines():
            line = line.strip()
            if lang == "console":
                if not line.startswith("$ "):
                    continue   # output shown in the block
                line = line[2:]
            line = re.sub(r"(^|\s)#.*$", "", line).strip()
            if line:
                out.extend(c.strip() for c in line.split(" && "))
    first = {}
    for c in out:   # one test per command as run (``fdikit demo`` and ``fdikit demo [--json]``: one)
        first.setdefault(runnable(c), c)
    return list(first.values())


def python_blocks() -> list[str]:
    return [body for lang, body in FENCE.findall(TEXT) if lang == "python"]


def runnable(cmd: str) -> str:
    """The command without its optional bracketed parts."""
    return re.sub(r"\s+", " ", re.sub(r"\s*\[[^\[\]]*\]", "", cmd)).strip()


def disposition(cmd: str) -> tuple[str, str]:
    """``("skip", reason)``, ``("fast", "")`` or ``("slow", "")``."""
    if cmd in _tutorial_lines():
        return "skip", TUTORIAL
    for pattern, reason in SKIP:
        if re.search(pattern, runnable(cmd)):
            return "skip", reason
    return ("fast", "") if runnable(cmd) in FAST else ("slow", "")


COMMANDS = readme_commands()


def _params():
    for cmd in COMMANDS:
        kind, _ = disposition(cmd)
        yield pytest.param(cmd, id=runnable(cmd)[:70], marks=[pytest.mark.slow] if kind == "slow" else [])


@pytest.fixture(scope="module")
def sandbox(tmp_path_factory):
    """A copy of the repository's examples and benchmarks beside ``shared``, ``fdikit`` and ``python``
    on PATH; returns (folder, env, the commands run so far)."""
    base = tmp_path_factory.mktemp("readme")
    repo = base / "repo"
    repo.mkdir()
    for d in ("examples", "benchmarks", "docs"):
        if (ROOT / d).exists():
            shutil.copytree(ROOT / d, repo / d, ignore=shutil.ignore_patterns("__pycache__", "_build"))
    if (ROOT.parent / "shared").exists():
        (base / "shared").symlink_to(ROOT.parent / "shared")
    bin_ = base / "bin"
    bin_.mkdir()
    (bin_ / "fdikit").write_text(f'#!/bin/sh\nexec "{sys.executable}" -m fdikit.cli "$@"\n')
    (bin_ / "fdikit").chmod(0o755)
    (bin_ / "python").symlink_to(sys.executable)
    env = {**os.environ, "PATH": f"{bin_}{os.pathsep}{os.environ.get('PATH', '')}",
           "PYTHONPATH": str(Path(fdikit.__file__).resolve().parents[1]), "MPLBACKEND": "Agg"}
    return repo, env, set()


def _run(cmd: str, sandbox) -> subprocess.CompletedProcess:
    repo, env, done = sandbox
    for pattern, first in NEEDS:
        if re.search(pattern, runnable(cmd)) and not runnable(cmd).startswith(first):
            pre = next((c for c in COMMANDS if c.startswith(first)), None)
            assert pre is not None, f"{cmd!r} needs a README command starting {first!r}, which is gone"
            if pre not in done:
                out = _run(pre, sandbox)
                assert out.returncode == 0, f"{pre} (needed by {cmd}):\n{out.stderr[-2000:]}"
    out = subprocess.run(["bash", "-c", runnable(cmd)], cwd=repo, env=env, capture_output=True, text=True,
                         timeout=3600)
    done.add(cmd)
    return out


def test_every_readme_command_is_classified():
    assert len(COMMANDS) >= 20, COMMANDS
    kinds = {c: disposition(c) for c in COMMANDS}
    assert all(k in ("fast", "slow") or reason for k, reason in kinds.values())
    assert FAST <= {runnable(c) for c in COMMANDS}, "a FAST command is no longer in the README"
    assert "fdikit demo" in {runnable(c) for c in COMMANDS}   # the main job is run (slow), not skipped


@pytest.mark.parametrize("cmd", list(_params()))
def test_readme_command_runs_as_written(cmd, sandbox):
    kind, reason = disposition(cmd)
    if kind == "skip":
        pytest.skip(f"{runnable(cmd)!r}: {reason}")
    out = _run(cmd, sandbox)
    assert out.returncode == 0, f"{runnable(cmd)}\nstdout: {out.stdout[-1500:]}\nstderr: {out.stderr[-3000:]}"
    assert "Traceback" not in out.stderr, out.stderr[-3000:]
    if re.search(r"^fdikit .*--json\b", runnable(cmd)) and "--follow" not in cmd:
        json.loads(out.stdout)   # exactly one JSON object


@pytest.mark.skipif(not python_blocks(), reason="README.md absent or without Python examples")
@pytest.mark.parametrize("i", range(len(python_blocks())))
def test_readme_python_example_runs(i):
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        exec(compile(python_blocks()[i], f"README.md python block {i}", "exec"), {"__name__": "__readme__"})
    assert buf.getvalue().strip(), "the example prints nothing"


def test_reconstruction_example_reconstructs():
    block = next((b for b in python_blocks() if "design_reconstructor" in b), None)
    if block is None:
        pytest.skip("no reconstruction example in the README")
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        exec(compile(block, "README.md reconstruction example", "exec"), {"__name__": "__readme__"})
    last = buf.getvalue().strip().splitlines()[-1]
    fhat, episodes = last.split(" ", 1)
    # the status flags the reaching phase right after the fault's jump (issue 31: no wrong
    # estimate is called sliding); a loss of sliding any longer than a millisecond is a failure
    lost = [float(x) for x in episodes.strip("[]").split(",") if x.strip()]
    assert abs(float(fhat) - 1.5) < 0.01 and all(d <= 1e-3 for d in lost), last
