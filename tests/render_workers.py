"""A render worker process for tests that talk to it directly (generator.worker_pool)."""
from dockfactory.core.scene import to_dict
from dockfactory.generator.random_draws import static_scene
from dockfactory.generator.worker_pool import WorkerProcess


def start_worker(cfg, root, timeout_s: float) -> WorkerProcess:
    """A started worker for ``cfg`` writing its frames under ``root`` (2 threads, EXR kept)."""
    init = {"op": "init", "static": to_dict(static_scene(cfg)), "width": cfg.image.width,
            "height": cfg.image.height, "threads": 2, "root": str(root), "keep_exr": True,
            "visible_threshold": cfg.labels.visible_threshold, "min_chroma": cfg.labels.min_chroma}
    proc = WorkerProcess(init, root / "logs" / "worker.log")
    proc.start(timeout_s)
    return proc
