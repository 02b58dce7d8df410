"""The architecture contract (DESIGN.md, issue 14): import-linter's contracts in pyproject.toml.

The layers point down (commands > systems > evaluate > monitor > estimate > isolate > detect >
residuals > design > sim > faults > model > io > base > signals > errors), the core never imports
a system, the systems are independent, and sibling modules have no import cycles. The first test
runs the contracts on the package; the others copy the source tree, plant one bad import and
check that the linter then fails and names it (so the contract is not one that cannot fail).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SRC = ROOT / "src" / "fdikit"
LINT = shutil.which("lint-imports") or str(Path(sys.executable).with_name("lint-imports"))


def _lint(cwd: Path, pythonpath: Path | None = None) -> subprocess.CompletedProcess:
    env = dict(os.environ)
    if pythonpath is not None:
        env["PYTHONPATH"] = str(pythonpath)
    return subprocess.run([LINT, "--no-cache"], cwd=cwd, env=env, capture_output=True, text=True, timeout=300)


def test_contracts_are_kept():
    if not Path(LINT).exists():
        pytest.skip("import-linter is not installed (pip install '.[test]')")
    res = _lint(ROOT)
    assert res.returncode == 0, res.stdout + res.stderr
    assert "4 kept, 0 broken" in res.stdout


def test_contract_covers_every_subpackage():
    """Every subpackage of fdikit is in a layer (a new package cannot slip past the contract)."""
    cfg = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["importlinter"]["contracts"]
    layers = next(c for c in cfg if c["id"] == "layers")["layers"]
    named = {x.strip().strip("()") for entry in layers for x in entry.split("|")}
    pkgs = {f"fdikit.{p.stem if p.suffix else p.name}" for p in SRC.iterdir()
            if (p.is_dir() and (p / "__init__.py").exists()) or (p.suffix == ".py" and p.stem != "__init__")}
    assert pkgs <= named, f"subpackages or modules outside the layers contract: {sorted(pkgs - named)}"


BAD_IMPORTS = [
    # (file to edit, line to append, contract that must break, text the report must contain)
    ("detect/glrt.py", "from ..systems.abs import plant as _bad  # noqa", "The core never imports a system",
     "fdikit.detect.glrt -> fdikit.systems.abs.plant"),
    ("residuals/observer.py", "from ..monitor import core as _bad  # noqa", "Layers",
     "fdikit.residuals.observer -> fdikit.monitor.core"),
    ("systems/car/model.py", "from ..abs import plant as _bad  # noqa", "independent",
     "fdikit.systems.car.model -> fdikit.systems.abs.plant"),
    ("io/can.py", "from . import formats as _bad  # noqa", "No import cycles", "fdikit.io"),
]


@pytest.mark.parametrize("path,line,contract,named", BAD_IMPORTS, ids=[b[2].split()[0] for b in BAD_IMPORTS])
def test_a_bad_import_breaks_the_contract(tmp_path, path, line, contract, named):
    if not SRC.exists():
        pytest.skip("the source tree src/fdikit is not beside the tests")
    if not Path(LINT).exists():
        pytest.skip("import-linter is not installed (pip install '.[test]')")
    shutil.copytree(SRC, tmp_path / "src" / "fdikit", ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copy(ROOT / "pyproject.toml", tmp_path / "pyproject.toml")
    good = _lint(tmp_path, tmp_path / "src")
    assert good.returncode == 0, good.stdout + good.stderr   # the copy itself is clean
    target = tmp_path / "src" / "fdikit" / path
    target.write_text(target.read_text() + "\n" + line + "\n")
    bad = _lint(tmp_path, tmp_path / "src")
    assert bad.returncode != 0, bad.stdout
    broken = bad.stdout.split("Broken contracts")[-1]
    assert contract in broken and named in broken, bad.stdout
