"""Property-based fuzz of the JSON inputs of ``solve`` (detections), ``evaluate`` (poses,
detections) and ``report`` (metrics.json, provenance.json) (issue 10, finding 8): JSON of any wrong
shape, and valid files mutated (a key deleted, a value replaced by null, a string, a list, an
object, NaN, a boolean, a huge or negative number), make ``main`` return 2 with a one-line
message naming the file, or (a mutation the tool can use) a normal exit status; never a
traceback. Deterministic: the conftest loads a derandomized hypothesis profile.
"""
import json
import math

import pytest
from hypothesis import HealthCheck, given
from hypothesis import settings as hsettings
from hypothesis import strategies as st
from pipeline_data import write_painted_dataset

from dockfactory.core.resources import shipped_config
from dockfactory.eval.acceptance import AcceptanceSpec
from dockfactory.cli import main
from dockfactory.eval.evaluate import evaluate, write_outputs
from dockfactory.eval.solve_frames import solve_dataset
from dockfactory.generator.datasets.reader import Dataset

FUZZ = hsettings(max_examples=25, deadline=None,
                 suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])

json_values = st.recursive(
    st.none() | st.booleans() | st.integers(-10**6, 10**6) | st.floats(allow_nan=True, allow_infinity=True)
    | st.text(max_size=8),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=8), inner, max_size=4),
    max_leaves=12)

REPLACEMENTS = (None, "x", "false", [], {}, math.nan, math.inf, True, -1, 0, 1e308, [1, 2])

# hypothesis over every JSON input: ~16 s, in `make test` (CI), not in the fast lane
pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def world(tmp_path_factory):
    """A painted smoke dataset, valid detections, poses and an evaluation folder of them."""
    base = tmp_path_factory.mktemp("fuzz")
    root = base / "dataset"
    write_painted_dataset(root, shipped_config("smoke"))
    ds = Dataset.open(root)
    frames = {}   # one frame with detections (the others: "no detections"), to keep the solver cheap
    for fid in ds.frames(("test", "repeat"))[:1]:
        frames[fid] = [{"class_id": m["class_id"], "center_px": m["outline_centroid_px"], "score": 0.9,
                        "bbox_px": m["bbox_px"], "refined": True}
                       for m in ds.labels[fid]["markers"] if m["visibility"] == 2][:6]
    dets = {"format": "dockfactory.detections/1", "dataset_version": ds.version_id, "frames": frames}
    poses = solve_dataset(ds, oracle_sigma_px=0.0)
    for rec in poses["frames"].values():   # not read by evaluate or report: fewer idle mutations
        for k in ("covariance", "cam_from_a", "rejected_ids", "n_markers"):
            rec.pop(k, None)
    (base / "poses.json").write_text(json.dumps(poses))
    metrics, rows = evaluate(ds, base / "poses.json", AcceptanceSpec(), oracle=False, oracle_sigma_px=0.0)
    write_outputs(base / "eval", metrics, rows)
    (base / "eval" / "provenance.json").write_text(json.dumps({"detections": None, "commands": ["x"]}))
    spec = base / "spec.toml"
    spec.write_text("[localization]\nx = 5.0\n")
    return {"base": base, "root": root, "ds": ds, "dets": dets, "poses": json.loads(json.dumps(poses)),
            "metrics": json.loads((base / "eval" / "metrics.json").read_text()), "spec": spec}


@pytest.fixture(scope="module", autouse=True)
def cheap_extras(world):
    """The report's matplotlib figures and evaluate's oracle re-solve (exact centroids + noise) are
    exercised by test_stages; here they cost time only: the figures are left out and the oracle's
    poses are computed once per noise level."""
    import dockfactory.eval.evaluate as evaluate_mod
    import dockfactory.eval.report.document as report
    saved = report.plots, evaluate_mod.solve_dataset
    cache = {}

    def cached_solve(ds, splits=("test", "repeat"), **kw):
        key = (tuple(splits), json.dumps(kw, sort_keys=True, default=str))
        if key not in cache:
            cache[key] = saved[1](ds, splits, **kw)
        return json.loads(json.dumps(cache[key]))

    report.plots = lambda rows, metrics, detections_pr=None: {}
    evaluate_mod.solve_dataset = cached_solve
    yield
    report.plots, evaluate_mod.solve_dataset = saved


def _paths(doc, prefix=()):
    """Every path (tuple of keys / indices) to a node of ``doc`` below the top level."""
    out = []
    if isinstance(doc, dict):
        items = doc.items()
    elif isinstance(doc, list):
        items = enumerate(doc)
    else:
        return out
    for k, v in items:
        out.append(prefix + (k,))
        out.extend(_paths(v, prefix + (k,)))
    return out


@st.composite
def mutated(draw, doc):
    """``doc`` with one to three nodes deleted or replaced."""
    doc = json.loads(json.dumps(doc))
    for _ in range(draw(st.integers(1, 3))):
        paths = _paths(doc)
        if not paths:
            break
        path = draw(st.sampled_from(paths))
        parent = doc
        for k in path[:-1]:
            parent = parent[k]
        if draw(st.booleans()):
            del parent[path[-1]]
        else:
            parent[path[-1]] = draw(st.sampled_from(REPLACEMENTS))
    return doc


def _write(path, value):
    path.write_text(json.dumps(value, allow_nan=True))


def _run(argv, capsys, named, allowed=(0, 1, 2, 3)):
    rc = main(argv)   # a traceback here fails the test: never allowed
    out = capsys.readouterr()
    assert rc in allowed, (rc, out.err)
    if rc == 2:
        assert out.err.startswith("dockfactory: error: ") and out.err.count("\n") == 1, out.err
        assert str(named) in out.err, out.err
    return rc


# ----------------------------------------------------------------------------- solve (detections)

@FUZZ
@given(value=json_values)
def test_solve_refuses_detections_of_any_other_shape(world, tmp_path_factory, capsys, value):
    d = world["base"]
    _write(d / "fz_dets.json", value)
    _run(["solve", str(world["root"]), "--detections", str(d / "fz_dets.json"), "--out", str(d / "fz_p.json")],
         capsys, d / "fz_dets.json", allowed=(2,))


@FUZZ
@given(data=st.data())
def test_solve_on_mutated_detections(world, capsys, data):
    d = world["base"]
    _write(d / "fm_dets.json", data.draw(mutated(world["dets"])))
    _run(["solve", str(world["root"]), "--detections", str(d / "fm_dets.json"), "--out", str(d / "fm_p.json")],
         capsys, d / "fm_dets.json", allowed=(0, 2))


# ----------------------------------------------------------------------------- evaluate (poses, detections)

@FUZZ
@given(value=json_values)
def test_evaluate_refuses_poses_of_any_other_shape(world, capsys, value):
    d = world["base"]
    _write(d / "fz_poses.json", value)
    _run(["evaluate", str(world["root"]), "--poses", str(d / "fz_poses.json"), "--acceptance", str(world["spec"]),
          "--out", str(d / "fz_eval")], capsys, d / "fz_poses.json", allowed=(2,))


@FUZZ
@given(data=st.data())
def test_evaluate_on_mutated_poses(world, capsys, data):
    d = world["base"]
    _write(d / "fm_poses.json", data.draw(mutated(world["poses"])))
    _run(["evaluate", str(world["root"]), "--poses", str(d / "fm_poses.json"), "--acceptance", str(world["spec"]),
          "--out", str(d / "fm_eval")], capsys, d / "fm_poses.json")


@FUZZ
@given(data=st.data())
def test_evaluate_on_mutated_detections(world, capsys, data):
    d = world["base"]
    _write(d / "fe_dets.json", data.draw(mutated(world["dets"])))
    _run(["evaluate", str(world["root"]), "--poses", str(d / "poses.json"), "--detections", str(d / "fe_dets.json"),
          "--acceptance", str(world["spec"]), "--out", str(d / "fe_eval")], capsys, d / "fe_dets.json")


def test_evaluate_records_the_weights_its_detections_name(world, capsys):
    """A report of a detector's run names the weights (the detections' ``weights_sha256``) in its
    provenance; a run without detections says it has none (it said so for both before)."""
    d, sha = world["base"], "ab" * 32
    _write(d / "fw_dets.json", {**world["dets"], "weights_sha256": sha})
    for name, extra in (("fw", ["--detections", str(d / "fw_dets.json")]), ("fo", [])):
        rc = main(["evaluate", str(world["root"]), "--poses", str(d / "poses.json"), *extra,
                   "--acceptance", str(world["spec"]), "--out", str(d / f"{name}_eval")])
        assert rc in (0, 1, 3), capsys.readouterr().err
        assert main(["report", str(d / f"{name}_eval"), "--out", str(d / f"{name}_r.html")]) in (0, 1)
    assert json.loads((d / "fw_eval" / "provenance.json").read_text())["model_sha256"] == sha
    assert sha in (d / "fw_r.html").read_text()
    assert json.loads((d / "fo_eval" / "provenance.json").read_text())["model_sha256"] is None
    assert "n/a (oracle or no detector)" in (d / "fo_r.html").read_text()
    # a weights digest that is not a string is refused when evaluate reads it, not later by report
    _write(d / "fx_dets.json", {**world["dets"], "weights_sha256": 5})
    _run(["evaluate", str(world["root"]), "--poses", str(d / "poses.json"), "--detections", str(d / "fx_dets.json"),
          "--out", str(d / "fx_eval")], capsys, d / "fx_dets.json", allowed=(2,))


# ----------------------------------------------------------------------------- report (metrics.json, provenance.json)

def _eval_copy(world, name):
    import shutil
    dst = world["base"] / name
    if not dst.exists():
        shutil.copytree(world["base"] / "eval", dst)
    return dst


@FUZZ
@given(value=json_values)
def test_report_refuses_metrics_of_any_other_shape(world, capsys, value):
    d = _eval_copy(world, "fz_eval_dir")
    _write(d / "metrics.json", value)
    _run(["report", str(d), "--out", str(world["base"] / "fz_r.html")], capsys, d / "metrics.json", allowed=(2,))


@FUZZ
@given(data=st.data())
def test_report_on_mutated_metrics(world, capsys, data):
    d = _eval_copy(world, "fm_eval_dir")
    doc = data.draw(mutated(world["metrics"]))
    _write(d / "metrics.json", doc)
    rc = _run(["report", str(d), "--out", str(world["base"] / "fm_r.html")], capsys, d / "metrics.json", allowed=(0, 2))
    if rc == 0:   # a report was written: its verdict is the one its rows give
        crit = doc["acceptance"]["criteria"]
        verdict = json.loads((world["base"] / "fm_r.json").read_text())["verdict"]
        from dockfactory.eval.acceptance import overall_verdict
        assert verdict == overall_verdict(crit)


@FUZZ
@given(value=json_values)
def test_report_refuses_provenance_of_another_shape(world, capsys, value):
    d = _eval_copy(world, "fp_eval_dir")
    _write(d / "provenance.json", value)
    _run(["report", str(d), "--out", str(world["base"] / "fp_r.html")], capsys, d / "provenance.json")


@pytest.mark.parametrize("key,value", [("full_well_e", [20000.0]), ("read_noise_e", [1.0, 2.0, 3.0])])
def test_a_simulated_camera_range_that_is_not_a_pair_is_a_one_line_error(key, value):
    """Found by the fuzz above: a three-chip sensor's range cut to one value reached the report's
    text and raised IndexError; every range the report prints as low-high is checked as a pair."""
    from dockfactory.core.errors import DockfactoryError
    from dockfactory.eval.report import check_schema
    from dockfactory.eval.simulated_cameras import THREE_CHIP_SCHEMA
    sensor = {"model": "three-chip noise model", "full_well_e": [20000.0, 30000.0], "read_noise_e": [2.0, 6.0],
              "adc_bits": 12}
    check_schema(sensor, THREE_CHIP_SCHEMA, "metrics.json", "sensor")
    with pytest.raises(DockfactoryError, match=f"metrics.json: sensor.{key}: expected 2 values, got {len(value)}"):
        check_schema({**sensor, key: value}, THREE_CHIP_SCHEMA, "metrics.json", "sensor")
