"""Run bop_toolkit's calc_gt_info on a dockfactory BOP export (a script the BOP tests start in a
subprocess: bop_toolkit's renderer needs an OpenGL context, which stays out of the test process).

    python bop_toolkit_check.py BOP_EXPORT WORK_DIR WIDTH HEIGHT  -> JSON on stdout

Steps, as a user follows docs/datasets.md:
1. a copy of bop_toolkit (the installed ``bop_toolkit_lib``, or the checkout named by
   ``DOCKFACTORY_BOP_TOOLKIT``, with its ``scripts/``) in WORK_DIR, registered for the dataset
   name ``dockfactory`` by the three edits of ``dataset_params.py`` the docs give;
2. the export copied to WORK_DIR/datasets/dockfactory (calc_gt_info writes scene_gt_info.json
   over the export's own);
3. ``scripts/calc_gt_info.py`` with its parameter block set to that dataset and each split, the
   vispy renderer (headless: EGL's surfaceless platform, Mesa's software rasteriser), delta 15 mm.
4. bop_toolkit's renderer draws each section's model in its scene_gt pose with its cam_K: the
   pixels it covers, against the export's mask/<im>_<gt>.png;
5. when its plotting dependencies import (trimesh, tqdm), ``scripts/vis_poses.py gt`` on the test
   split with its defaults (models_eval/, test_targets_bop19.json): the images it wrote.
Prints, per split, bop_toolkit's scene_gt_info records, per image and object the pixels of the
render outside the export's mask and of the mask outside the render, and vis_poses' images
(null when it could not run for want of its dependencies).
"""
import json
import os
import re
import runpy
import shutil
import sys
from pathlib import Path

SPLITS = ("train", "val", "test", "repeat")


def toolkit_source() -> Path:
    """The folder holding ``bop_toolkit_lib/`` and ``scripts/``."""
    if os.environ.get("DOCKFACTORY_BOP_TOOLKIT"):
        return Path(os.environ["DOCKFACTORY_BOP_TOOLKIT"])
    import bop_toolkit_lib
    return Path(bop_toolkit_lib.__file__).resolve().parents[1]


def register(dataset_params: Path, width: int, height: int) -> None:
    """The registration docs/datasets.md gives: the objects and an image size for ``dockfactory``."""
    s = dataset_params.read_text()
    s = s.replace("    obj_ids = {\n", '    obj_ids = {\n        "dockfactory": [1, 2],\n', 1)
    s = s.replace("    symmetric_obj_ids = {\n", '    symmetric_obj_ids = {\n        "dockfactory": [],\n', 1)
    s = re.sub(r"(\n    else:\n        raise ValueError\(\"Unknown BOP dataset)",
               f'\n    elif dataset_name == "dockfactory":\n        p["scene_ids"] = [0]\n'
               f'        p["im_size"] = ({width}, {height})\n\\1', s, count=1)
    if s.count('"dockfactory"') != 3:
        raise SystemExit(f"{dataset_params}: the registration anchors were not found")
    dataset_params.write_text(s)


def calc_gt_info(script: Path, split: str) -> None:
    """Run calc_gt_info.py with its parameter block set to the dockfactory split."""
    text = script.read_text()
    for key, value in (("dataset", '"dockfactory"'), ("dataset_split", f'"{split}"'), ("modality", "None"),
                       ("sensor", "None"), ("renderer_type", '"vispy"'), ("delta", "15")):
        text, n = re.subn(rf'("{key}":\s*)([^,\n]+)(,)', rf"\g<1>{value}\3", text, count=1)
        if n != 1:
            raise SystemExit(f"{script}: no '{key}' in its parameter block")
    patched = script.with_name(f"calc_gt_info_{split}.py")
    patched.write_text(text)
    runpy.run_path(str(patched), run_name="__main__")


def masks_vs_render(data: Path, width: int, height: int) -> dict:
    """{split: {im: [[render only, mask only] per gt]}}: bop_toolkit's depth render of each model
    in its pose (cam_K as given) against the export's full masks."""
    from bop_toolkit_lib import inout
    from bop_toolkit_lib.rendering import renderer
    ren = renderer.create_renderer(width, height, "vispy", mode="depth")
    for obj_id in (1, 2):
        ren.add_object(obj_id, str(data / "models" / f"obj_{obj_id:06d}.ply"))
    out = {}
    for scene in sorted(data.glob("*/000000/scene_gt.json")):
        cams, gts = inout.load_scene_camera(str(scene.with_name("scene_camera.json"))), inout.load_scene_gt(str(scene))
        rows = out.setdefault(scene.parents[1].name, {})
        for im, gt_list in gts.items():
            k = cams[im]["cam_K"]
            rows[im] = []
            for gt_id, gt in enumerate(gt_list):
                depth = ren.render_object(gt["obj_id"], gt["cam_R_m2c"], gt["cam_t_m2c"], k[0, 0], k[1, 1], k[0, 2],
                                          k[1, 2])["depth"]
                mask = inout.load_im(str(scene.parent / "mask" / f"{im:06d}_{gt_id:06d}.png")) > 0
                rows[im].append([int((depth > 0)[~mask].sum()), int(mask[depth <= 0].sum())])
    return out


def vis_poses(kit: Path, work: Path) -> list[str] | None:
    """Run vis_poses.py (GT mode) on the test split; the names of the images it wrote, or None
    when trimesh or tqdm is missing."""
    try:
        import tqdm  # noqa: F401
        import trimesh  # noqa: F401
    except ImportError:
        return None
    out = work / "vis"
    argv = sys.argv
    sys.argv = ["vis_poses.py", "gt", "--dataset", "dockfactory", "--dataset_split", "test", "--vis_path", str(out)]
    sys.path.insert(0, str(kit / "scripts"))
    try:
        runpy.run_path(str(kit / "scripts" / "vis_poses.py"), run_name="__main__")
    finally:
        sys.argv = argv
    return sorted(p.name for p in out.rglob("*.jpg"))


RENDERER_MISSING = 3   # exit status: bop_toolkit is there, its renderer's packages are not


def main(export: str, work_dir: str, width: str, height: str) -> None:
    work = Path(work_dir)
    src = toolkit_source()
    try:
        import OpenGL  # noqa: F401
        import vispy  # noqa: F401
    except ImportError as exc:
        print(f"bop_toolkit's vispy renderer cannot run: {exc}", file=sys.stderr)
        raise SystemExit(RENDERER_MISSING) from None
    kit = work / "toolkit"
    shutil.copytree(src / "bop_toolkit_lib", kit / "bop_toolkit_lib")
    shutil.copytree(src / "scripts", kit / "scripts")
    register(kit / "bop_toolkit_lib" / "dataset_params.py", int(width), int(height))
    data = work / "datasets" / "dockfactory"
    shutil.copytree(export, data)
    os.environ.update(BOP_PATH=str(work / "datasets"), EGL_PLATFORM="surfaceless", PYOPENGL_PLATFORM="egl")
    sys.path.insert(0, str(kit))
    out = {}
    for split in SPLITS:
        if (data / split).is_dir():
            calc_gt_info(kit / "scripts" / "calc_gt_info.py", split)
            out[split] = json.loads((data / split / "000000" / "scene_gt_info.json").read_text())
    masks = masks_vs_render(data, int(width), int(height))
    vis = vis_poses(kit, work) if (data / "test").is_dir() else None
    print(json.dumps({"source": str(src), "gt_info": out, "masks": masks, "vis_poses": vis}))


if __name__ == "__main__":
    main(*sys.argv[1:5])
