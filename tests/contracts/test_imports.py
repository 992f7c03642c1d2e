"""Every module outside blender_scenes/ imports in a process where bpy is absent, from any folder."""
import subprocess
import sys

BLOCK_BPY = """
import sys, importlib.abc
class Block(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path, target=None):
        if name.split('.')[0] in ('bpy', 'mathutils'):
            raise ImportError('bpy is not available in this process')
sys.meta_path.insert(0, Block())
"""
PACKAGES = ("core", "generator", "detector", "solver", "eval")


def test_modules_import_without_bpy(repo_root, tmp_path):
    modules = ["dockfactory"]
    for pkg in PACKAGES:
        for path in sorted((repo_root / pkg).rglob("*.py")):   # subpackages too (eval/report/)
            parts = path.relative_to(repo_root / pkg).with_suffix("").parts
            parts = parts[:-1] if parts[-1] == "__init__" else parts
            modules.append(".".join(("dockfactory", pkg, *parts)))
    code = BLOCK_BPY + "\nimport importlib\n" + "".join(f"importlib.import_module({m!r})\n" for m in modules)
    code += "assert 'bpy' not in sys.modules\nprint('ok', len(%r))\n" % (modules,)
    proc = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.startswith("ok")


def test_cli_help_is_instant_and_bpy_free(tmp_path):
    code = BLOCK_BPY + "\nfrom dockfactory.cli import build_parser\nbuild_parser().format_help()\n" \
        "assert 'bpy' not in sys.modules and 'torch' not in sys.modules\n"
    proc = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr


def test_a_foreign_folder_named_like_a_subpackage_cannot_shadow_ours(tmp_path):
    """The old layout imported `eval`, `solver`, ...: a folder of that name in the working directory
    shadowed them. Under one import root it cannot."""
    for name in ("eval", "solver", "generator", "detector", "core"):
        (tmp_path / name).mkdir()
        (tmp_path / name / "__init__.py").write_text("raise ImportError('foreign package imported')\n")
    code = "import dockfactory.cli, dockfactory.solver, dockfactory.core.config; print('ok')"
    proc = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True)
    assert proc.returncode == 0 and proc.stdout.strip() == "ok", proc.stderr


def test_the_detector_facade_names_resolve_and_load_torch_only_when_used(tmp_path):
    """``import dockfactory.detector`` loads no torch; each name of its ``__all__`` resolves to its
    owner's object (the lazy ones too), and an unknown name is an AttributeError."""
    code = ("import sys, dockfactory.detector as d\n"
            "assert 'torch' not in sys.modules\n"
            "d.refine_centre, d.card_figures\n"
            "assert 'torch' not in sys.modules\n"
            "from dockfactory.detector import train, infer, checkpoint, centre\n"
            "assert d.train_detector is train.train and d.detect_dataset is infer.detect_dataset\n"
            "assert d.load_model is checkpoint.load_model and d.refine_centre is centre.refine_centre\n"
            "assert all(getattr(d, n) is not None for n in d.__all__)\n"
            "try:\n    d.no_such_name\nexcept AttributeError as e:\n    print('ok', e)\n")
    _runs_ok(code, tmp_path)


def test_the_generator_facade_imports_nothing_and_its_names_resolve(tmp_path):
    """``import dockfactory.generator`` loads no module beyond what ``import dockfactory`` loads (render
    workers import it: the dataset tools must not load there), no torch, no bpy; each name of its
    ``__all__`` resolves, on first use, to its owner's object, and an unknown name is an AttributeError."""
    code = ("import sys, dockfactory\n"
            "before = set(sys.modules)\n"
            "import dockfactory.generator as g\n"
            "assert set(sys.modules) - before == {'dockfactory.generator'}, sorted(set(sys.modules) - before)\n"
            "assert 'torch' not in sys.modules and 'bpy' not in sys.modules\n"
            "from dockfactory.generator import render_job\n"
            "from dockfactory.generator.datasets import reader, check, tools, diff, card\n"
            "assert g.run_render is render_job.run_render and g.JobOptions is render_job.JobOptions\n"
            "assert g.Dataset is reader.Dataset and g.verify_dataset is check.verify\n"
            "assert g.export_dataset is tools.export and g.dataset_info is tools.info\n"
            "assert g.diff_datasets is diff.diff and g.write_card is card.write_card\n"
            "assert all(getattr(g, n) is not None for n in g.__all__) and set(g.__all__) <= set(dir(g))\n"
            "try:\n    g.no_such_name\nexcept AttributeError as e:\n    print('ok', e)\n")
    _runs_ok(code, tmp_path)


def test_the_datasets_facade_imports_nothing_and_its_names_resolve(tmp_path):
    """``import dockfactory.generator.datasets`` loads none of the room's modules (a module of the
    room importing a helper of another must not load them all); each name of its ``__all__``
    resolves, on first use, to its owner's object, and an unknown name is an AttributeError."""
    code = ("import sys, dockfactory.generator\n"
            "before = set(sys.modules)\n"
            "import dockfactory.generator.datasets as ds\n"
            "assert set(sys.modules) - before == {'dockfactory.generator.datasets'}, sorted(set(sys.modules) - before)\n"
            "from dockfactory.generator.datasets import reader, folder, check, tools, diff, card, hf_view, published\n"
            "assert ds.Dataset is reader.Dataset and ds.DatasetError is folder.DatasetError\n"
            "assert ds.verify_dataset is check.verify and ds.dataset_info is tools.info\n"
            "assert ds.export_dataset is tools.export and ds.diff_datasets is diff.diff\n"
            "assert ds.write_card is card.write_card and ds.write_hf_view is hf_view.write_hf_view\n"
            "assert ds.publish_dataset is published.publish and ds.verify_against_manifest is published.verify_against\n"
            "assert set(ds.__all__) <= set(dir(ds))\n"
            "try:\n    ds.no_such_name\nexcept AttributeError as e:\n    print('ok', e)\n")
    _runs_ok(code, tmp_path)


def test_the_camera_chain_facade_imports_nothing_and_its_names_resolve(tmp_path):
    """``import dockfactory.core.camera_chain`` loads none of the chain's modules (``core.scene``
    imports a stage module, which imports ``core.scene``: an eager facade would be a cycle); each
    name of its ``__all__`` resolves, on first use, to its owner's object."""
    code = ("import sys, dockfactory.core\n"
            "before = set(sys.modules)\n"
            "import dockfactory.core.camera_chain as cc\n"
            "assert set(sys.modules) - before == {'dockfactory.core.camera_chain'}, sorted(set(sys.modules) - before)\n"
            "from dockfactory.core.camera_chain import order, lens, colour_sensor, isp, encoding\n"
            "assert cc.capture is order.capture and cc.expose_frame is order.expose_frame\n"
            "assert cc.develop is order.develop and cc.Capture is order.Capture\n"
            "assert cc.resample_passes is lens.resample_passes and cc.RenderPasses is lens.RenderPasses\n"
            "assert cc.ColourChain is colour_sensor.ColourChain and cc.develop_raw is isp.develop_raw\n"
            "assert cc.jpeg_round_trip is encoding.jpeg_round_trip and set(cc.__all__) <= set(dir(cc))\n"
            "try:\n    cc.no_such_name\nexcept AttributeError as e:\n    print('ok', e)\n")
    _runs_ok(code, tmp_path)


def test_no_facade_name_shadows_a_module_of_its_package(tmp_path):
    """``import dockfactory.eval.evaluate as m`` must give the module: a facade that bound a
    function of the same name as one of its package's modules would hand out the function. Two
    older facades do (``solver.upnp``, ``generator.exports.coco_results``): listed, so no new one
    can join them."""
    code = ("import importlib, pkgutil, types\n"
            "known = {('dockfactory.solver', 'upnp'), ('dockfactory.generator.exports', 'coco_results')}\n"
            "for pkg in ('dockfactory.eval', 'dockfactory.detector', 'dockfactory.solver',\n"
            "            'dockfactory.generator', 'dockfactory.generator.exports', 'dockfactory.generator.datasets',\n"
            "            'dockfactory.eval.report', 'dockfactory.core.camera_chain',\n"
            "            'dockfactory.measure'):\n"
            "    p = importlib.import_module(pkg)\n"
            "    for m in pkgutil.iter_modules(p.__path__):\n"
            "        importlib.import_module(f'{pkg}.{m.name}')\n"
            "        got = getattr(p, m.name)\n"
            "        assert isinstance(got, types.ModuleType) or (pkg, m.name) in known, (pkg, m.name, got)\n"
            "print('ok')\n")
    _runs_ok(code, tmp_path)


def _runs_ok(code: str, tmp_path) -> None:
    """Run ``code`` in a fresh interpreter; it must exit 0 and print a line starting with ``ok``."""
    proc = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True)
    assert proc.returncode == 0 and proc.stdout.startswith("ok"), proc.stderr
