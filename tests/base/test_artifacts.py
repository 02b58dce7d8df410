"""Design artifacts: every kind round-trips through JSON + NPZ and behaves identically after
loading; a mismatched or corrupt artifact is refused with a clear message."""

import json

import numpy as np
import pytest

from fdikit import DataError, Signals
from fdikit.base.artifacts import KINDS
from fdikit.detect import GLRT, MHSSPT, Hold, TimeGated, UniformMeanGaussian
from fdikit.isolate import DMatrix, ao_star
from fdikit.model import LinearFaultModel
from fdikit.monitor import load_artifact, save_artifact
from fdikit.residuals import FaultDetectionFilter, ObserverResidual, design_observer_residual, design_uio


@pytest.fixture
def plant():
    return LinearFaultModel(np.diag([0.9, 0.8, 0.7]), np.eye(3)[:, :2], np.eye(3)[:2], dt=0.1,
                            inputs=["a", "b"], outputs=["y1", "y2"], faults=["actuator:a", "actuator:b"])


@pytest.fixture
def data():
    rng = np.random.default_rng(0)
    return Signals(np.arange(200) * 0.1, rng.normal(size=(2, 200, 4)), ["a", "b", "y1", "y2"])


def roundtrip(tmp_path, obj, name):
    p = save_artifact(tmp_path / name, obj, meta={"note": "test"}, units={"y1": "m"})
    manifest = json.loads(p.read_text())
    assert manifest["kind"] == type(obj).__name__ and manifest["format"].startswith("fdikit-artifact/")
    return load_artifact(p, kind=type(obj).__name__)


def test_linear_designs(tmp_path, plant, data):
    obs = design_observer_residual(plant)
    back = roundtrip(tmp_path, obs, "obs")
    np.testing.assert_array_equal(ObserverResidual(back).run(data).values,
                                  ObserverResidual(obs).run(data).values)
    uio = design_uio(plant, "actuator:a", ["actuator:b"])
    back = roundtrip(tmp_path, uio, "uio")
    np.testing.assert_array_equal(FaultDetectionFilter(back).run(data).values,
                                  FaultDetectionFilter(uio).run(data).values)


def test_processors(tmp_path, data):
    r = data.select(["y1", "y2"])
    for obj in (GLRT(["y1", "y2"], [0.1, 0.0], [1.0, 2.0], W=7), Hold(["y1", "y2"], [0.5, 0.7], Z=2),
                MHSSPT(["y1"], {"ok": UniformMeanGaussian([0], [0], [1]),
                                "f": UniformMeanGaussian([1], [2], [1])}, p=0.01, q=0.001,
                       groups={"any": ["f"]})):
        back = roundtrip(tmp_path, obj, type(obj).__name__)
        np.testing.assert_array_equal(back.run(r).values, obj.run(r).values)
    tg = TimeGated(["y1"], 0.5, T=3.0)
    back = roundtrip(tmp_path, tg, "tg")
    np.testing.assert_array_equal(back.run(r).values, tg.run(r).values)


def test_isolation_artifacts(tmp_path):
    dm = DMatrix(["F0", "F1", "F2", "F3"], ["t1", "t2", "t3"],
                 [[0, 0, 0], [1, 0, 1], [0, 1, 1], [1, 1, 0]])
    back = roundtrip(tmp_path, dm, "dm")
    np.testing.assert_array_equal(back.d, dm.d)
    tree = ao_star(dm, prior=[0.7, 0.1, 0.1, 0.1])
    back = roundtrip(tmp_path, tree, "tree")
    assert back.expected_cost == pytest.approx(tree.expected_cost, rel=1e-12)
    for row, fault in zip(dm.d, dm.faults):
        outcome = dict(zip(dm.tests, row))
        assert back.diagnose(outcome) == tree.diagnose(outcome)
        assert fault in back.diagnose(outcome)


def test_sliding_mode_reconstructor(tmp_path):
    from fdikit.residuals.smo import design_reconstructor
    from fdikit.systems import aircraft

    rec = design_reconstructor(aircraft.model(), dt=1e-4, hinf_check=False)
    back = roundtrip(tmp_path, rec, "smo")
    rng = np.random.default_rng(1)
    t = np.arange(300) * 1e-4
    names = [*rec.u_names, *rec.y_names]
    sig = Signals(t, 0.01 * rng.normal(size=(1, 300, len(names))), names)
    np.testing.assert_array_equal(back.run(sig).values, rec.run(sig).values)


def test_refusals(tmp_path, plant):
    obs = design_observer_residual(plant)
    p = save_artifact(tmp_path / "obs", obs)
    with pytest.raises(DataError, match=r"inputs are \['a', 'b', 'y1', 'y2'\], but"):
        load_artifact(p, expect_inputs=["a", "b", "y1", "speed"])
    with pytest.raises(DataError, match="artifact is a ObserverDesign, expected a GLRT"):
        load_artifact(p, kind="GLRT")
    m = json.loads(p.read_text())
    m["format"] = "fdikit-artifact/2"
    p.write_text(json.dumps(m))
    with pytest.raises(DataError, match="this fdikit reads 'fdikit-artifact/1'"):
        load_artifact(p)
    (tmp_path / "junk.json").write_text("{not json")
    with pytest.raises(DataError, match="not a readable artifact"):
        load_artifact(tmp_path / "junk.json")
    with pytest.raises(DataError, match="no such artifact"):
        load_artifact(tmp_path / "missing.json")
    with pytest.raises(DataError, match="object is not an artifact kind"):
        save_artifact(tmp_path / "x", object())
    # a manifest cannot make the loader import code from outside fdikit
    m = json.loads(p.read_text())
    m["format"] = "fdikit-artifact/1"
    for target in ("os:system", "fdikit_evil:Thing", "fdikit.residuals.fdf:NoSuchClass"):
        m["kind"], m["class"] = "Sneaky", target
        p.write_text(json.dumps(m))
        with pytest.raises(DataError, match="Sneaky"):
            load_artifact(p)
    # every registered kind resolves to a class with to_dict / from_dict
    from fdikit.base.artifacts import _resolve

    for k in KINDS:
        cls = _resolve(k)
        assert hasattr(cls, "to_dict") and hasattr(cls, "from_dict"), k


def test_svm_artifact(tmp_path):
    from fdikit.isolate.svm import SVMDecision, SVMIsolator

    rng = np.random.default_rng(4)
    X = np.vstack([rng.normal(0, 1, (40, 6)), rng.normal(2, 1, (40, 6))])
    labels = ["a"] * 40 + ["b"] * 40
    dec = SVMDecision(SVMIsolator().fit(X, labels).export())   # the default: scaled, cross-validated
    back = roundtrip(tmp_path, dec, "svm")
    assert (tmp_path / "svm.npz").exists()  # the support vectors travel as an array
    np.testing.assert_array_equal(back.decision_function(X), dec.decision_function(X))


def test_large_filter_matrices_go_to_npz_exactly(tmp_path):
    from fdikit.residuals import FilterDesign

    rng = np.random.default_rng(5)
    n, m, p, q = 20, 2, 3, 4
    d = FilterDesign(rng.normal(size=(n, n)) / 10, rng.normal(size=(n, m)), rng.normal(size=(n, p)),
                     rng.normal(size=(q, n)), rng.normal(size=(q, m)), rng.normal(size=(q, p)), 0.01,
                     ["u1", "u2"], ["y1", "y2", "y3"], [f"r{i}" for i in range(q)])
    path = save_artifact(tmp_path / "big", d)
    manifest = json.loads(path.read_text())
    # A (400 entries) is an array in the NPZ; the small C, Du, Dy stay readable in the JSON
    assert "p/A" in manifest["arrays"] and "p/Du" not in manifest["arrays"]
    back = load_artifact(path)
    for k in ("A", "Bu", "By", "C", "Du", "Dy"):
        assert np.array_equal(getattr(back, k), getattr(d, k)), k
    assert all(isinstance(v, list) for k, v in d.to_dict(inline=None).items() if k in ("A", "C"))


# ------------------------------------------------------------- artifacts of the old package layout
OLD_LAYOUT = [
    # (how to build a design of a moved class, the class path an old-layout manifest recorded)
    ("rav4_features", "fdikit.plants.passenger_car.monitor_rav4:Rav4FeatureNorms"),
    ("abs_observer", "fdikit.residuals.abs_residuals:ABSObserver"),
    ("abs_sensitivity", "fdikit.residuals.abs_residuals:ParameterSensitivity"),
]


def _old_layout_design(name):
    if name == "rav4_features":
        from fdikit.systems.car.monitor_rav4 import Rav4FeatureNorms

        return Rav4FeatureNorms({"n": ["a", "b"], "m": ["b"]}, 0.02, 0.1)
    from fdikit.systems.abs.residuals import ABSObserver, observer_sensitivity

    return ABSObserver(0.01) if name == "abs_observer" else observer_sensitivity(0.01, ["I_w"])


@pytest.mark.parametrize("name,old", OLD_LAYOUT, ids=[o[0] for o in OLD_LAYOUT])
def test_artifacts_of_the_old_layout_load(tmp_path, name, old):
    """A manifest written before the systems left the core names fdikit.plants.* /
    fdikit.residuals.abs_residuals classes; it loads through the layout aliases (MOVED)."""
    import json

    from fdikit.base.artifacts import MOVED, _resolve

    obj = _old_layout_design(name)
    p = save_artifact(tmp_path / name, obj)
    text = p.read_text()
    new = json.loads(text)["class"]
    if name == "abs_sensitivity":   # the wrapper is core; its members were ABS classes
        assert new == "fdikit.residuals.sensitivity:ParameterSensitivity"
        assert "fdikit.systems.abs.residuals:ABSObserver" in text
        text = text.replace("fdikit.systems.abs.residuals:", "fdikit.residuals.abs_residuals:")
    else:
        assert new != old and _resolve(old.rpartition(":")[2], old) is type(obj), (old, new)
        text = text.replace(new, old)
    assert "fdikit.plants" in text or "abs_residuals" in text
    p.write_text(text)
    back = load_artifact(p)
    assert type(back) is type(obj)
    a, b = back.to_dict(), obj.to_dict()
    assert json.dumps(a, sort_keys=True, default=str) == json.dumps(b, sort_keys=True, default=str)
    assert all(v.startswith("fdikit.") for v in MOVED.values())


def test_old_layout_recipes_resolve():
    from fdikit.base.artifacts import moved

    for old in ("fdikit.evaluate.abs_config:design", "fdikit.plants.passenger_car.recipe:design",
                "fdikit.plants.passenger_car.monitor_rav4:design", "fdikit.plants.aircraft:design",
                "fdikit.plants.two_mass:design"):
        mod, _, fn = moved(old).partition(":")
        assert callable(getattr(__import__(mod, fromlist=[fn]), fn)), old


def test_artifacts_record_the_package_path_of_a_split_module():
    """A class moved into a one-concept submodule by the wave-3 split is recorded under the path it
    had before (its package re-exports it), so manifests stay the same across the split and load
    in older fdikits; a class the package does not re-export keeps its own module."""
    from fdikit.base.artifacts import _class_path
    from fdikit.detect.sensor import GainDetector, StuckDetector
    from fdikit.residuals.fdf import FilterDesign
    from fdikit.systems.car.monitor_rav4 import Rav4LateralFilter

    assert GainDetector.__module__ == "fdikit.detect.sensor.gain"
    assert _class_path(object.__new__(GainDetector)) == "fdikit.detect.sensor:GainDetector"
    assert _class_path(object.__new__(StuckDetector)) == "fdikit.detect.sensor:StuckDetector"
    assert _class_path(object.__new__(Rav4LateralFilter)) == \
        "fdikit.systems.car.monitor_rav4:Rav4LateralFilter"
    assert _class_path(object.__new__(FilterDesign)) == "fdikit.residuals.fdf:FilterDesign"   # KINDS
