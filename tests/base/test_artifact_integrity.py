"""Issue 16, item 6: artifacts carry the hash of the design that made them, and their manifest is
checked against the payload; each silent case of the issue is now a DataError naming the key."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from fdikit.errors import DataError
from fdikit.monitor import load_artifact, save_artifact
from fdikit.monitor.config import build_monitor, design_hash, load_config, run_design

EXAMPLES = Path(__file__).parents[2] / "examples"

def _array_design():
    """A design whose artifact holds NPZ arrays (the ABS parity residual r1, its Butterworth
    sections), made here: a clean checkout has no designed examples."""
    from fdikit.systems.abs.residuals import ParityR1

    return ParityR1(1e-3)



@pytest.fixture(scope="module")
def two_mass(tmp_path_factory):
    """examples/two-mass designed into a temporary folder (a small recipe: a few seconds)."""
    d = tmp_path_factory.mktemp("two_mass")
    shutil.copy(EXAMPLES / "two-mass" / "monitor.toml", d / "monitor.toml")
    cfg = load_config(d / "monitor.toml")
    run_design(cfg)
    return d


def _edit(path: Path, fn) -> None:
    m = json.loads(path.read_text())
    fn(m)
    path.write_text(json.dumps(m))


def test_design_stamps_the_hash_and_a_changed_design_is_refused(two_mass, tmp_path):
    d = tmp_path / "tm"
    shutil.copytree(two_mass, d)
    cfg = load_config(d / "monitor.toml")
    stamp = json.loads((d / "designs" / "observer.json").read_text())["meta"]["design_hash"]
    assert stamp == design_hash(cfg) and len(stamp) == 64
    build_monitor(cfg)                                   # fresh: builds
    text = (d / "monitor.toml").read_text()
    (d / "monitor.toml").write_text(text.replace("Z = 5 ", "Z = 7 "))
    stale = load_config(d / "monitor.toml")
    assert design_hash(stale) != stamp
    with pytest.raises(DataError, match=r"artifact 'observer' .* designed from another \[design\] section.*"
                                         r"Rerun 'fdikit design .*monitor.toml'"):
        build_monitor(stale)
    # channel-map changes outside [design] do not make a design stale
    (d / "monitor.toml").write_text(text.replace('name = "two-mass sensor monitor"', 'name = "renamed"'))
    build_monitor(load_config(d / "monitor.toml"))
    # rerunning the design makes it fresh again
    (d / "monitor.toml").write_text(text.replace("Z = 5 ", "Z = 7 "))
    run_design(load_config(d / "monitor.toml"))
    assert build_monitor(load_config(d / "monitor.toml")).processors[0].Z == 7


def test_the_hash_covers_the_files_a_declarative_design_names(tmp_path):
    p = tmp_path / "m.toml"
    (tmp_path / "plant.npz").write_bytes(b"one")
    p.write_text('[channels.y]\n[design]\nsample_time = 0.01\n[design.plant]\nfile = "plant.npz"\n')
    h1 = design_hash(load_config(p))
    (tmp_path / "plant.npz").write_bytes(b"two")
    assert design_hash(load_config(p)) != h1


def test_artifacts_without_a_stamp_are_accepted(two_mass, tmp_path):
    """Artifacts written before stamping (the committed examples, older fdikit) load as they are."""
    d = tmp_path / "tm"
    shutil.copytree(two_mass, d)
    for name in ("observer", "hold"):
        _edit(d / "designs" / f"{name}.json", lambda m: m["meta"].pop("design_hash"))
    build_monitor(load_config(d / "monitor.toml"))


def test_edited_manifest_channels_are_refused(two_mass, tmp_path):
    d = tmp_path / "tm"
    shutil.copytree(two_mass, d / "x")
    obs = d / "x" / "designs" / "observer.json"
    _edit(obs, lambda m: m["channels"]["inputs"].reverse())
    with pytest.raises(DataError, match=r"key 'channels.inputs' lists .* but the design in the payload has"):
        load_artifact(obs)
    hold = d / "x" / "designs" / "hold.json"
    _edit(hold, lambda m: m["channels"]["outputs"].append("r:extra:alarm"))
    with pytest.raises(DataError, match=r"key 'channels.outputs'"):
        load_artifact(hold)


def test_array_shapes_keys_and_kind_are_checked_against_the_payload(tmp_path):
    r1 = _array_design()
    p = save_artifact(tmp_path / "r1", r1)
    m = json.loads(p.read_text())
    key = next(iter(m["arrays"]))
    assert set(m["shapes"]) == set(m["arrays"]) and "shape" in m["shapes"][key]
    # the NPZ replaced by arrays of another shape
    with np.load(p.with_suffix(".npz")) as z:
        arrays = {k: z[k] for k in z.files}
    stored = m["arrays"][key]
    wrong = dict(arrays, **{stored: np.zeros(arrays[stored].size + 1)})
    np.savez(p.with_suffix(".npz"), **wrong)
    with pytest.raises(DataError, match=rf"array '{key}' is float64 of shape \[\d+\] in the NPZ file, but "
                                        r"key 'shapes' records"):
        load_artifact(p)
    np.savez(p.with_suffix(".npz"), **arrays)
    load_artifact(p)
    # a listed array missing from the NPZ file
    np.savez(p.with_suffix(".npz"), **{k: v for k, v in arrays.items() if k != stored})
    with pytest.raises(DataError, match=rf"arrays \['{key}'\] listed under key 'arrays'"):
        load_artifact(p)
    np.savez(p.with_suffix(".npz"), **arrays)
    # the payload naming an array the manifest does not list
    _edit(p, lambda mm: mm["arrays"].pop(key))
    with pytest.raises(DataError, match=rf"refers to arrays \['{key}'\] that key 'arrays' does not list"):
        load_artifact(p)
    _edit(p, lambda mm: mm["arrays"].update({key: stored}))
    load_artifact(p)


def test_an_artifact_from_a_newer_fdikit_is_refused(tmp_path):
    import fdikit
    from fdikit.base.artifacts import read_manifest, version_tuple
    from fdikit.detect import Hold

    p = save_artifact(tmp_path / "hold", Hold(["r"], 0.5))
    mine = version_tuple(fdikit.__version__)
    newer = ".".join(str(x) for x in (*mine[:-1], mine[-1] + 1))
    _edit(p, lambda m: m.update(fdikit_version=newer))
    with pytest.raises(DataError, match=rf"written by fdikit {newer}, newer than the installed "
                                        rf"{fdikit.__version__}.*Upgrade fdikit"):
        load_artifact(p)
    for older in ("0.0.1", "0.1", fdikit.__version__):
        _edit(p, lambda m, v=older: m.update(fdikit_version=v))
        assert read_manifest(p)["fdikit_version"] == older
        load_artifact(p)


@pytest.mark.parametrize("text,want", [("0.1.0", (0, 1)), ("0.10.2", (0, 10, 2)), ("1.2.dev3", (1, 2)),
                                       ("2.0rc1+local", (2,)), ("3", (3,)), ("", ()), ("dev", ())])
def test_version_tuple_without_packaging(text, want):
    from fdikit.base.artifacts import version_tuple

    assert version_tuple(text) == want
