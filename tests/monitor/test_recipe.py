"""A design recipe module beside its config file imports without PYTHONPATH (issue 15)."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from fdikit.errors import DataError
from fdikit.monitor.config import load_config, run_design

RECIPE = '''
import numpy as np
from fdikit.detect import Hold


def design(params):
    return {"hold": Hold(["r"], float(params.get("threshold", 0.5)), Z=int(params.get("Z", 3)))}
'''

CONFIG = '''
[monitor]
artifacts = "designs"
[channels.r]
[design]
recipe = "{module}:design"
[design.params]
threshold = 0.25
Z = 4
[[generators]]
artifact = "hold"
'''


def test_recipe_beside_the_config_imports_without_pythonpath(tmp_path):
    module = "my_plant_recipe_9f3"
    (tmp_path / f"{module}.py").write_text(RECIPE)
    cfg_path = tmp_path / "monitor.toml"
    cfg_path.write_text(CONFIG.format(module=module))
    out = run_design(load_config(cfg_path))
    manifest = json.loads(out["hold"].read_text())
    assert manifest["payload"]["__dict__"]["Z"] == 4
    assert str(tmp_path) not in sys.path          # the import did not leave the folder on sys.path


def test_recipe_beside_the_config_through_the_cli(tmp_path):
    """The same from the command line, in a fresh process started elsewhere (no PYTHONPATH)."""
    module = "my_cli_recipe_41b"
    (tmp_path / f"{module}.py").write_text(RECIPE)
    (tmp_path / "monitor.toml").write_text(CONFIG.format(module=module))
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    cmd = [sys.executable, "-m", "fdikit.cli", "design", str(tmp_path / "monitor.toml"), "--json"]
    res = subprocess.run(cmd, capture_output=True, text=True, cwd="/", env=env, timeout=300)
    assert res.returncode == 0, res.stderr
    assert "hold" in json.loads(res.stdout.strip().splitlines()[-1])["artifacts"]


def test_missing_recipe_names_the_places_looked(tmp_path):
    (tmp_path / "monitor.toml").write_text(CONFIG.format(module="no_such_recipe_module_x"))
    with pytest.raises(DataError, match="looked beside the config"):
        run_design(load_config(tmp_path / "monitor.toml"))
    (tmp_path / "monitor.toml").write_text(CONFIG.format(module="no_colon").replace(":design", ""))
    with pytest.raises(DataError, match="module:function"):
        run_design(load_config(tmp_path / "monitor.toml"))
