"""The CI check of the generated C (issue 29, item 3): an example config (own-system, with
plausibility rules added to its channels) designed, generated, compiled with
``-std=c99 -Wall -Wextra -Werror -pedantic`` (both variants) and run once as a program under
``-fsanitize=address,undefined`` (no recovery) on its fault log with injected artefacts: the
same statuses and events as the Python monitor, statistics bitwise. ``.ci/run`` runs this file
explicitly; without a C compiler it is skipped with the message below."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from fdikit.codegen import compile_shared, driver_source, find_compiler, generate, run_driver
from fdikit.errors import DataError

from .equivalence import c_events, py_stream

NO_CC = ("no C compiler (cc, gcc or clang) on PATH: the generated-C checks are skipped; install one "
         "(Debian/Ubuntu: apt-get install gcc; macOS: xcode-select --install) or set CC")
pytestmark = pytest.mark.skipif(find_compiler() is None, reason=NO_CC)

ROOT = Path(__file__).resolve().parents[2]

RULES = {"w_meas": "spike = 10.0\nspike_window = 20\n", "i_meas": "min = -50.0\nmax = 50.0\n"}


def _with_rules(cfg: Path) -> None:
    text = cfg.read_text()
    for ch, rule in RULES.items():
        head = f"[channels.{ch}]\n"
        assert head in text, ch
        text = text.replace(head, head + rule)
    cfg.write_text(text)


def test_example_strict_and_sanitized(tmp_path):
    from fdikit.monitor.config import build_monitor, load_config, map_channels, read_log, run_design

    ex = tmp_path / "own-system"
    shutil.copytree(ROOT / "examples" / "own-system", ex, ignore=shutil.ignore_patterns("designs"))
    _with_rules(ex / "monitor.toml")
    cfg = load_config(ex / "monitor.toml")
    run_design(cfg)
    subprocess.run([sys.executable, str(ex / "simulate_logs.py"), str(tmp_path / "logs"), "--minutes", "0.6"],
                   check=True, capture_output=True)
    gen = generate(ex / "monitor.toml", tmp_path / "c", name="fdk_ci")
    cdir = tmp_path / "c"
    for stem in ("fdk_ci", "fdk_ci_f32"):   # strict flags (harness.CFLAGS), both precisions
        compile_shared([cdir / f"{stem}.c"], cdir / f"lib{stem}.so")
    layout = gen["layout"]
    assert layout["plausibility"] is not None
    (tmp_path / "main.c").write_text(driver_source(layout))
    try:
        exe = compile_shared([tmp_path / "main.c", cdir / "fdk_ci.c"], tmp_path / "asan", sanitize=True,
                             shared=False, extra=(f"-I{cdir}",))
    except DataError as exc:
        pytest.skip(f"the compiler has no sanitizer runtime (libasan/libubsan): {str(exc)[-200:]}")
    cfg = load_config(ex / "monitor.toml")
    mon = build_monitor(cfg)
    sig = map_channels(cfg, read_log(cfg, tmp_path / "logs" / "sensor_w_meas.csv"))
    x = sig.values[0][:, sig.index(layout["inputs"])].copy()
    t = sig.t.copy()
    x[200, 0] = np.nan
    x[300:303, 1] = 1e300
    w = layout["inputs"].index("w_meas")
    x[150, w] += 40.0 * np.std(np.diff(x[:140, w]))   # a spike
    t[400:] += 5 * layout["dt"]              # a gap
    py_out, py_status, py_ev = py_stream(mon, t, x, layout["inputs"])
    res = run_driver(exe, layout, t, x)
    assert "runtime error" not in res["stderr"] and "AddressSanitizer" not in res["stderr"]
    assert np.array_equal(res["status"], py_status)
    assert np.array_equal(res["out"], py_out)
    assert c_events(res) == py_ev and py_ev
    assert (py_status == 1).sum() >= 5   # the NaN, the huge values and the spike were held
