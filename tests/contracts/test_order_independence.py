"""A frame's bytes depend on (config, seed, frame index) only, never on what the render worker
rendered before it: alone, after any other condition, shuffled, sharded, resumed or after a worker
crash (issue 10, finding 4). configs/smoke.toml at 320 x 240, one sample.

The render job hands a worker its frames in plan order (``--frames`` picks frames, not their
order), so orders the job never produces today (B right after A, a shuffled run) are driven
through the worker protocol itself: the same process, requests and post-processing as a job.
"""
import itertools
import os
import random
from pathlib import Path

import pytest

from dockfactory.core.config import load_config
from dockfactory.core.scene import to_dict
from dockfactory.generator.frame_output import frame_paths
from dockfactory.generator.render_job import JobOptions, run_render, worker_init_request
from dockfactory.generator.sampler import frame_plan, sample_frame
from dockfactory.generator.worker_pool import WorkerProcess

pytestmark = pytest.mark.render

TIMEOUT_S = 120


@pytest.fixture(scope="module")
def smoke(repo_root):
    path = repo_root / "configs" / "smoke.toml"
    cfg = load_config(path)
    plan = frame_plan(cfg)
    scenes = {s.frame_id: sample_frame(cfg, s) for s in plan}
    # one frame per condition, and both kinds of glare (a lamp in view, a specular highlight)
    picks = {}
    for s in plan:
        key = (s.condition, scenes[s.frame_id].glare_kind)
        picks.setdefault(key, s.frame_id)
    conditions = {c for c, _ in picks}
    assert conditions == {"normal", "low_light", "occlusion", "glare"}, picks
    assert {g for c, g in picks if c == "glare"} == {"lamp_in_view", "specular"}, picks
    return cfg, path.read_text(), scenes, sorted(picks.values())


def frame_files(root: Path, fid: str) -> dict[str, bytes]:
    """The bytes of one frame's image, EXR, label and meta (and raw frame, where the config keeps one)."""
    return {kind: p.read_bytes() for kind, p in frame_paths(root, fid).items() if kind != "raw" or p.exists()}


def all_frames(root: Path, scenes) -> dict[str, dict[str, bytes]]:
    return {fid: frame_files(root, fid) for fid in scenes}


def differences(got: dict, want: dict) -> list[str]:
    return [f"{fid} {kind}" for fid in sorted(want) for kind in sorted(want[fid])
            if got.get(fid, {}).get(kind) != want[fid][kind]]


class Worker:
    """One render worker process driven request by request (files read after each reply)."""

    def __init__(self, smoke, root: Path):
        cfg, _, self.scenes, _ = smoke
        self.root = root
        self.proc = WorkerProcess(worker_init_request(cfg, root, 2), root / "logs" / "worker.log")
        self.proc.start(TIMEOUT_S)

    def render(self, fid: str) -> dict[str, bytes]:
        reply = self.proc.request({"op": "render", "frame": to_dict(self.scenes[fid])}, TIMEOUT_S)
        assert reply.get("ok"), reply
        return frame_files(self.root, fid)

    def state(self, fid: str, full: bool = False) -> dict:
        reply = self.proc.request({"op": "state", "frame": to_dict(self.scenes[fid]), "full": full}, TIMEOUT_S)
        assert reply.get("ok"), reply
        return reply

    def close(self) -> None:
        self.proc.close()


def every_ordered_pair(ids: list[str]) -> list[str]:
    """A sequence in which every ordered pair (a, b), a != b, of ``ids`` appears as neighbours
    (an Eulerian circuit of the complete directed graph: n * (n - 1) + 1 items)."""
    out_edges = {a: [b for b in reversed(ids) if b != a] for a in ids}
    stack, circuit = [ids[0]], []
    while stack:
        v = stack[-1]
        if out_edges[v]:
            stack.append(out_edges[v].pop())
        else:
            circuit.append(stack.pop())
    circuit.reverse()
    pairs = set(itertools.pairwise(circuit))
    assert len(pairs) == len(ids) * (len(ids) - 1) == len(circuit) - 1
    return circuit


@pytest.fixture(scope="module")
def single_run(smoke, tmp_path_factory):
    """The reference: all of smoke in one job (one worker, plan order)."""
    cfg, text, scenes, _ = smoke
    root = tmp_path_factory.mktemp("single") / "ds"
    summary = run_render(cfg, root, text, JobOptions(progress=False))
    assert summary.ok and summary.complete, summary.text()
    return all_frames(root, scenes)


def covering_walks(ids: list[str], second: dict[str, str], length: int = 6) -> list[list[str]]:
    """One frame sequence per id (starting with it, ``length`` frames, ``second[id]`` second when
    given) such that together they hold every ordered pair (a, b), a != b, as neighbours."""
    walks = []

    def solve(k, free):
        if k == len(ids):
            return not free
        if len(free) > (len(ids) - k) * (length - 1):
            return False

        def grow(walk, free):
            if len(walk) == length:
                walks.append(walk)
                if solve(k + 1, free):
                    return True
                walks.pop()
                return False
            options = [second[walk[0]]] if len(walk) == 1 and walk[0] in second else ids
            # uncovered pairs first
            for b in sorted((b for b in options if b != walk[-1]), key=lambda b: (walk[-1], b) not in free):
                if grow([*walk, b], free - {(walk[-1], b)}):
                    return True
            return False
        return grow([ids[k]], free)

    assert solve(0, frozenset((a, b) for a in ids for b in ids if a != b))
    return walks


@pytest.fixture(scope="module")
def histories(smoke, tmp_path_factory):
    """The picked frames rendered with many histories: one fresh worker per picked frame renders
    it first (its bytes "alone"), then a walk through the others; together the walks hold every
    ordered pair of picked frames as neighbours, and the lamp-in-view frame is followed by the
    specular-glare one in a fresh worker (the case of the issue).
    Returns ({frame id: files alone}, [(previous frame id, frame id, files)])."""
    _, _, scenes, picks = smoke
    lamp = next(f for f in picks if scenes[f].glare_kind == "lamp_in_view")
    specular = next(f for f in picks if scenes[f].glare_kind == "specular")
    alone, after = {}, []
    for walk in covering_walks(picks, {lamp: specular}):
        w = Worker(smoke, tmp_path_factory.mktemp(f"walk{walk[0]}"))
        try:
            alone[walk[0]] = w.render(walk[0])
            after += [(prev, fid, w.render(fid)) for prev, fid in itertools.pairwise(walk)]
        finally:
            w.close()
    return alone, after


def test_blender_state_after_a_frame_does_not_depend_on_earlier_frames(smoke, tmp_path):
    """apply_frame sets every property it ever changes: the whole Blender state a render reads
    (settings, objects, lights, camera, materials, world) after frame B is the same whatever
    frame came before it. Cheap (no rendering), and names the property that leaks."""
    _, _, _, picks = smoke
    w = Worker(smoke, tmp_path)
    try:
        seen, leaks = {}, []
        seq = every_ordered_pair(picks)
        w.state(seq[-2])   # so that every state below has a predecessor to name
        for prev, fid in itertools.pairwise([seq[-2], *seq]):
            digest = w.state(fid)["digest"]
            if seen.setdefault(fid, (digest, prev))[0] != digest:
                leaks.append((seen[fid][1], prev, fid))
        if leaks:
            first_prev, prev, fid = leaks[0]
            states = []
            for p in (first_prev, prev):
                if p is not None:
                    w.state(p)
                states.append(w.state(fid, full=True)["state"])
            keys = sorted(k for k in set(states[0]) | set(states[1]) if states[0].get(k) != states[1].get(k))
            pytest.fail(f"{len(leaks)} of {len(seq)} frame updates depend on the frame before; frame {fid} "
                        f"after {first_prev} vs after {prev} differs at {keys[:10]}")
    finally:
        w.close()


def test_each_frame_after_any_other_equals_the_frame_alone(histories):
    """For every ordered pair (A, B) of the picked frames (one per condition, both kinds of
    glare), B rendered right after A has the bytes of B rendered alone (image, EXR, label, meta)."""
    alone, after = histories
    bad = [f"{fid} after {prev}: {kind}" for prev, fid, files in after
           for kind in files if files[kind] != alone[fid][kind]]
    assert not bad, bad


def test_alone_equals_in_order(histories, single_run):
    """A frame rendered alone has the bytes it has inside an ordered run of the whole config."""
    alone, _ = histories
    assert not differences(single_run, alone)


def test_shuffled_run_equals_ordered_run(smoke, single_run, tmp_path):
    _, _, scenes, picks = smoke
    lamp = next(f for f in picks if scenes[f].glare_kind == "lamp_in_view")
    specular = next(f for f in picks if scenes[f].glare_kind == "specular")
    rest = sorted(set(scenes) - {lamp, specular})
    random.Random(4).shuffle(rest)
    # the pair of the issue first: with Cycles' persistent data, a worker whose first frame had
    # the lamp in view rendered a later specular-glare frame differently
    order = [lamp, specular, *rest]
    w = Worker(smoke, tmp_path)
    try:
        got = {fid: w.render(fid) for fid in order}
    finally:
        w.close()
    assert not differences(got, single_run), order


def test_shards_equal_a_single_run(smoke, single_run, tmp_path):
    cfg, text, scenes, _ = smoke
    for k in (1, 2):
        summary = run_render(cfg, tmp_path / "ds", text, JobOptions(progress=False, shard=(k, 2)))
        assert summary.ok, summary.text()
    assert summary.complete
    assert not differences(all_frames(tmp_path / "ds", scenes), single_run)


def test_partial_frames_then_resume_equal_a_single_run(smoke, single_run, tmp_path):
    """``--frames`` with a shuffled subset (the lamp-in-view frame before the specular-glare
    one, as in the issue), then the same command without ``--frames`` and with ``--workers 2``
    renders the rest."""
    cfg, text, scenes, _ = smoke
    first = ("000003", "000007", "000001")
    summary = run_render(cfg, tmp_path / "ds", text, JobOptions(progress=False, frame_ids=first))
    assert summary.ok and summary.rendered == 3 and not summary.complete, summary.text()
    # the rest on two workers (one thread each, frames handed out as they finish)
    summary = run_render(cfg, tmp_path / "ds", text, JobOptions(progress=False, workers=2))
    assert summary.ok and summary.complete and summary.rendered == len(scenes) - 3, summary.text()
    assert not differences(all_frames(tmp_path / "ds", scenes), single_run)


def test_frames_after_a_worker_crash_equal_a_clean_run(smoke, single_run, tmp_path):
    """The worker is killed (-9) when it receives its first frame; a fresh worker retries the
    frames it had in flight and renders the rest, a history unlike the clean run's (the
    lamp-in-view frame first, then the specular-glare one): every byte still agrees."""
    cfg, text, scenes, picks = smoke
    lamp = next(f for f in picks if scenes[f].glare_kind == "lamp_in_view")
    specular = next(f for f in picks if scenes[f].glare_kind == "specular")
    occlusion = next(f for f in picks if scenes[f].spec.condition == "occlusion")
    ids = sorted({lamp, specular, occlusion})
    assert ids[0] == lamp
    env = dict(os.environ, DOCKFACTORY_FAULT=f"crash:{lamp}", DOCKFACTORY_FAULT_DIR=str(tmp_path))
    summary = run_render(cfg, tmp_path / "ds", text, JobOptions(progress=False, env=env, frame_ids=tuple(ids)))
    assert summary.ok and summary.retried >= 1 and summary.rendered + summary.recovered == len(ids), summary.text()
    assert (tmp_path / f"fault-crash-{lamp}").exists()
    got = {fid: frame_files(tmp_path / "ds", fid) for fid in ids}
    assert not differences(got, {fid: single_run[fid] for fid in ids})


# --- the same for real cameras: distortion, chromatic aberration, depth of field, JPEG, runs -----

LENS_SMOKE = """
[dataset]
name = "smoke-lens"
seed = 7
frames = 6
train_fraction = 0.5
[conditions]
normal = 1
low_light = 1
occlusion = 1
glare = 1
[repeatability]
poses = 1
captures = 2
[image]
width = 320
height = 240
[camera]
focal_px = [300, 750]
margin_px = 12
[camera_units]
count = 2
principal_offset_x_px = [-12, 12]
principal_offset_y_px = [-10, 10]
k1 = [-0.15, 0.05]
k2 = [-0.05, 0.05]
p1 = [-1e-3, 1e-3]
p2 = [-1e-3, 1e-3]
aberration_red_px = [-0.3, 0.3]
aberration_blue_px = [-0.3, 0.3]
sensor_width_mm = 8.8
depth_of_field = true
f_number = [2.8, 5.6]
focus_error_mm = [-100, 100]
jpeg = true
[runs]
frames_per_run = 2
[render]
samples = 1
keep_exr = true
frame_timeout_s = 120
marker_samples = 0   # the job mechanics, not label-aware sampling (its own render tests)
"""


@pytest.fixture(scope="module")
def lens_smoke(tmp_path_factory):
    """(cfg, text, scenes, frame ids) of LENS_SMOKE, and its frames rendered by one job in plan order."""
    d = tmp_path_factory.mktemp("lens-smoke")
    (d / "cfg.toml").write_text(LENS_SMOKE)
    cfg = load_config(d / "cfg.toml")
    scenes = {s.frame_id: sample_frame(cfg, s) for s in frame_plan(cfg)}
    assert {f.camera.unit for f in scenes.values()} == {0, 1}
    assert all(f.camera.f_number > 0 and f.camera.jpeg_quality and not f.camera.is_pinhole() for f in scenes.values())
    assert len({f.camera.canvas() for f in scenes.values()}) == 2   # the render size changes between units
    summary = run_render(cfg, d / "ds", LENS_SMOKE, JobOptions(progress=False))
    assert summary.ok and summary.complete, summary.text()
    return (cfg, LENS_SMOKE, scenes, sorted(scenes)), all_frames(d / "ds", scenes)


def test_lens_frames_blender_state_does_not_depend_on_earlier_frames(lens_smoke, tmp_path):
    smoke, _ = lens_smoke
    ids = smoke[3]
    w = Worker(smoke, tmp_path)
    try:
        seen = {}
        for fid in every_ordered_pair(ids):
            digest = w.state(fid)["digest"]
            assert seen.setdefault(fid, digest) == digest, fid
    finally:
        w.close()


def test_lens_frames_shuffled_equal_the_ordered_run(lens_smoke, tmp_path):
    """Distorted, aberrated, defocused, JPEG frames of two units (their canvases differ in size)
    rendered in reverse plan order by one worker have the bytes of the ordered job."""
    smoke, reference = lens_smoke
    w = Worker(smoke, tmp_path)
    try:
        got = {fid: w.render(fid) for fid in reversed(smoke[3])}
    finally:
        w.close()
    assert not differences(got, reference)
