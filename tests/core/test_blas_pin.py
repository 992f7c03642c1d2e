"""Labels the same on every CPU: numpy's OpenBLAS kernel and its trigonometry paths are pinned (core.blas).

The published paper dataset was rendered on a CPU whose OpenBLAS ran its SSE3 kernel; on an
AVX2/AVX-512 machine the default kernel gave other last bits in every label's geometry, and
``dataset verify --manifest`` refused the re-render. These tests check the pin where it is set
(the command's entry point, every render worker), the refusal when it could not take effect, and, with
Cycles, that a re-rendered published frame verifies on this machine. numpy's AVX-512 sin and cos
(which the published generator took) round otherwise than libm's: with them pinned off, the frame
matches the published geometry as libm gives it (fingerprints_v3.npz), on every CPU.
"""
import os
import json
import subprocess
import sys

import pytest

import dockfactory
from dockfactory.core import blas
from dockfactory.core.errors import DockfactoryError
from dockfactory.generator import worker_pool
from dockfactory.generator.render_job import JobOptions, run_render


def _python(code: str, **env) -> subprocess.CompletedProcess:
    full = {k: v for k, v in os.environ.items() if k != blas.ENV}
    full.update(env)
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=full, timeout=120)


def _needs_openblas():
    if blas.openblas_core() is None:
        pytest.skip("numpy does not use OpenBLAS here: nothing to pin")


def test_the_pin_set_before_numpy_loads_runs_the_label_kernel():
    _needs_openblas()
    out = _python("import os, dockfactory\ndockfactory.pin_label_arithmetic(os.environ)\nimport numpy\n"
                  "from dockfactory.core.blas import openblas_core\nprint(openblas_core())")
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == blas.LABEL_BLAS_CORE


def test_the_pin_switches_numpys_avx512_paths_off_and_keeps_the_callers():
    code = ("import os, dockfactory\ndockfactory.pin_label_arithmetic(os.environ)\nimport numpy\n"
            "from dockfactory.core.blas import numpy_simd_on\n"
            "from numpy.core._multiarray_umath import __cpu_features__ as f\n"
            "print(os.environ['NPY_DISABLE_CPU_FEATURES']); print(numpy_simd_on(), f['AVX2'])")
    out = _python(code, NPY_DISABLE_CPU_FEATURES="AVX2")
    assert out.returncode == 0, out.stderr
    env, state = out.stdout.strip().splitlines()
    assert env.split() == ["AVX2", *dockfactory.LABEL_SIMD_OFF]
    assert state == "[] False"     # the caller's AVX2 off as asked, no AVX-512 path on any CPU


def test_a_feature_numpy_has_no_paths_for_is_not_counted_as_on(monkeypatch):
    """A CPU with AVX512_SPR under a numpy that dispatches no AVX512_SPR path (1.26) runs nothing of
    it: only the dispatched features the CPU has and the pin left on count."""
    monkeypatch.setattr(blas, "__cpu_features__", {"AVX512_SPR": True, "AVX512_SKX": False, "AVX2": True})
    monkeypatch.setattr(blas, "__cpu_dispatch__", ["AVX2", "AVX512_SKX"])
    assert blas.numpy_simd_on() == []
    monkeypatch.setattr(blas, "__cpu_dispatch__", ["AVX2", "AVX512_SKX", "AVX512_SPR"])
    assert blas.numpy_simd_on() == ["AVX512_SPR"]


def test_a_render_with_numpy_on_its_avx512_paths_is_refused_in_one_line(monkeypatch, repo_root, tmp_path):
    from dockfactory.core.config import load_config
    monkeypatch.setattr(blas, "numpy_simd_on", lambda: ["AVX512_SKX"])
    cfg = load_config(repo_root / "configs" / "smoke.toml")
    root = tmp_path / "ds"
    with pytest.raises(DockfactoryError, match="numpy runs its AVX512_SKX paths: labels' sin and cos"):
        run_render(cfg, root, (repo_root / "configs" / "smoke.toml").read_text(), JobOptions())
    assert not root.exists()


def test_numpy_loaded_first_with_another_kernel_is_refused_in_one_line():
    _needs_openblas()
    code = ("import numpy, dockfactory\nfrom dockfactory.core.blas import check_label_blas, openblas_core\n"
            "print(openblas_core())\ncheck_label_blas()")
    out = _python(code, OPENBLAS_CORETYPE="Core2")   # a kernel every x86-64 CPU runs, not the label one
    if out.stdout.strip() != "Core2":
        pytest.skip(f"OpenBLAS here cannot run the Core2 kernel ({out.stdout.strip()!r})")
    assert out.returncode == 1
    last = out.stderr.strip().splitlines()[-1]
    assert "DockfactoryError" in last and "runs its Core2 kernel, not Prescott" in last


def test_a_render_is_refused_before_anything_is_written(monkeypatch, repo_root, tmp_path):
    from dockfactory.core.config import load_config
    monkeypatch.setattr(blas, "openblas_core", lambda: "Haswell")
    cfg = load_config(repo_root / "configs" / "smoke.toml")
    root = tmp_path / "ds"
    with pytest.raises(DockfactoryError, match="OpenBLAS runs its Haswell kernel"):
        run_render(cfg, root, (repo_root / "configs" / "smoke.toml").read_text(), JobOptions())
    assert not root.exists()


def test_every_render_worker_gets_the_label_kernel_even_from_a_caller_env(monkeypatch, tmp_path):
    seen = {}

    class Stop(Exception):
        pass

    def popen(cmd, **kw):
        seen.update(kw["env"])
        raise Stop

    monkeypatch.setattr(worker_pool.subprocess, "Popen", popen)
    proc = worker_pool.WorkerProcess({"op": "init"}, tmp_path / "w.log",
                                     env={"PATH": "/bin", blas.ENV: "Haswell", blas.LABEL_SIMD_ENV: "AVX2"})
    with pytest.raises(Stop):
        proc.start(1.0)
    assert seen[blas.ENV] == blas.LABEL_BLAS_CORE and seen["PATH"] == "/bin"
    assert seen[blas.LABEL_SIMD_ENV].split() == ["AVX2", *blas.LABEL_SIMD_OFF]


@pytest.mark.render
def test_a_published_paper_frame_rerendered_here_verifies(repo_root, tmp_path):
    """Frame 000001 of the published paper dataset (8e89fd1e76e6ba2b), rendered on this machine:
    its label geometry equals the published one (byte for byte, image measurements aside, the
    sections' silhouettes as the published generator drew them) and its image is within the
    published tolerance."""
    out = tmp_path / "paper"
    render = subprocess.run([sys.executable, "-m", "dockfactory", "render", "paper", "--out", str(out),
                             "--frames", "000001", "--workers", "1", "--quiet"],
                            capture_output=True, text=True, timeout=600)
    assert render.returncode == 0, render.stderr
    verify = subprocess.run([sys.executable, "-m", "dockfactory", "dataset", "verify", str(out), "--manifest",
                             str(repo_root / "results" / "paper" / "manifest.json")],
                            capture_output=True, text=True, timeout=300)
    assert verify.returncode == 0, verify.stdout + verify.stderr
    assert "1 frames checked: labels" in verify.stdout
    # the published generator drew sections' silhouettes as a convex hull (fixed since): verify
    # compares them as it drew them, and nothing else is let through: a marker moved by 1e-3 px fails
    assert "1 labels match once their sections' pixels_all and bbox_obj_px are drawn" in verify.stdout
    assert "1 labels match the published geometry as libm's sin and cos give it" in verify.stdout
    path = out / "labels" / "000001.json"
    label = json.loads(path.read_text())
    label["markers"][0]["center_px"][0] += 1e-3
    path.write_text(json.dumps(label, indent=1) + "\n")
    again = subprocess.run([sys.executable, "-m", "dockfactory", "dataset", "verify", str(out), "--manifest",
                            str(repo_root / "results" / "paper" / "manifest.json")],
                           capture_output=True, text=True, timeout=300)
    assert again.returncode != 0 and "labels/000001.json: differs from the manifest beyond" in again.stdout


def test_the_label_kernel_is_the_one_that_made_the_published_datasets():
    # changing it changes every label's last bits without changing the version id (the constant
    # lives in dockfactory/__init__.py, which the version's source hash does not cover)
    assert blas.LABEL_BLAS_CORE == "Prescott"
