"""The dataset card: ``README.md`` at the dataset's root, Hugging Face style (YAML front matter,
then a body generated from the dataset's identity), and the ``hf/`` view it points at
(``generator.datasets.hf_view``).

The card and the view are derived, like ``exports/``: they are not in the manifest (``dataset
verify`` neither needs nor checks them; a dataset rendered before cards existed stays valid),
they are written when a dataset completes and again by ``dockfactory dataset card DIR``, and a
file whose bytes would not change is not rewritten (a DVC-tracked dataset stays clean).

Why and how: docs/datasets.md, "The dataset card's content".
"""
from __future__ import annotations

import json
from collections import Counter
from pathlib import Path

from dockfactory.core.io import write_text_atomic
from dockfactory.core.layout import CLASS_NAMES
from dockfactory.core.names import SPLITS
from dockfactory.generator.datasets.folder import CONVENTIONS
from dockfactory.generator.datasets.reader import Dataset
from dockfactory.generator.datasets.hf_view import HF_DIR, HF_FEATURES, HF_SPLIT_NAMES, write_hf_view

CARD_NAME = "README.md"
SIZE_BUCKETS = ((1_000, "n<1K"), (10_000, "1K<n<10K"), (100_000, "10K<n<100K"), (1_000_000, "100K<n<1M"))
TAGS = ("synthetic", "dockfactory", "blender", "pose-estimation", "camera-calibration")


def size_category(frames: int) -> str:
    """The hub's ``size_categories`` bucket of ``frames`` examples."""
    return next((name for limit, name in SIZE_BUCKETS if frames < limit), "1M<n<10M")


def feature_schema(spec):
    """One feature of hf_view.HF_FEATURES as datasets' card schema writes it (the value beside
    ``dtype``, ``list``, ``struct`` or ``class_label``): (key, value)."""
    if isinstance(spec, str):
        return "dtype", spec
    kind, body = spec
    if kind == "struct":
        return "struct", [{"name": k, **dict([feature_schema(v)])} for k, v in body]
    if kind == "class_label":
        return "class_label", {"names": {str(i): n for i, n in enumerate(body)}}
    key, value = feature_schema(body)
    return "list", (value if key == "dtype" else {key: value})


def front_matter(ds: Dataset, license_id: str, counts: dict[str, int]) -> str:
    """The YAML front matter (between ``---`` lines); strings JSON-quoted (valid YAML)."""
    q = json.dumps
    pretty = f"dockfactory {ds.identity['name']} ({ds.version_id})"
    lines = ["---", f"license: {q(license_id)}", f"pretty_name: {q(pretty)}",
             "task_categories:", "- object-detection", "- keypoint-detection",
             "tags:", *[f"- {t}" for t in TAGS],
             "size_categories:", f"- {q(size_category(sum(counts.values())))}",
             "annotations_creators:", "- machine-generated", "source_datasets:", "- original",
             "configs:", "- config_name: default", "  data_files:"]
    for split in SPLITS:
        if counts.get(split):
            lines += [f"  - split: {HF_SPLIT_NAMES[split]}", f"    path: {q(f'{HF_DIR}/{split}/**')}"]
    # the config's features (datasets reads them into imagefolder's config; JSON flow mappings are
    # valid YAML): what imagefolder would infer, objects.category a ClassLabel
    lines += ["  features:"] + [f"  - {q({'name': k, **dict([feature_schema(v)])})}" for k, v in HF_FEATURES]
    return "\n".join(lines + ["---"]) + "\n"


def _split_table(ds: Dataset) -> list[str]:
    by = Counter((s.split, s.condition) for s in ds.plan)
    conds = sorted({c for _, c in by})
    rows = ["| split (hub name) | frames | " + " | ".join(conds) + " |", "|---" * (len(conds) + 2) + "|"]
    for split in SPLITS:
        n = sum(v for (sp, _), v in by.items() if sp == split)
        rows.append(f"| {split} ({HF_SPLIT_NAMES[split]}) | {n} | " + " | ".join(str(by[(split, c)]) for c in conds) + " |")
    return rows


def _config_summary(c) -> list[str]:
    """A few lines on the resolved config ``c`` (core.config.Config)."""
    weights = {k: v for k, v in vars(c.conditions).items() if v}
    return [
        f"- images {c.image.width} x {c.image.height} px; {c.dataset.frames} main frames "
        f"(train fraction {c.dataset.train_fraction}, val fraction {c.dataset.val_fraction}), "
        f"repeatability {c.repeatability.poses} poses x {c.repeatability.captures} captures",
        f"- condition weights: {', '.join(f'{k} {v:g}' for k, v in weights.items())}",
        f"- camera: distance {list(c.camera.distance_mm)} mm, focal {list(c.camera.focal_px)} px, "
        f"{c.camera_units.count} camera unit(s), JPEG {'on' if c.camera_units.jpeg else 'off'}",
        f"- sections: radius {c.sections.radius_mm} mm; markers: {c.markers.diameter_mm} mm discs, "
        f"{len(c.markers.layout_a)} on A (red), {len(c.markers.layout_b)} on B (blue)",
        f"- sensor: {', '.join(c.sensor.presets) or 'the generic noise model'}; CFA {', '.join(c.sensor.cfa)}; "
        f"motion {'on' if c.motion.enabled else 'off'}; Cycles {c.render.samples} samples",
        "- the resolved config is `dataset.json` (`config`); the config as given is `config.toml`",
    ]


def _camera_rows(ds: Dataset) -> list[str]:
    """One row per camera unit: frames, focal range, lens (from the labels), sensor (the config's
    per-unit lists: unit u takes item u % len)."""
    units: dict[int, list[dict]] = {}
    for label in ds.labels_of():
        units.setdefault(int(label["camera"].get("unit", 0)), []).append(label["camera"])
    sensor = ds.config.sensor
    rows = ["| unit | frames | focal (px) | principal point (px) | distortion k1, k2, p1, p2, k3 | JPEG quality "
            "| sensor | CFA |", "|---|---|---|---|---|---|---|---|"]
    for unit, cams in sorted(units.items()):
        f = [c["focal_px"] for c in cams]
        pp = ", ".join(f"{v:.2f}" for v in cams[0]["principal_point"])
        dist = ", ".join(f"{v:.4g}" for v in cams[0].get("distortion", []))
        preset = sensor.presets[unit % len(sensor.presets)] if sensor.presets else "generic noise model"
        rows.append(f"| {unit} | {len(cams)} | {min(f):.1f} .. {max(f):.1f} | ({pp}) | {dist} | "
                    f"{cams[0].get('jpeg_quality') or 'none'} | {preset} | {sensor.cfa[unit % len(sensor.cfa)]} |")
    return rows


def _conventions() -> list[str]:
    return [f"- {k}: {v if isinstance(v, str) else json.dumps(v)}" for k, v in CONVENTIONS.items()] + [
        "- `hf/<split>/metadata.jsonl` (one line per frame): `objects.bbox` is [x, y, w, h] in continuous "
        "coordinates (COCO's: the label's `bbox_px` + 0.5); `objects.center_px` is the label's, in the "
        "OpenCV convention above; `category` 0 is "
        f"{CLASS_NAMES[0]}, 1 is {CLASS_NAMES[1]}; `label_file` is the full label (every field: "
        "`docs/datasets.md` of dockfactory), `label_sha256` its manifest sha256",
    ]


def body(ds: Dataset, license_id: str, counts: dict[str, int]) -> str:
    """The card's Markdown body (module docstring)."""
    ident, m = ds.identity, ds.manifest
    source = ("the config's `[dataset] license`" if license_id == ds.config.dataset.license
              else "given to `dockfactory dataset card --license`")
    size_mb = sum(f["bytes"] for f in m["files"]) / 1e6
    lines = [f"# dockfactory dataset `{ident['name']}`", "",
             "Synthetic images of two cylindrical sections (A fixed, B mobile) with coloured markers near their "
             "seam, rendered by dockfactory with Blender/Cycles, with exact labels: camera, relative pose of B "
             "in A's docking frame, and every marker's projected centre, box and visibility.", "",
             "| | |", "|---|---|", f"| version id | `{ds.version_id}` |",
             f"| generator | dockfactory {ident['generator_version']} |", f"| Blender | {ident['blender_version']} |",
             f"| seed | {ident['seed']} |", f"| frames | {len(ds.plan)} |",
             f"| size | {size_mb:.1f} MB in {len(m['files'])} files (the manifest's content) |",
             f"| licence | `{license_id}` |", "",
             "## Splits and conditions", "", *_split_table(ds), "",
             "## Config", "", *_config_summary(ds.config), "",
             "## Camera units", "", *_camera_rows(ds), "",
             "## Label conventions", "", *_conventions(), "",
             "## Loading", "", "```python", "from datasets import load_dataset",
             "ds = load_dataset(\"PATH/TO/THIS/FOLDER\")   # every split, from this card's configs",
             "ds = load_dataset(\"imagefolder\", data_dir=\"PATH/TO/THIS/FOLDER\", data_files="
             + json.dumps({HF_SPLIT_NAMES[s]: f"{HF_DIR}/{s}/**" for s in SPLITS if counts.get(s)}) + ")",
             "```", "",
             "## Verifying", "",
             "`manifest.json` lists every file of the content with its size and sha256. `dockfactory dataset "
             "verify DIR` checks every byte against it (this card and `hf/` are derived, outside the manifest: "
             "`dockfactory dataset card DIR` writes them again); `dockfactory dataset verify DIR --manifest "
             "PUBLISHED/manifest.json` checks a re-render against a published dataset.", "",
             "## Licence", "",
             f"The data: `{license_id}` ({source}). dockfactory itself is GPL-3.0-or-later; "
             "the images and labels it renders are its output, not a copy of it, and carry the data's licence.", ""]
    return "\n".join(lines)


def card_text(ds: Dataset, license_id: str | None = None, counts: dict[str, int] | None = None) -> str:
    """README.md of the complete dataset ``ds``; ``license_id`` overrides the config's."""
    license_id = license_id or ds.config.dataset.license
    counts = counts if counts is not None else {s: len(ds.frames(s)) for s in SPLITS if ds.frames(s)}
    return front_matter(ds, license_id, counts) + "\n" + body(ds, license_id, counts)


def write_card(ds: Dataset, license_id: str | None = None) -> Path:
    """Write the Hugging Face view ``hf/`` and the card ``README.md`` of the complete dataset ``ds``.

    Each is left untouched when its bytes would not change (a DVC-tracked dataset stays clean); both are derived
    files, outside the manifest (module docstring).

    Parameters
    ----------
    ds : Dataset
        The complete, checked dataset (``Dataset.open``); its labels are read (each checked against the manifest).
    license_id : str, optional
        The data's licence identifier written into the card; None: the config's ``[dataset] license``.

    Returns
    -------
    Path
        The card, ``ds.root / "README.md"``.

    Raises
    ------
    DatasetError
        ``hf/`` or an image is a symlink (not a DVC cache link), or a label changed since the dataset was finished
        (its sha256 is not the manifest's).
    OSError
        The dataset folder cannot be written.
    """
    counts = write_hf_view(ds)
    path = ds.root / CARD_NAME
    text = card_text(ds, license_id, counts)
    try:
        same = path.read_text(encoding="utf-8") == text
    except (OSError, UnicodeDecodeError):
        same = False
    if not same:
        write_text_atomic(path, text)   # replaces a DVC link by a file, never writes through it
    return path
