"""The channels' plausibility rules of a config reach the raw CAN frame checks on the config route
(``fdikit monitor``'s reader, :func:`fdikit.monitor.config.read_log`), in the source's unit
(issue 27, item 4: before, only a Python caller of fdikit.io.read_log got them)."""

from pathlib import Path

import numpy as np
import pytest

from fdikit.monitor.config import load_config, read_log, source_plausibility

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT / ".." / "shared" / "data" / "rav4-highway"
BLF, DBC = DATA / "drive.blf", DATA / "toyota_rav4.dbc"
YAW = "KINEMATICS.YAW_RATE"
pytestmark = pytest.mark.skipif(not BLF.exists(), reason=f"RAV4 data not found at {DATA}")


@pytest.fixture(scope="module")
def spiked(tmp_path_factory):
    """drive.blf with one KINEMATICS frame (the first after 40 s) reading 120 deg/s."""
    import can
    import cantools

    msgs = list(can.LogReader(str(BLF)))
    kin = cantools.database.load_file(str(DBC), strict=False).get_message_by_name("KINEMATICS")
    t0 = msgs[0].timestamp
    k = next(i for i, m in enumerate(msgs) if m.arbitration_id == kin.frame_id and m.timestamp - t0 > 40.0)
    vals = kin.decode(bytes(msgs[k].data), decode_choices=False)
    vals["YAW_RATE"] = 120.0
    path = tmp_path_factory.mktemp("spike") / "spike.blf"
    with can.BLFWriter(str(path)) as w:
        for i, m in enumerate(msgs):
            if i == k:
                m = can.Message(timestamp=m.timestamp, arbitration_id=m.arbitration_id,
                                data=kin.encode(vals, strict=False), is_extended_id=m.is_extended_id,
                                channel=m.channel)
            w.on_message_received(m)
    return path, msgs[k].timestamp - t0


def _config(tmp_path, rule):
    text = (f'[log]\nformat = "can"\ndbc = "{DBC.resolve()}"\nrate = 50.0\n'
            f'[channels.yaw]\nsource = "{YAW}"\nscale = 0.017453292519943295\nunit = "rad/s"\n{rule}'
            '[channels.speed]\nsource = "SPEED.SPEED"\nscale = 0.2777777777777778\n'
            '[design]\nrecipe = "m:f"\n[[generators]]\nartifact = "g"\n')
    p = tmp_path / "m.toml"
    p.write_text(text)
    return load_config(p)


@pytest.mark.parametrize("rule", ["spike = 8.0\n", "min = -1.0\nmax = 1.0\n"])
def test_config_rules_reach_the_frame_checks(spiked, tmp_path, rule):
    path, t_spike = spiked
    cfg = _config(tmp_path, rule)
    s = read_log(cfg, path)
    assert s.info[YAW].n_implausible == 1                      # the one frame, before resampling
    bad = np.flatnonzero(~s.valid[0, :, s.names.index(YAW)])
    assert 1 <= bad.size <= 2 and np.all(np.abs(s.t[bad] - t_spike) < 0.02)


def test_rules_in_the_source_unit(tmp_path):
    cfg = _config(tmp_path, "min = -1.0\nmax = 1.0\nspike = 8.0\n")
    rule = source_plausibility(cfg)[YAW]
    assert rule["spike"] == 8.0 and np.isclose(rule["max"], np.degrees(1.0))
    assert np.isclose(rule["min"], -np.degrees(1.0)) and "SPEED.SPEED" not in source_plausibility(cfg)
