"""The README's "Fault reconstruction on your own system" block, run as written (issue 17, item 4)."""

from __future__ import annotations

import contextlib
import io
from pathlib import Path

README = Path(__file__).resolve().parents[1] / "README.md"


def _block() -> str:
    s = README.read_text()
    sec = s[s.index("## Fault reconstruction on your own system"):]
    start = sec.index("```python") + len("```python")
    return sec[start:sec.index("```", start)]


def test_readme_smo_block_runs_and_prints_what_it_says():
    code = _block()
    assert "from fdikit.residuals import design_reconstructor" in code  # the public import
    out = io.StringIO()
    ns: dict = {}
    with contextlib.redirect_stdout(out):
        exec(compile(code, "README.md", "exec"), ns)
    lines = out.getvalue().splitlines()
    case, gamma, f_max = lines[0].split()
    assert case == "cascade" and float(gamma) > 0 and float(f_max) >= 2.0
    # each "# -> X" comment in the block is what its line prints
    expected = [c.split("# ->", 1)[1].strip() for c in code.splitlines() if "# ->" in c]
    assert lines[1:] == expected
    rec = ns["rec"]
    assert rec.info["l2_bound_from"].startswith("xi, the input of the uncertainty filter")
    assert rec.info["self_check"]["step_error"] <= rec.info["boundary_layers"]["accuracy"]
