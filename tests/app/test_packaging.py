"""A wheel installs a working dockfactory: built from the sources, installed non-editable into a
fresh venv, run from another folder with the shipped configs, weights and acceptance spec.

How, and why this way:
- The repository's sources are copied to a temporary folder first (without .venv, out, .git,
  build products), so building writes nothing into the repository; ``pip wheel --no-deps
  --no-build-isolation`` builds with the setuptools of the test extra (no network).
- The fresh venv is made with ``python -m venv --without-pip`` and the wheel is installed into it
  by this venv's pip (``pip --python FRESH/bin/python install --no-deps WHEEL``): a plain,
  non-editable install, its files in FRESH's site-packages.
- The heavy dependencies (bpy, torch, opencv, ...: several GB) are not installed a second time:
  one ``.pth`` file in FRESH's site-packages names this venv's site-packages, which Python then
  appends to ``sys.path`` after FRESH's own site-packages. That only adds the folder: ``.pth``
  files inside it are not processed (``site`` processes them only in site directories), so the
  editable install's finder (``__editable__*.pth``) of this venv is not active, and the
  ``dockfactory`` found is the wheel's (FRESH's site-packages come first). The test checks that:
  ``dockfactory.__file__`` and the shipped weights lie inside FRESH.
- Every command runs from an unrelated working folder, with FRESH/bin first on PATH and no
  PYTHONPATH, so nothing of the repository can be picked up by accident.

It renders (``dockfactory run smoke``: 10 frames at 320 x 240, then detect with the shipped weights,
solve, evaluate against the shipped acceptance spec, report): about a minute on 2 cores, so it is
marked ``render`` and ``slow`` (``make test`` runs it, ``make test-fast`` does not).
"""
import hashlib
import json
import os
import shutil
import subprocess
import sys
import sysconfig
import zipfile
from pathlib import Path

import pytest

from dockfactory.core.resources import WEIGHTS_NAME

pytestmark = [pytest.mark.render, pytest.mark.slow]

NOT_SOURCES = shutil.ignore_patterns(".venv", "out", ".git", "build", "dist", "*.egg-info",
                                     "__pycache__", ".pytest_cache", ".hypothesis", "*.pyc")


def _run(cmd, cwd, env, timeout=900):
    proc = subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)
    return proc


def _check(proc, *expected_codes):
    codes = expected_codes or (0,)
    assert proc.returncode in codes, (f"{proc.args} exited {proc.returncode}\n"
                                      f"stdout:\n{proc.stdout[-3000:]}\nstderr:\n{proc.stderr[-3000:]}")
    return proc


@pytest.fixture(scope="module")
def wheel(repo_root, tmp_path_factory):
    """The wheel built from a copy of the sources."""
    tmp = tmp_path_factory.mktemp("wheel")
    src = tmp / "src"
    shutil.copytree(repo_root, src, ignore=NOT_SOURCES)
    dist = tmp / "dist"
    _check(_run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation",
                 "--no-cache-dir", "--quiet", "--wheel-dir", str(dist), str(src)], cwd=tmp, env=None))
    wheels = list(dist.glob("dockfactory-*.whl"))
    assert len(wheels) == 1, wheels
    return wheels[0]


@pytest.fixture(scope="module")
def fresh(wheel, tmp_path_factory):
    """(venv folder, environment for commands) of a fresh venv holding only the wheel."""
    venv = tmp_path_factory.mktemp("fresh") / "venv"
    _check(_run([sys.executable, "-m", "venv", "--without-pip", str(venv)], cwd=venv.parent, env=None))
    py = venv / "bin" / "python"
    _check(_run([sys.executable, "-m", "pip", "--python", str(py), "install", "--no-deps",
                 "--no-cache-dir", "--quiet", str(wheel)], cwd=venv.parent, env=None))
    site = Path(_check(_run([str(py), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                            cwd=venv.parent, env=None)).stdout.strip())
    # the folders this interpreter finds its dependencies in: its site-packages, and any folder
    # that a .pth file of it put on sys.path (in order; only the folders, never their .pth files)
    ours = [sysconfig.get_paths()["purelib"], sysconfig.get_paths()["platlib"]]
    ours += [p for p in sys.path if Path(p).name in ("site-packages", "dist-packages")]
    ours = [p for p in dict.fromkeys(ours) if Path(p).is_dir()]
    (site / "heavy_deps_from_dev_venv.pth").write_text("".join(f"{p}\n" for p in ours))
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV", "PYTHONHOME")}
    env["PATH"] = f"{venv / 'bin'}{os.pathsep}{env.get('PATH', '')}"
    return venv, env


def test_wheel_holds_one_package_with_configs_and_weights(wheel, repo_root):
    names = zipfile.ZipFile(wheel).namelist()
    tops = {n.split("/")[0] for n in names}
    assert {t for t in tops if not t.endswith(".dist-info")} == {"dockfactory"}, tops
    for folder, pattern in (("configs", "*.toml"), ("models", "*.pt")):
        shipped = sorted(p.name for p in (repo_root / folder).glob(pattern))
        assert shipped, (folder, pattern)
        for name in shipped:
            assert f"dockfactory/{folder}/{name}" in names, name
    for sub in ("core", "generator", "blender_scenes", "solver", "detector", "eval", "eval/report", "generator/exports"):
        assert f"dockfactory/{sub}/__init__.py" in names, sub
    assert "dockfactory/__main__.py" in names
    assert not any(n.startswith("dockfactory/tests/") or "/bench/" in n for n in names)


def test_the_installed_wheel_works_from_another_folder(fresh, repo_root, tmp_path):
    venv, env = fresh
    work = tmp_path / "elsewhere"
    work.mkdir()

    # the wheel's package, not the repository's (no editable finder, no sys.path edits)
    probe = _check(_run([str(venv / "bin" / "python"), "-c",
                         "import json, sys, dockfactory; from dockfactory.core.resources import "
                         "shipped_weights, default_acceptance; print(json.dumps({'file': dockfactory.__file__, "
                         "'version': dockfactory.__version__, 'weights': str(shipped_weights()), "
                         "'acceptance': str(default_acceptance()), 'editable': [m for m in sys.modules "
                         "if 'editable' in m]}))"], cwd=work, env=env))
    info = json.loads(probe.stdout)
    for key in ("file", "weights", "acceptance"):
        assert Path(info[key]).resolve().is_relative_to(venv.resolve()), (key, info[key])
    assert info["version"] == "0.1.0" and info["editable"] == []

    proc = _check(_run(["dockfactory", "--help"], cwd=work, env=env, timeout=120))
    for cmd in ("render", "check-config", "run", "detect", "evaluate"):
        assert cmd in proc.stdout

    proc = _check(_run(["dockfactory", "check-config", "smoke"], cwd=work, env=env, timeout=300))
    assert "smoke" in proc.stdout + proc.stderr
    # the README's spelling, from a folder that has no configs/: the shipped config is used
    proc = _check(_run(["dockfactory", "check-config", "configs/smoke.toml"], cwd=work, env=env, timeout=300))
    assert "valid; dataset version" in proc.stdout

    # render -> detect (shipped weights) -> solve -> evaluate (shipped spec) -> report;
    # exit 0 accepted, 1 rejected, 3 not proven: all results, anything else is a failure
    out = work / "X"
    proc = _check(_run(["dockfactory", "run", "smoke", "--out", "X"], cwd=work, env=env, timeout=1800), 0, 1, 3)
    assert "verdict:" in proc.stdout
    manifest = json.loads((out / "dataset" / "manifest.json").read_text())
    assert manifest["counts"]["frames"] == 10 and manifest["image_size"] == [320, 240]
    assert len(list((out / "dataset" / "images").glob("*.png"))) == 10
    metrics = json.loads((out / "eval" / "metrics.json").read_text())
    assert proc.returncode == {"ACCEPTED": 0, "REJECTED": 1, "NOT PROVEN": 3}[metrics["acceptance"]["verdict"]]
    assert metrics["localization"]["n_frames"] == 4 and "detection" in metrics
    assert {c["name"] for c in metrics["acceptance"]["criteria"]} >= {"detection: map50", "detection: map50_95"}
    prov = json.loads((out / "eval" / "provenance.json").read_text())
    weights_sha = hashlib.sha256((repo_root / "models" / WEIGHTS_NAME).read_bytes()).hexdigest()
    assert prov["model_sha256"] == weights_sha
    assert (out / "report.html").is_file() and (out / "detections.json").is_file()

    proc = _check(_run(["dockfactory", "detect", "X/dataset", "--out", "d.json", "--quiet"], cwd=work, env=env,
                       timeout=900))
    dets = json.loads((work / "d.json").read_text())
    assert dets["dataset_version"] == manifest["version_id"]
    assert sorted(dets["frames"]) == ["000001", "000004", "000006", "000007"]   # the test split
    assert sum(len(v) for v in dets["frames"].values()) > 0
