"""fdikit.codegen.can: the generated DBC decoder equals cantools on random payloads (big- and
little-endian, signed and unsigned, truncated frames; the RAV4 DBC's signals), and the generated
gridder releases the samples of :class:`fdikit.io.stream.FrameGridder` (jittered rates, a gap, a
duplicated time stamp, an undecodable frame, time going back); the RAV4 example (main.c) prints
the events of ``fdikit monitor --follow`` on the same candump lines (slow)."""

from __future__ import annotations

import ctypes
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from fdikit.codegen import CFLAGS, compile_shared, find_compiler
from fdikit.codegen.can import emit_can_frontend

pytestmark = pytest.mark.skipif(find_compiler() is None, reason="no C compiler (cc, gcc or clang) on PATH")
ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT / ".." / "shared" / "data" / "rav4-highway"
DBC = '''VERSION ""
BO_ 100 FAST: 8 XXX
 SG_ A : 7|16@0- (0.01,-5) [-400|400] "" XXX
 SG_ B : 24|12@1+ (0.5,1) [0|100] "" XXX
BO_ 200 SLOW: 8 XXX
 SG_ C : 3|13@1- (1,0) [0|0] "" XXX
 SG_ D : 44|10@0+ (0.1,0) [0|100] "" XXX
'''
SOURCES = ["FAST.A", "FAST.B", "SLOW.C", "SLOW.D"]


class _Lib:
    """The compiled front end, through ctypes."""

    def __init__(self, tmp: Path, db, sources, rate=50.0, name="fdk_t", method="previous"):
        h, c = emit_can_frontend(db, sources, rate, [(k, 1.0, 0.0) for k in range(len(sources))], name=name,
                                 method=method)
        (tmp / f"{name}.h").write_text(h)
        (tmp / f"{name}.c").write_text(c)
        self.lib = ctypes.CDLL(str(compile_shared([tmp / f"{name}.c"], tmp / f"lib{name}.so")))
        self.n = len(sources)
        self.f = {k: getattr(self.lib, f"{name}_{k}") for k in ("init", "grid_size", "decode", "push",
                                                                 "flush")}
        vp = ctypes.c_void_p
        self.f["push"].argtypes = [vp, ctypes.c_double, ctypes.c_uint32, ctypes.c_char_p, ctypes.c_int, vp,
                                   ctypes.c_int]
        self.f["decode"].argtypes = [ctypes.c_uint32, ctypes.c_char_p, ctypes.c_int, vp, vp]
        self.f["flush"].argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_int]
        self.grid = ctypes.create_string_buffer(self.f["grid_size"]())
        self.f["init"](self.grid)
        self.rec = 2 + self.n                              # t, x[n], valid (+ padding): doubles
        self.out = np.zeros(4096 * self.rec)

    def decode(self, fid, data):
        v, hit = np.full(self.n, -1.0), np.zeros(self.n, np.int32)
        self.f["decode"](fid, bytes(data), len(data), v.ctypes.data, hit.ctypes.data)
        return v, hit

    def _samples(self, n):
        assert n >= 0, n
        rows = self.out[:n * self.rec].reshape(n, self.rec)
        valid = rows[:, -1].view(np.int64) & 0xFFFFFFFF
        return [(float(r[0]), r[1:1 + self.n].copy(), bool(ok)) for r, ok in zip(rows, valid)]

    def push(self, t, fid, data):
        n = self.f["push"](self.grid, t, fid, bytes(data), len(data), self.out.ctypes.data, 4096)
        return n if n == -1 else self._samples(n)

    def flush(self):
        return self._samples(self.f["flush"](self.grid, self.out.ctypes.data, 4096))


def _db(text=DBC):
    import cantools

    return cantools.database.load_string(text, database_format="dbc", strict=False)


def test_decoder_equals_cantools(tmp_path):
    db = _db()
    lib = _Lib(tmp_path, db, SOURCES)
    rng = np.random.default_rng(0)
    for _ in range(300):
        for msg in db.messages:
            n = int(rng.integers(0, 9))
            data = rng.integers(0, 256, n, dtype=np.uint8).tobytes()
            ref = msg.decode(data, decode_choices=False, scaling=True, allow_truncated=True)
            v, hit = lib.decode(msg.frame_id, data)
            for k, full in enumerate(SOURCES):
                m, s = full.split(".")
                if m != msg.name:
                    assert not hit[k]
                    continue
                assert hit[k]
                assert (np.isnan(v[k]) and s not in ref) or v[k] == float(ref[s]), (full, data.hex(), ref)


@pytest.mark.skipif(not (DATA / "toyota_rav4.dbc").exists(), reason=f"RAV4 DBC not found at {DATA}")
def test_decoder_equals_cantools_on_the_rav4_signals(tmp_path):
    import cantools

    from fdikit.systems.car.monitor_rav4 import RAW_SOURCES

    db = cantools.database.load_file(str(DATA / "toyota_rav4.dbc"), strict=False)
    sources = [s for s, _sc, _u in RAW_SOURCES.values()]
    lib = _Lib(tmp_path, db, sources, name="fdk_r")
    rng = np.random.default_rng(1)
    for full_k, full in enumerate(sources):
        m, s = full.split(".")
        msg = db.get_message_by_name(m)
        for _ in range(200):
            data = rng.integers(0, 256, msg.length, dtype=np.uint8).tobytes()
            ref = msg.decode(data, decode_choices=False, scaling=True, allow_truncated=True)
            assert lib.decode(msg.frame_id, data)[0][full_k] == float(ref[s])


def _frames(rng):
    """Two messages at ~100 and ~40 Hz with jitter, a 0.3 s pause of the slow one, a duplicated time
    stamp with another value, a truncated frame and a frame going back in time."""
    db = _db()
    fast, slow = db.get_message_by_name("FAST"), db.get_message_by_name("SLOW")
    out = []
    for k in range(400):
        out.append((1000.0 + 0.01 * k + 0.002 * rng.random(), fast.frame_id,
                    fast.encode({"A": 3 * np.sin(k / 20), "B": 10 + k % 50})))
    for k in range(160):
        t = 1000.003 + 0.025 * k + 0.003 * rng.random()
        if 1.5 < t - 1000 < 1.8:
            continue
        out.append((t, slow.frame_id, slow.encode({"C": int(100 * np.cos(k / 9)), "D": k % 90})))
    out.sort(key=lambda f: f[0])
    t_dup = out[50][0]
    out.insert(51, (t_dup, out[50][1], bytes(8)))                      # the same time, other payload
    out.insert(120, (out[119][0], fast.frame_id, b"\x01\x02"))          # truncated
    out.insert(200, (out[150][0], fast.frame_id, out[150][2]))          # back in time: refused
    return db, out


@pytest.mark.parametrize("method", ["previous", "linear"])
def test_gridder_equals_the_follow_mode_gridder(tmp_path, method):
    from fdikit.errors import DataError
    from fdikit.io.stream import FrameGridder

    db, frames = _frames(np.random.default_rng(2))
    lib = _Lib(tmp_path, db, SOURCES, rate=50.0, method=method)
    py = FrameGridder(db, SOURCES, 50.0, method=method)
    got, ref, refused = [], [], 0
    for t, fid, data in frames:
        c = lib.push(t, fid, data)
        try:
            p = py.push(t, fid, data)
        except DataError:
            assert c == -1
            refused += 1
            continue
        got += c
        ref += p
    got += lib.flush()
    ref += py.flush()
    assert refused == 1
    assert len(got) == len(ref) > 150
    assert any(why is not None for *_x, why in ref)                 # invalid samples were exercised
    for (tc, xc, ok), (tp, vals, why) in zip(got, ref):
        assert tc == tp
        xp = np.array([vals[s] for s in SOURCES])
        assert np.array_equal(xc, xp, equal_nan=True), (tc, xc, xp, why)
        assert ok == (why is None)


@pytest.mark.slow
@pytest.mark.skipif(not (DATA / "drive.blf").exists(), reason=f"RAV4 data not found at {DATA}")
def test_rav4_example_prints_the_follow_mode_events(tmp_path):
    """examples/rav4-c: design, generate (--can), compile main.c, run on 40 s of the real minute as
    candump lines with a yaw-rate fault from 25 s: the events of ``fdikit monitor - --follow``."""
    import cantools

    from fdikit.io.decode import decode_message, read_blf_table, set_signal

    text = (ROOT / "examples" / "rav4-c" / "monitor.toml").read_text()
    text = text.replace('dbc = "../../../shared/data/rav4-highway/toyota_rav4.dbc"',
                        f'dbc = "{(DATA / "toyota_rav4.dbc").resolve()}"')
    cfg = tmp_path / "monitor.toml"
    cfg.write_text(text)
    cli = [sys.executable, "-m", "fdikit.cli"]
    gen = tmp_path / "gen"
    codegen = ["codegen", str(cfg), "--out", str(gen), "--name", "fdk_rav4", "--can"]
    for args in (["design", str(cfg)], codegen):
        r = subprocess.run([*cli, *args], capture_output=True, text=True, timeout=900)
        assert r.returncode == 0, r.stderr
    exe = tmp_path / "rav4_monitor"
    r = subprocess.run([find_compiler(), *CFLAGS, f"-I{gen}", str(ROOT / "examples" / "rav4-c" / "main.c"),
                        str(gen / "fdk_rav4.c"), str(gen / "fdk_rav4_can.c"), "-o", str(exe), "-lm"],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    ts, ids, pay, _ = read_blf_table(DATA / "drive.blf")
    db = cantools.database.load_file(str(DATA / "toyota_rav4.dbc"), strict=False)
    msg = db.get_message_by_name("KINEMATICS")
    sel = np.flatnonzero((ids == msg.frame_id) & (ts - ts[0] >= 25.0))
    v, _ = decode_message(msg, ["YAW_RATE"], pay.take(sel))
    pay.matrix[sel] = set_signal(msg, "YAW_RATE", pay.take(sel), v[:, 0] + 5.0).matrix
    keep = ts - ts[0] < 40.0
    lines = "".join(f"({t:.6f}) can0 {i:03X}#{pay[k].hex().upper()}\n"
                    for k, (t, i) in enumerate(zip(ts, ids)) if keep[k])
    c = subprocess.run([str(exe)], input=lines, capture_output=True, text=True, timeout=300)
    assert c.returncode == 0, c.stderr
    ev = tmp_path / "events.jsonl"
    p = subprocess.run([*cli, "monitor", "-", "--config", str(cfg), "--follow", "--events", str(ev)],
                       input=lines, capture_output=True, text=True, timeout=900)
    assert p.returncode == 0, p.stderr
    py = [json.loads(x) for x in ev.read_text().splitlines()]
    py = [x for x in py if "kind" in x]
    got = [json.loads(x) for x in c.stdout.splitlines()]
    assert got == py
    assert any(e["kind"] == "onset" and e["hypothesis"].startswith("yaw_rate") for e in got)
