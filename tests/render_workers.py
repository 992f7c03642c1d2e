"""A render worker process for tests that talk to it directly (generator.worker_pool)."""
from dockfactory.generator.render_job import worker_init_request
from dockfactory.generator.worker_pool import WorkerProcess


def start_worker(cfg, root, timeout_s: float) -> WorkerProcess:
    """A started worker for ``cfg`` writing its frames under ``root`` (2 threads, EXR kept)."""
    proc = WorkerProcess(worker_init_request(cfg, root, 2, keep_exr=True), root / "logs" / "worker.log")
    proc.start(timeout_s)
    return proc
