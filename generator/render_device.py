"""The render device's check before a render starts: ``[render] device = "gpu"`` needs a GPU that
Cycles can use (OptiX, CUDA or HIP), asked of Blender in a child process (bpy is only ever imported
in processes that render, never in the job's). Without one the render is refused in one line
(DockfactoryError, exit 2) before anything is written. With ``--executor ray`` the GPUs are the
cluster's, not this machine's: each worker checks its own when it starts (its init fails with the
same words, and the frame fails).
"""
from __future__ import annotations

import json
import os
import subprocess
import sys

from dockfactory.core.config import Config
from dockfactory.core.errors import DockfactoryError

PROBE = ("import json\nfrom dockfactory.blender_scenes.render import gpu_devices\n"
         "print('GPUS ' + json.dumps(gpu_devices()))\n")
PROBE_TIMEOUT_S = 300.0   # importing bpy and listing its devices: seconds; a hung driver: this


def probe_gpus(env: dict | None = None) -> dict[str, list[str]]:
    """Cycles' GPU devices by backend, from a child Python that imports bpy (an empty dict: none).
    DockfactoryError when the child cannot tell (no bpy, a crash, a timeout)."""
    try:
        proc = subprocess.run([sys.executable, "-c", PROBE], capture_output=True, text=True,
                              timeout=PROBE_TIMEOUT_S, env=dict(os.environ if env is None else env))
    except subprocess.TimeoutExpired:
        raise DockfactoryError(f'[render] device = "gpu": Blender did not list its GPUs within '
                               f"{PROBE_TIMEOUT_S:.0f} s") from None
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("GPUS ")]
    if proc.returncode != 0 or not lines:
        last = (proc.stderr.strip().splitlines() or ["no message"])[-1][:200]
        raise DockfactoryError(f'[render] device = "gpu": could not ask Blender for its GPUs ({last})')
    return json.loads(lines[-1][5:])


def check_render_device(cfg: Config, executor: str, env: dict | None = None) -> None:
    """Refuse (DockfactoryError) a local render on "gpu" without a usable GPU; nothing else."""
    if cfg.render.device != "gpu" or executor != "local":
        return
    if not probe_gpus(env):
        raise DockfactoryError('[render] device = "gpu": no usable GPU on this machine (Cycles finds no OptiX, '
                               'CUDA or HIP device); render with device = "cpu"')
