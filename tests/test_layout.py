"""The size of the rooms (issue 25): no module of fdikit exceeds MAX_MODULE_LINES, no command
module exceeds MAX_COMMAND_LINES (a command only parses arguments, calls the library and prints).

The limits are the project's choice: a module over ~800 lines holds more than one concept (the
split of wave 3 brought every module under 900); a command over 200 lines does work that belongs
in the library, where a user can call it without the command line.
"""

from __future__ import annotations

from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[1] / "src" / "fdikit"
MAX_MODULE_LINES = 900
MAX_COMMAND_LINES = 200


def _lines(p: Path) -> int:
    with p.open(encoding="utf-8") as f:
        return sum(1 for _ in f)


def _modules() -> list[Path]:
    if not SRC.exists():
        pytest.skip("the source tree src/fdikit is not beside the tests")
    return sorted(p for p in SRC.rglob("*.py") if "__pycache__" not in p.parts)


def test_no_module_exceeds_the_limit():
    big = {str(p.relative_to(SRC)): n for p in _modules() if (n := _lines(p)) > MAX_MODULE_LINES}
    assert not big, f"modules over {MAX_MODULE_LINES} lines (split them along their concepts): {big}"


def test_no_command_module_exceeds_the_limit():
    cmds = [p for p in _modules() if p.parent.name == "commands"]
    assert len(cmds) >= 10, "the command modules were not found"
    big = {p.name: n for p in cmds if (n := _lines(p)) > MAX_COMMAND_LINES}
    assert not big, (f"command modules over {MAX_COMMAND_LINES} lines (move their work into the library): "
                     f"{big}")


def test_the_check_can_fail(tmp_path):
    """The counter sees a long file (the limit is not one that cannot be exceeded)."""
    f = tmp_path / "long.py"
    f.write_text("x = 1\n" * (MAX_MODULE_LINES + 1))
    assert _lines(f) > MAX_MODULE_LINES
