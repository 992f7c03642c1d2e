"""measure --acceptance: IN / OUT / UNDECIDED per image with the guard band U = 2 u, the summary
line, the exit status of the worst image; the layout's sigma_mm in the budget. On two painted
1280 x 960 frames (tests/pipeline_data.py, no Blender): measured once, then re-judged by reruns
that resume every image (the spec is not part of what is measured)."""
import csv
import json

import numpy as np
import pytest

from dockfactory.cli import main
from test_measure import CONFIG   # the painted 1280 x 960 dataset of tests/app/test_measure.py

IMAGES = ("000000.png", "000001.png")


@pytest.fixture(scope="module")
def painted(tmp_path_factory):
    from pipeline_data import painted_from_text
    return painted_from_text(tmp_path_factory, "conformity", CONFIG)


def _argv(ds, out, layout=None) -> list:
    return ["measure", *(str(ds / "images" / n) for n in IMAGES), "--layout", str(layout or ds / "layout.json"),
            "--out", str(out), "--workers", "1", "--threads", "1", "--overlay-size", "0", "--quiet"]


@pytest.fixture(scope="module")
def measured(painted, tmp_path_factory):
    ds = painted
    out = tmp_path_factory.mktemp("m") / "out"
    argv = _argv(ds, out)
    assert main(argv) == 0
    return ds, out, argv


def _spec(tmp_path, name: str, x: float, rule: str = "guarded") -> str:
    path = tmp_path / name
    path.write_text(f'decision_rule = "{rule}"\n[localization]\nx = {x!r}\ny = 1000.0\nalpha = 100.0\n')
    return str(path)


def _doc(out):
    return json.loads((out / "measurements.json").read_text())


@pytest.mark.slow   # the detector on two 1280 x 960 images (once for the module)
def test_exit_status_follows_the_worst_image_on_both_sides_of_the_guard_band(measured, tmp_path, capsys):
    ds, out, argv = measured
    images = _doc(out)["images"]
    xs = [abs(r["pose"]["x_mm"]) for r in images]
    near = max(xs)                      # the farthest image sits exactly at the limit: UNDECIDED
    u_far = images[xs.index(near)]["uncertainty"]["x_mm"]["combined"]
    cases = [(1000.0, "guarded", 0, "IN"),
             (near + 2 * u_far * 1.01, "guarded", 0, "IN"),              # just beyond |x| + U
             (near + 2 * u_far * 0.99, "guarded", 3, "UNDECIDED"),       # just inside |x| + U
             (near, "guarded", 3, "UNDECIDED"),
             (near - 2 * u_far * 0.99, "guarded", 3, "UNDECIDED"),       # just above |x| - U
             (near - 2 * u_far * 1.01, "guarded", 1, "OUT"),             # |x| - U beyond it
             (near, "simple", 0, "IN"), (near * (1 - 1e-9), "simple", 1, "OUT")]
    for k, (x, rule, status, worst) in enumerate(cases):
        capsys.readouterr()
        assert main([*argv[:-1], "--acceptance", _spec(tmp_path, f"s{k}.toml", x, rule)]) == status, (x, rule)
        lines = capsys.readouterr().out.strip().splitlines()
        assert lines[-1].startswith(f"conformity {worst}:"), lines
        assert "+- U, k = 2" in lines[-2] or rule == "simple"
        doc = _doc(out)
        assert doc["conformity"]["worst"] == worst and doc["images_measured"] == 0   # resumed, not re-measured
        far = doc["images"][xs.index(near)]["conformity"]
        assert far["components"]["x_mm"]["decision"] == worst and far["k"] == (2.0 if rule == "guarded" else 0.0)


@pytest.mark.slow   # the detector on two 1280 x 960 images (once for the module)
def test_csv_carries_u_U_and_decisions(measured, tmp_path):
    ds, out, argv = measured
    assert main([*argv, "--acceptance", _spec(tmp_path, "s.toml", 1000.0)]) == 0
    rows = list(csv.DictReader((out / "measurements.csv").open()))
    assert [r["conformity"] for r in rows] == ["IN", "IN"]
    for r in rows:
        assert r["conformity_x_mm"] == "IN" and r["conformity_z_mm"] == ""     # z is not gated
        assert float(r["U_x_mm"]) == pytest.approx(2 * float(r["u_x_mm"]), abs=2e-4)
        assert float(r["u_x_mm"]) >= float(r["std_x_mm"]) - 1e-4   # + the shipped card's detector bias
        assert len(r["U_x_mm"].split(".")[1]) == 4                                  # mm to 0.1 um


@pytest.mark.slow   # the detector on two 1280 x 960 images (once for the module)
def test_layout_sigma_mm_enters_the_budget_and_the_guard_band(measured, tmp_path, capsys):
    ds, out, argv = measured
    layout = json.loads((ds / "layout.json").read_text())
    layout["sigma_mm"] = 0.05
    path = tmp_path / "layout_cmm.json"
    path.write_text(json.dumps(layout))
    out2 = tmp_path / "out2"
    assert main(_argv(ds, out2, path)) == 0
    before, after = _doc(out)["images"], _doc(out2)["images"]
    assert _doc(out2)["uncertainty"]["layout_sigma_mm"] == {"min": 0.05, "max": 0.05}
    for a, b in zip(before, after):
        bx = b["uncertainty"]["x_mm"]
        assert bx["layout"] > 0 and bx["combined"] > a["uncertainty"]["x_mm"]["combined"]
        assert bx["detector_bias"] is not None   # the shipped weights' noise card measured it
        assert bx["model_error"] > 0            # the lens is not known: marginalised by default
        assert bx["section_shift"] is not None   # ... and the section offset of its centres
        assert bx["combined"] ** 2 == pytest.approx(bx["centre_noise"] ** 2 + bx["intrinsics"] ** 2 + bx["layout"] ** 2
                                                    + bx["detector_bias"] ** 2 + bx["model_error"] ** 2
                                                    + bx["section_shift"] ** 2)


@pytest.mark.slow   # the detector on two 1280 x 960 images, twice
def test_lens_prior_sets_the_camera_model_term(measured, tmp_path, capsys):
    """--lens-prior known: nothing marginalised (no camera-model term, a smaller u); narrower
    stated ranges: a smaller term than the default's; the rest of the budget unchanged."""
    ds, out, argv = measured
    base = _doc(out)["images"]
    runs = {}
    for name, value in (("known", "known"), ("narrow", "pp=0.01,k1=0.05,k2=0.02,p=5e-4")):
        assert main(_argv(ds, tmp_path / name) + ["--lens-prior", value]) == 0
        runs[name] = _doc(tmp_path / name)["images"]
    for a, k, n in zip(base, runs["known"], runs["narrow"]):
        for c in ("x_mm", "y_mm", "alpha_deg"):
            ua, uk, un = a["uncertainty"][c], k["uncertainty"][c], n["uncertainty"][c]
            assert uk["model_error"] is None and ua["model_error"] > 0
            assert 0 < un["model_error"] < ua["model_error"]
            assert uk["combined"] < un["combined"] < ua["combined"]
            assert uk["centre_noise"] == pytest.approx(ua["centre_noise"], rel=1e-6)
        assert k["pose"] == a["pose"]          # the prior changes the uncertainty, never the pose
    with pytest.raises(SystemExit) as stop:    # argparse: one error line, exit 2, nothing measured
        main(_argv(ds, tmp_path / "bad") + ["--lens-prior", "k9=1"])
    assert stop.value.code == 2 and not (tmp_path / "bad").exists()
    err = capsys.readouterr().err.strip().splitlines()
    assert "--lens-prior" in err[-1] and "k9=1" in err[-1]


def test_a_spec_without_pose_tolerances_is_refused_before_measuring(painted, tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text("[localization]\ngated = false\n")
    fresh = tmp_path / "fresh"
    for spec, words in ((bad, "[localization] gates no component"), (tmp_path / "nope.toml", "nope.toml")):
        assert main([*_argv(painted, fresh), "--acceptance", str(spec)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and words in err[0], err
    assert not fresh.exists() or not (fresh / "measurements.json").exists()


@pytest.mark.slow   # the detector on two 1280 x 960 images (once for the module)
def test_overlays_are_redrawn_with_each_decision(measured, tmp_path):
    """A resumed run with a spec redraws the overlays after the decision: the header band of each
    carries it (the white text reaches further than the 1-sigma line's decision-free text)."""
    import cv2
    ds, out, argv = measured
    argv = [a for a in argv if a != "--quiet"]
    k = argv.index("--overlay-size")
    with_overlays = [*argv[:k + 1], "0.5", *argv[k + 2:]]
    assert main([*with_overlays, "--quiet"]) == 0
    plain = {p.name: cv2.imread(str(p)) for p in (out / "overlays").glob("*.png")}
    assert len(plain) == 2
    assert main([*with_overlays, "--quiet", "--acceptance", _spec(tmp_path, "s.toml", 1000.0)]) == 0
    for name, before in plain.items():
        after = cv2.imread(str(out / "overlays" / name))
        assert after.shape == before.shape and not np.array_equal(after[:60], before[:60]), name
        assert np.array_equal(after[80:], before[80:])     # only the text changed
