"""Rendering across nodes: a real multi-node Ray cluster started on one machine
(``ray.cluster_utils.Cluster``: a head and a second node, each its own raylet and worker
processes), a tiny dataset rendered with ``--executor ray``, the second node killed half-way.
The render still completes (the lost node's frame is retried by the surviving actor), ``dataset
verify`` passes, and every content file equals a single-process local render byte for byte. (A
frame takes about a second, so the node dies with a frame in flight: at 0.2 s per frame it was
sometimes caught between two frames and nothing was retried.)"""
import threading
import time

import pytest

from dockfactory.core.config import load_config
from dockfactory.generator.datasets import tools as dt
from dockfactory.generator.render_job import JobOptions, run_render

pytestmark = [pytest.mark.render, pytest.mark.slow]

TINY = """
[dataset]
name = "ray-cluster"
seed = 31
frames = 6
train_fraction = 0.5
[conditions]
normal = 1
[repeatability]
poses = 1
captures = 1
[image]
width = 320
height = 240
[camera]
focal_px = [300, 740]
margin_px = 8
[render]
samples = 4
keep_exr = false
frame_timeout_s = 120
marker_samples = 0   # the job mechanics, not label-aware sampling (its own render tests)
[export]
formats = []
"""


def _labels(root) -> int:
    folder = root / "labels"
    return len(list(folder.glob("*.json"))) if folder.is_dir() else 0


def _kill_when(cluster, node, root, at: int, killed: dict) -> None:
    """Remove ``node`` (its raylet and every process on it) once ``at`` labels exist."""
    deadline = time.monotonic() + 600
    while _labels(root) < at and time.monotonic() < deadline:
        time.sleep(0.05)
    killed["labels_then"] = _labels(root)
    cluster.remove_node(node, allow_graceful=False)
    killed["at"] = time.monotonic()


def test_a_node_dies_half_way_and_the_render_still_matches_a_local_one(tmp_path):
    ray = pytest.importorskip("ray")
    from ray.cluster_utils import Cluster
    cfg_path = tmp_path / "tiny.toml"
    cfg_path.write_text(TINY)
    cfg = load_config(cfg_path)
    local = run_render(cfg, tmp_path / "local", TINY, JobOptions(progress=False, workers=1, threads=1))
    assert local.ok and local.complete
    cluster = Cluster(initialize_head=True, head_node_args={"num_cpus": 1})
    try:
        second = cluster.add_node(num_cpus=1)
        cluster.wait_for_nodes()
        ray.init(address=cluster.address, include_dashboard=False, log_to_driver=False)
        assert len([n for n in ray.nodes() if n["Alive"]]) == 2
        out, killed = tmp_path / "ray", {}
        killer = threading.Thread(target=_kill_when, args=(cluster, second, out, 2, killed), daemon=True)
        killer.start()
        summary = run_render(cfg, out, TINY, JobOptions(progress=False, executor="ray", workers=2, threads=1))
        killer.join(timeout=60)
    finally:
        ray.shutdown()
        cluster.shutdown()
    planned = 7
    assert killed.get("labels_then", planned) < planned, "the node was killed after the render had finished"
    assert summary.ok and summary.complete, summary.text()
    assert summary.retried >= 1, summary.text()   # the frame the dead node was rendering
    assert dt.verify(out).ok, dt.verify(out).text()
    mine = {rel: (out / rel).read_bytes() for rel in dt.content_files(out)}
    theirs = {rel: (tmp_path / "local" / rel).read_bytes() for rel in dt.content_files(tmp_path / "local")}
    assert mine.keys() == theirs.keys() and len(mine) > planned
    assert [rel for rel in mine if mine[rel] != theirs[rel]] == []
