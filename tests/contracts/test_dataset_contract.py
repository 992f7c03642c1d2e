"""The dataset contract, consumer by consumer: a damaged, incomplete or foreign dataset is refused by
every command that reads one (``Dataset.open``, generator/datasets/reader.py), with exit status 2 and
one line ``dockfactory: error: DATASET: ...`` naming the problem, and nothing is written.

A damage x consumer matrix on the painted smoke dataset (tests/pipeline_data.py, no rendering):

- damages: a test frame deleted, a label deleted, two images swapped, a digit of the ground truth
  changed, a frame dropped from a self-consistent manifest, a sha256 of the manifest changed, a
  stray label+image pair, manifest.json deleted, dataset.json's config edited (threshold, seed),
  an image replaced by a symlink to an identical file outside, one byte of an image changed (same
  size: only the sha256 tells), an image truncated, a meta record deleted, and foreign folders
  (another format, an empty folder, a folder of images only);
- consumers: ``detect``, ``train`` (slow), ``solve``, ``evaluate``, ``dataset export`` (coco,
  yolo, bop) and ``run`` on a work folder whose stages are all current (the issue's finding: a
  deleted test frame was skipped past and ACCEPTED). Positive controls show each consumer accepts
  the intact dataset, so the matrix can fail; ``dataset verify`` names every damage (exit 1).

``run`` differs by design where the damage touches the manifest itself (a frame dropped from it, a
sha256 edited, the file deleted): its render stage is then not current, so it resumes the dataset
(renders the frames that are missing, re-derives the manifest from the meta records) and opens
it with every byte checked; tests below pin that the resumed dataset is the intact one, and that
re-deriving the manifest cannot launder an edited label.
"""
import hashlib
import json
import os
import re
import shutil
from pathlib import Path

import pytest

from dockfactory.core.resources import shipped_config
from dockfactory.eval.report import document as report
from dockfactory.cli import main
from dockfactory.generator import render_job
from dockfactory.generator.datasets.folder import frame_files

SMOKE = shipped_config("smoke")


# ----------------------------------------------------------------------------- damages
# Each takes the dataset root, damages it, and returns a text the refusal must name (a file, a
# frame id). Frames are picked from the manifest's ``frames`` list.

def _manifest(root: Path) -> dict:
    return json.loads((root / "manifest.json").read_text())


def _test_frames(root: Path) -> list[str]:
    return [f["frame_id"] for f in _manifest(root)["frames"] if f["split"] == "test"]


def _frame_files(root: Path, fid: str) -> list[str]:
    """Every file of frame ``fid`` (its own files and its meta record), relative paths."""
    keep_exr = (root / "exr").is_dir()
    return sorted(frame_files(fid, keep_exr).values()) + [f"meta/{fid}.json"]


def _bump_digit(text: str, start: int) -> str:
    """``text`` with the first digit at or after ``start`` changed (same length)."""
    m = re.compile(r"\d").search(text, start)
    d = m.group()
    return text[:m.start()] + str((int(d) + 1) % 10) + text[m.end():]


def frame_deleted(root):
    fid = _test_frames(root)[0]
    (root / "labels" / f"{fid}.json").unlink()
    (root / "images" / f"{fid}.png").unlink()
    return f"images/{fid}.png"


def label_deleted(root):
    fid = _test_frames(root)[0]
    (root / "labels" / f"{fid}.json").unlink()
    return f"labels/{fid}.json"


def images_swapped(root):
    a, b = (root / "images" / f"{fid}.png" for fid in _test_frames(root)[:2])
    da, db = a.read_bytes(), b.read_bytes()
    assert da != db
    a.write_bytes(db)
    b.write_bytes(da)
    return f"images/{a.name}"


def ground_truth_edited(root):
    """One digit of pose_b_in_d's x in a test frame's label; the file otherwise identical."""
    fid = _test_frames(root)[0]
    path = root / "labels" / f"{fid}.json"
    text = path.read_text()
    x_at = text.index('"x_mm"', text.index('"pose_b_in_d"'))
    edited = _bump_digit(text, x_at)
    assert len(edited) == len(text)
    before, after = json.loads(text), json.loads(edited)
    assert before["pose_b_in_d"]["x_mm"] != after["pose_b_in_d"]["x_mm"]
    after["pose_b_in_d"]["x_mm"] = before["pose_b_in_d"]["x_mm"]
    assert after == before   # nothing else changed
    path.write_text(edited)
    return f"labels/{fid}.json"


def manifest_frame_dropped(root):
    """A test frame removed from the manifest's frames, counts and files, and its files deleted:
    a self-consistent manifest of a dataset one frame short of its plan."""
    m = _manifest(root)
    fid = _test_frames(root)[0]
    gone = next(f for f in m["frames"] if f["frame_id"] == fid)
    m["frames"].remove(gone)
    own = set(_frame_files(root, fid))
    assert own <= {rec["path"] for rec in m["files"]}
    m["files"] = [rec for rec in m["files"] if rec["path"] not in own]
    counts = m["counts"]
    counts["frames"] -= 1
    counts["by_split"][gone["split"]] -= 1
    counts["by_condition"][gone["condition"]] -= 1
    counts["by_split_condition"][f"{gone['split']}/{gone['condition']}"] -= 1
    for rel in own:
        (root / rel).unlink()
    (root / "manifest.json").write_text(json.dumps(m, indent=1))
    return fid


def manifest_sha_edited(root):
    m = _manifest(root)
    rel = f"labels/{_test_frames(root)[0]}.json"
    rec = next(r for r in m["files"] if r["path"] == rel)
    rec["sha256"] = _bump_digit(rec["sha256"], 0)
    (root / "manifest.json").write_text(json.dumps(m, indent=1))
    return rel


def stray_pair(root):
    """An existing frame's label and image copied as frame 999999 (its frame ids edited)."""
    fid = _test_frames(root)[0]
    label = json.loads((root / "labels" / f"{fid}.json").read_text())
    label["frame_id"] = label["spec"]["frame_id"] = "999999"
    (root / "labels" / "999999.json").write_text(json.dumps(label, indent=1))
    shutil.copyfile(root / "images" / f"{fid}.png", root / "images" / "999999.png")
    return "999999"


def manifest_deleted(root):
    (root / "manifest.json").unlink()
    return "manifest.json"


def _edit_identity(root, old: str, new: str):
    path = root / "dataset.json"
    text = path.read_text()
    assert text.count(old) == 1, old
    path.write_text(text.replace(old, new))
    return "dataset.json"


def config_threshold_edited(root):
    return _edit_identity(root, '"visible_threshold": 0.5', '"visible_threshold": 0.6')


def config_seed_edited(root):
    """The config's seed (not the identity's top-level copy of it)."""
    path = root / "dataset.json"
    ident = json.loads(path.read_text())
    ident["config"]["dataset"]["seed"] += 1
    path.write_text(json.dumps(ident, indent=1))
    return "dataset.json"


def image_symlinked(root):
    """An image replaced by a symlink to a byte-identical copy outside the dataset (size and
    sha256 match the manifest: only the link gives it away)."""
    rel = f"images/{_test_frames(root)[0]}.png"
    outside = root.parent / "outside.png"
    shutil.copyfile(root / rel, outside)
    (root / rel).unlink()
    (root / rel).symlink_to(outside)
    return rel


def image_byte_flipped(root):
    """One byte in the middle of an image changed: same size, only its sha256 differs (caught
    only when images are hashed on open, ``full=True``, which every command does)."""
    rel = f"images/{_test_frames(root)[0]}.png"
    path = root / rel
    data = bytearray(path.read_bytes())
    data[len(data) // 2] ^= 0x01
    path.write_bytes(bytes(data))
    return rel


def image_truncated(root):
    rel = f"images/{_test_frames(root)[0]}.png"
    path = root / rel
    path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])
    return rel


def meta_deleted(root):
    rel = f"meta/{_test_frames(root)[0]}.json"
    (root / rel).unlink()
    return rel


def foreign_format(root):
    """A dataset of another tool (or format version): dataset.json's format is "other/1"."""
    _edit_identity(root, '"format": "dockfactory.dataset/1"', '"format": "other/1"')
    return "format 'other/1'"


def _empty(root):
    for p in root.iterdir():
        if p.is_dir() and not p.is_symlink():
            shutil.rmtree(p)
        else:
            p.unlink()


def foreign_empty(root):
    _empty(root)
    return "dataset.json"


def foreign_images_only(root):
    images = root.parent / "images-aside"
    shutil.move(root / "images", images)
    _empty(root)
    shutil.move(images, root / "images")
    return "dataset.json"


# name -> (damage, a word naming the problem in the refusal)
DAMAGES = {
    "frame_deleted": (frame_deleted, "missing"),
    "label_deleted": (label_deleted, "missing"),
    "images_swapped": (images_swapped, "corrupt"),
    "ground_truth_edited": (ground_truth_edited, "corrupt"),
    "manifest_frame_dropped": (manifest_frame_dropped, "inconsistent"),
    "manifest_sha_edited": (manifest_sha_edited, "corrupt"),
    "stray_pair": (stray_pair, "unexpected"),
    "manifest_deleted": (manifest_deleted, "not complete"),
    "config_threshold_edited": (config_threshold_edited, "inconsistent"),
    "config_seed_edited": (config_seed_edited, "inconsistent"),
    "image_symlinked": (image_symlinked, "unsafe"),
    "image_byte_flipped": (image_byte_flipped, "corrupt"),
    "image_truncated": (image_truncated, "corrupt"),
    "meta_deleted": (meta_deleted, "missing"),
    "foreign_format": (foreign_format, "inconsistent"),
    "foreign_empty": (foreign_empty, "not a dockfactory dataset"),
    "foreign_images_only": (foreign_images_only, "not a dockfactory dataset"),
}
NOT_A_DATASET = ("foreign_empty", "foreign_images_only")   # no dataset.json at all
# touch the manifest itself: ``run``'s render stage is not current, it resumes (tests below)
RUN_RESUMES = ("manifest_frame_dropped", "manifest_sha_edited", "manifest_deleted")


# ----------------------------------------------------------------------------- helpers

def _tree(folder: Path, skip=("logs",)) -> dict[str, str]:
    """relative path -> sha256 (or link target) of every file under ``folder``, top-level
    folders in ``skip`` left out (the lock file lives in logs/)."""
    out = {}
    if not folder.exists():
        return out
    for p in sorted(folder.rglob("*")):
        rel = p.relative_to(folder)
        if rel.parts[0] in skip:
            continue
        if p.is_symlink():
            out[rel.as_posix()] = "-> " + os.readlink(p)
        elif p.is_file():
            out[rel.as_posix()] = hashlib.sha256(p.read_bytes()).hexdigest()
    return out


def _assert_refused(rc, captured, root: Path, words, extra_lines=()):
    """Exit 2, stderr one line ``dockfactory: error: ...`` naming ``root`` and every one of
    ``words`` (lines starting with one of ``extra_lines`` are allowed before it), no traceback."""
    err_lines = captured.err.splitlines()
    errors = [ln for ln in err_lines if ln.startswith("dockfactory: error:")]
    others = [ln for ln in err_lines if not ln.startswith("dockfactory: error:")]
    assert rc == 2, captured
    assert len(errors) == 1 and err_lines[-1] == errors[0], captured.err
    assert all(ln.startswith(tuple(extra_lines)) for ln in others) if extra_lines else not others, captured.err
    line = errors[0]
    assert str(root) in line, line
    for w in words:
        assert w in line, (w, line)
    assert "Traceback" not in captured.err + captured.out


def _no_render(*args, **kwargs):
    raise AssertionError("the run rendered although every frame of its dataset is done")


@pytest.fixture
def quiet_run(monkeypatch):
    """``run`` without Blender (a render attempt fails the test) and without the report's plots."""
    monkeypatch.setattr(render_job, "_render", _no_render)
    monkeypatch.setattr(report, "plots", lambda rows, metrics, detections_pr=None: {})
    return monkeypatch


def _run(work: Path) -> int:
    return main(["run", str(SMOKE), "--out", str(work), "--oracle-noise", "0"])


# ----------------------------------------------------------------------------- fixtures

@pytest.fixture(scope="module")
def good_poses(painted_source, tmp_path_factory):
    """Oracle poses of the intact dataset (``solve --oracle-noise 0``): bound to its version id,
    which damage to its images and labels does not change."""
    out = tmp_path_factory.mktemp("poses") / "poses.json"
    assert main(["solve", str(painted_source), "--oracle-noise", "0", "--out", str(out)]) == 0
    return out


@pytest.fixture(scope="module")
def good_run(painted_source, tmp_path_factory):
    """A work folder after one good oracle run (exit 1: REJECTED, the shipped spec gates mAP and an
    oracle run has none): stages.json says every stage is current. Tests copy it."""
    work = tmp_path_factory.mktemp("goodrun") / "work"
    shutil.copytree(painted_source, work / "dataset")
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(render_job, "_render", _no_render)
        mp.setattr(report, "plots", lambda rows, metrics, detections_pr=None: {})
        assert _run(work) == 1
    assert set(json.loads((work / "stages.json").read_text())) == {"render", "solve", "evaluate"}
    return work


@pytest.fixture(scope="module")
def damaged(painted_source, tmp_path_factory):
    """damage name -> (root, named): one damaged copy of the painted dataset per damage kind (per
    test process), shared by the consumers of that row. Every consumer must leave it as it was
    (each test checks that), so sharing it is sound; it keeps the 119 cells of the matrix cheap."""
    made = {}

    def get(damage: str):
        if damage not in made:
            root = tmp_path_factory.mktemp(damage) / "ds"
            shutil.copytree(painted_source, root)
            made[damage] = root, DAMAGES[damage][0](root)
        return made[damage]
    return get


@pytest.fixture
def work(good_run, tmp_path):
    """A private copy of the good run's work folder."""
    dst = tmp_path / "work"
    shutil.copytree(good_run, dst, symlinks=True)
    return dst


# ----------------------------------------------------------------------------- consumers
# Each takes (dataset root, output folder, poses file) and returns (argv, the path it must not
# create). The output folder exists and is empty; it must stay so.

def _detect(root, out, poses):
    p = out / "dets.json"
    return ["detect", str(root), "--out", str(p), "--threads", "1", "--quiet"], p


def _train(root, out, poses):
    p = out / "run"
    return ["train", str(root), "--out", str(p), "--epochs", "1", "--batch", "4", "--input-scale", "0.5",
            "--crops-per-frame", "1", "--threads", "1", "--quiet"], p


def _solve(root, out, poses):
    p = out / "poses.json"
    return ["solve", str(root), "--oracle-noise", "0", "--out", str(p)], p


def _evaluate(root, out, poses):
    p = out / "eval"
    return ["evaluate", str(root), "--poses", str(poses), "--out", str(p)], p


def _export(fmt):
    def make(root, out, poses):
        return ["dataset", "export", str(root), "--format", fmt], root / "exports" / fmt
    return make


CONSUMERS = {
    "detect": _detect,
    "train": _train,
    "solve": _solve,
    "evaluate": _evaluate,
    "export_coco": _export("coco"),
    "export_yolo": _export("yolo"),
    "export_bop": _export("bop"),
}
SLOW_CONSUMERS = ("train",)


def _consumer_params():
    return [pytest.param(c, id=c, marks=[pytest.mark.slow] if c in SLOW_CONSUMERS else [])
            for c in CONSUMERS]


# ----------------------------------------------------------------------------- positive controls

@pytest.mark.parametrize("consumer", _consumer_params())
def test_the_intact_dataset_is_accepted(painted, tmp_path, good_poses, capfd, consumer):
    """The matrix's control: each consumer, as invoked below, accepts the intact dataset."""
    out = tmp_path / "out"
    out.mkdir()
    argv, target = CONSUMERS[consumer](painted, out, good_poses)
    rc = main(argv)
    captured = capfd.readouterr()
    # evaluate: 1 = REJECTED (the shipped spec gates mAP; oracle poses have none), a verdict
    assert rc == (1 if consumer == "evaluate" else 0), captured
    assert "dockfactory: error" not in captured.err and "Traceback" not in captured.err
    assert target.exists()
    if consumer == "evaluate":
        assert "verdict: REJECTED" in captured.out and (target / "metrics.json").is_file()


def test_run_on_an_intact_work_folder_skips_every_stage(work, quiet_run, capfd):
    """The run column's control: the intact work folder is accepted, every stage current."""
    assert _run(work) == 1
    captured = capfd.readouterr()
    assert "verdict: REJECTED" in captured.out and "dockfactory: error" not in captured.err
    for line in ("render: dataset", "solve: poses current, skipped", "evaluate: metrics current, skipped"):
        assert line in captured.err, (line, captured.err)
    assert "complete, skipped" in captured.err


# ----------------------------------------------------------------------------- the matrix

@pytest.mark.parametrize("consumer", _consumer_params())
@pytest.mark.parametrize("damage", list(DAMAGES))
def test_a_damaged_dataset_is_refused(damaged, tmp_path, good_poses, capfd, damage, consumer):
    root, named = damaged(damage)
    word = DAMAGES[damage][1]
    out = tmp_path / "out"
    out.mkdir()
    before = _tree(root)
    argv, target = CONSUMERS[consumer](root, out, good_poses)
    rc = main(argv)
    _assert_refused(rc, capfd.readouterr(), root, (word, named))
    assert list(out.iterdir()) == [] and not target.exists()
    exports = root / "exports"
    assert not exports.exists() or list(exports.iterdir()) == []   # no export, no partial one
    assert _tree(root) == before                                     # the dataset is left as it was


# an empty WORKDIR/dataset is no damage to ``run``: it is where a first run renders a new dataset
RUN_DAMAGES = [d for d in DAMAGES if d not in RUN_RESUMES and d != "foreign_empty"]


@pytest.mark.parametrize("damage", RUN_DAMAGES)
def test_run_refuses_a_damaged_dataset_although_every_stage_is_current(work, quiet_run, capfd, damage):
    """The issue's finding: after a good run, damage to WORKDIR/dataset left stages.json saying
    every stage was current; the re-run skipped them all and printed a verdict. It must stop,
    exit 2, naming the dataset and the problem, and write nothing."""
    fn, word = DAMAGES[damage]
    data = work / "dataset"
    named = fn(data)
    if damage == "foreign_images_only":   # no dataset.json: the render stage refuses to write into it
        word, named = "not empty", "no dataset.json"
    before = _tree(work, skip=("logs", "dataset")), _tree(data)
    rc = _run(work)
    captured = capfd.readouterr()
    _assert_refused(rc, captured, data, (word, named), extra_lines=("[run] ",))
    if damage != "foreign_images_only":
        assert "complete, skipped" in captured.err   # the render stage was current: the open refused it
    assert "verdict" not in captured.out
    assert (_tree(work, skip=("logs", "dataset")), _tree(data)) == before


@pytest.mark.parametrize("damage", list(DAMAGES))
def test_verify_names_every_damage(damaged, capfd, damage):
    """``dataset verify``: exit 1 and the problem named for a damaged dataset; a folder that is not
    a dataset at all (no dataset.json) is bad input: exit 2, one line."""
    root, named = damaged(damage)
    word = DAMAGES[damage][1]
    rc = main(["dataset", "verify", str(root)])
    captured = capfd.readouterr()
    if damage in NOT_A_DATASET:
        _assert_refused(rc, captured, root, (word, named))
        return
    assert rc == 1, captured
    assert captured.out.startswith(f"{root}: FAILED")
    assert word in captured.out and named in captured.out, captured.out
    assert "Traceback" not in captured.err


# ----------------------------------------------------------------------------- run: resume, poses

def _snapshot_manifest(root):
    return (root / "manifest.json").read_bytes()


@pytest.mark.parametrize("damage", ["manifest_sha_edited", "manifest_deleted"])
def test_run_re_derives_an_edited_or_deleted_manifest_from_the_meta_records(work, painted_source, quiet_run,
                                                                            capfd, damage):
    """The manifest changed: the render stage is not current, finds every frame done (nothing
    rendered), writes the manifest again from the meta records, and the run goes on only because
    every byte then matches: the manifest is the intact one again."""
    DAMAGES[damage][0](work / "dataset")
    assert _run(work) == 1
    captured = capfd.readouterr()
    assert "dockfactory: error" not in captured.err and "verdict: REJECTED" in captured.out
    assert "complete, skipped" not in captured.err   # the render stage ran
    assert _snapshot_manifest(work / "dataset") == _snapshot_manifest(painted_source)
    assert main(["dataset", "verify", str(work / "dataset")]) == 0


def test_run_re_renders_a_frame_dropped_from_the_manifest(work, painted_source, quiet_run, capfd):
    """A frame dropped from a self-consistent manifest (its files deleted): the render stage renders
    exactly that frame again (here: restored from the painted source, which is what rendering it
    gives) and the run goes on with the complete dataset."""
    data = work / "dataset"
    fid = manifest_frame_dropped(data)
    rendered = []

    def fake_render(cfg, root, todo, scenes, opts, summary):
        for spec in todo:
            rendered.append(spec.frame_id)
            for rel in _frame_files(root, spec.frame_id):
                shutil.copyfile(painted_source / rel, root / rel)
            summary.rendered += 1

    quiet_run.setattr(render_job, "_render", fake_render)
    assert _run(work) == 1
    captured = capfd.readouterr()
    assert rendered == [fid]
    assert "dockfactory: error" not in captured.err and "verdict: REJECTED" in captured.out
    assert _snapshot_manifest(data) == _snapshot_manifest(painted_source)


def test_run_re_deriving_the_manifest_does_not_launder_an_edited_label(work, quiet_run, capfd):
    """A label edited and the manifest 'fixed' to match it: the render stage (not current) writes
    the manifest again from the meta records, which still hold the label's true sha256, and the
    open refuses the label."""
    data = work / "dataset"
    rel = ground_truth_edited(data)
    m = _manifest(data)
    rec = next(r for r in m["files"] if r["path"] == rel)
    rec["sha256"] = hashlib.sha256((data / rel).read_bytes()).hexdigest()
    (data / "manifest.json").write_text(json.dumps(m, indent=1))
    rc = _run(work)
    # before the error: the run's progress and the render summary (which says DAMAGED; it is
    # printed to the sys.stderr bound when render_job was imported, so capfd may not see it)
    _assert_refused(rc, capfd.readouterr(), data, ("corrupt", rel), extra_lines=("[run] ", "dataset ", "  "))


def test_run_solves_again_when_its_poses_were_edited(work, quiet_run, capfd):
    """stages.json records the sha256 of each stage's outputs: a poses.json edited after a good run
    (one frame's pose moved) is made again, never trusted."""
    path = work / "poses.json"
    original = json.loads(path.read_text())
    edited = json.loads(path.read_text())
    fid = next(f for f, r in edited["frames"].items() if r["ok"])
    edited["frames"][fid]["pose"]["x_mm"] += 50.0
    path.write_text(json.dumps(edited))
    assert _run(work) == 1
    captured = capfd.readouterr()
    assert "dockfactory: error" not in captured.err
    assert "[run] solve: poses current, skipped" not in captured.err
    assert "[run] solve:" in captured.err
    assert json.loads(path.read_text())["frames"][fid]["pose"] == original["frames"][fid]["pose"]
