"""The RAV4 lateral example config on the real RAV4 minute, for the tests that run it: the data
folder (``../shared/data/rav4-highway`` from the repository) and the config written into a test's
folder with its DBC path made absolute, designed (:func:`rav4_config`)."""

from __future__ import annotations

from pathlib import Path

ROOT = Path(__file__).resolve().parents[3]
#: The real RAV4 minute (drive.blf) and its DBC.
DATA = ROOT / ".." / "shared" / "data" / "rav4-highway"


def rav4_config(tmp: Path, design: bool = True) -> Path:
    """``examples/rav4-lateral/monitor.toml`` written as ``tmp/monitor.toml`` with the DBC path
    made absolute, designed there (``design``); returns its path."""
    from fdikit.monitor.config import load_config, run_design

    text = (ROOT / "examples" / "rav4-lateral" / "monitor.toml").read_text()
    text = text.replace('dbc = "../../../shared/data/rav4-highway/toyota_rav4.dbc"',
                        f'dbc = "{(DATA / "toyota_rav4.dbc").resolve()}"')
    cfg = Path(tmp) / "monitor.toml"
    cfg.write_text(text)
    if design:
        run_design(load_config(cfg))
    return cfg
