"""Training data from an opened dockfactory dataset: crops around the seam plus background crops.

The network sees images at ``input_scale`` (0.5: a 1280 x 960 frame is seen at 640 x 480, markers
6-25 px). Training uses ``crop x crop`` windows of the scaled frame: most are centred near a
marker (the seam, where all markers are), a fraction are background windows chosen away from
every marker (clutter, flanges, occluders, glare). Inference runs on the whole scaled frame.

Coordinates: labels are in the OpenCV convention (pixel centres at integers); the network works
in corner coordinates (``opencv + 0.5``) scaled by ``input_scale``, where resizing is exact.

Why and how: docs/detector.md, "Training data".
"""
from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Protocol

from dockfactory.core.cv import cv2
import numpy as np
import torch

from dockfactory.core.errors import DockfactoryError


@dataclass(frozen=True)
class DataConfig:
    input_scale: float = 0.5            # network px per image px
    crop: int = 256                     # training window (network px), multiple of 32
    crops_per_frame: int = 2            # windows per training frame per epoch
    background_fraction: float = 0.2    # share of windows chosen away from the markers
    min_visible_fraction: float = 0.3   # markers hidden more than this are not targets
    min_inside_fraction: float = 0.5    # a marker cut by the window edge stays a target above this
    augment: bool = True
    scale_range: tuple[float, float] = (0.8, 1.25)
    rotate_deg: float = 10.0
    flip_lr: float = 0.5
    gamma_range: tuple[float, float] = (0.7, 1.6)
    contrast_range: tuple[float, float] = (0.7, 1.2)
    brightness: float = 0.08            # additive, +-
    blur_prob: float = 0.3
    blur_sigma: tuple[float, float] = (0.3, 1.0)
    noise_std: tuple[float, float] = (0.0, 0.04)

    def __post_init__(self):
        if not 0 < self.input_scale <= 1:
            raise DockfactoryError(f"input_scale must be in (0, 1], got {self.input_scale}")
        if self.crop < 32 or self.crop % 32:
            raise DockfactoryError(f"crop must be a positive multiple of 32, got {self.crop}")
        if self.crops_per_frame < 1:
            raise DockfactoryError(f"crops_per_frame must be >= 1, got {self.crops_per_frame}")
        if not 0 <= self.background_fraction <= 1:
            raise DockfactoryError(f"background_fraction must be in [0, 1], got {self.background_fraction}")

    def to_dict(self) -> dict:
        return json.loads(json.dumps(asdict(self)))

    @classmethod
    def from_dict(cls, d: dict) -> "DataConfig":
        unknown = set(d) - set(cls.__dataclass_fields__)
        if unknown:
            raise DockfactoryError(f"unknown data config keys: {sorted(unknown)}")
        return cls(**{k: tuple(v) if isinstance(v, list) else v for k, v in d.items()})


@dataclass(frozen=True)
class Frame:
    """One labelled frame. ``boxes: (M, 4) float64`` [x0, y0, x1, y1] OpenCV px (``training_box``),
    ``classes: (M,) int64``, ``centers: (M, 2) float64`` px, ``visible: (M,) float64`` fraction."""
    frame_id: str
    image_path: str
    condition: str
    width: int
    height: int
    boxes: np.ndarray
    classes: np.ndarray
    centers: np.ndarray
    visible: np.ndarray


class FrameSource(Protocol):
    """What the detector reads from a dataset: an opened dockfactory dataset
    (``generator.datasets.reader.Dataset``, the one contract every consumer goes through; the eval
    layer opens it) or, in tests, ``detector.synthetic.SyntheticDataset``."""
    root: Path

    @property
    def version_id(self) -> str: ...

    def labels_of(self, split: str | None = None) -> list[dict]: ...


def training_box(marker: dict) -> list[float]:
    """The box a marker's label gives the network to learn, px (OpenCV convention): the marker's
    outline box ``bbox_px`` (geometry, within the image), or for a marker of B that moved during
    the exposure ``bbox_swept_px``, the box its outline sweeps over the exposure: the image holds
    the smear, not the outline at mid-exposure (which ``bbox_px`` is)."""
    swept = marker.get("bbox_swept_px")
    return marker["bbox_px"] if swept is None else swept


def frame_from_label(root, label: dict) -> Frame:
    """The :class:`Frame` of one label: its markers that show any pixel and have a box."""
    ms = [m for m in label["markers"] if m.get("visible_pixels") and m.get("bbox_px") is not None]
    return Frame(
        frame_id=label["frame_id"], image_path=str(Path(root) / "images" / f"{label['frame_id']}.png"),
        condition=label["spec"]["condition"], width=int(label["image"]["width"]),
        height=int(label["image"]["height"]),
        boxes=np.array([training_box(m) for m in ms], dtype=np.float64).reshape(-1, 4),
        classes=np.array([m["class_id"] for m in ms], dtype=np.int64),
        centers=np.array([m["center_px"] for m in ms], dtype=np.float64).reshape(-1, 2),
        visible=np.array([m["visible_fraction"] for m in ms], dtype=np.float64))


def load_frames(source: FrameSource, split: str | None) -> list[Frame]:
    """Frames of ``split`` ('train', 'test', 'repeat' or None for all) of an opened dataset, in
    plan order."""
    frames = [frame_from_label(source.root, lab) for lab in source.labels_of(split)]
    if not frames:
        raise DockfactoryError(f"{source.root}: no frames in split {split!r}")
    return frames


def read_rgb(path) -> np.ndarray:
    """``(H, W, 3) uint8`` RGB image."""
    bgr = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if bgr is None:
        raise DockfactoryError(f"cannot read image {path}")
    return cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)


def scaled_size(width: int, height: int, scale: float) -> tuple[int, int]:
    return max(1, round(width * scale)), max(1, round(height * scale))


def resize_exact(img: np.ndarray, scale: float) -> tuple[np.ndarray, float, float]:
    """Resize by ``scale``; returns the image and the exact x/y factors (new size / old size).

    A point at corner coordinate u maps to u * factor (cv2.resize aligns image corners).
    """
    h, w = img.shape[:2]
    nw, nh = scaled_size(w, h, scale)
    if (nw, nh) == (w, h):
        return img, 1.0, 1.0
    interp = cv2.INTER_AREA if scale < 1 else cv2.INTER_LINEAR
    return cv2.resize(img, (nw, nh), interpolation=interp), nw / w, nh / h


def _seed_int(*parts: int) -> int:
    return int(np.random.SeedSequence([int(p) for p in parts]).generate_state(1, dtype=np.uint64)[0]) >> 1


class CropDataset:
    """Seeded crops of the scaled frames of a split; images are cached in memory once read.

    ``batch(epoch, index, batch_size) -> (images (B, 3, S, S) float32 in [0, 1],
    targets (M, 6) float32 [image, class, cx, cy, w, h] network px)``. The content of a batch is
    a function of (seed, epoch, index, batch_size) alone, so a resumed run sees the same data.
    """

    def __init__(self, frames: list[Frame], cfg: DataConfig = DataConfig(), seed: int = 0):
        if not frames:
            raise ValueError("CropDataset needs at least one frame")
        self.frames, self.cfg, self.seed = list(frames), cfg, int(seed)
        self._cache: dict[int, tuple[np.ndarray, float, float]] = {}

    def __len__(self) -> int:
        return len(self.frames) * self.cfg.crops_per_frame

    def batches_per_epoch(self, batch_size: int) -> int:
        return math.ceil(len(self) / batch_size)

    def scaled(self, i: int) -> tuple[np.ndarray, float, float]:
        if i not in self._cache:
            img = read_rgb(self.frames[i].image_path)
            self._cache[i] = resize_exact(img, self.cfg.input_scale)
        return self._cache[i]

    def _order(self, epoch: int) -> np.ndarray:
        rng = np.random.default_rng(_seed_int(self.seed, epoch, 101))
        return rng.permutation(np.repeat(np.arange(len(self.frames)), self.cfg.crops_per_frame))

    def batch(self, epoch: int, index: int, batch_size: int):
        order = self._order(epoch)
        items = order[index * batch_size:(index + 1) * batch_size]
        if len(items) == 0:
            raise ValueError(f"batch {index} is past the end of epoch {epoch}")
        crops, targets = [], []
        for j, fi in enumerate(items):
            rng = np.random.default_rng(_seed_int(self.seed, epoch, index * batch_size + j, 202))
            img, boxes, classes = self._window(int(fi), rng)
            crops.append(img)
            targets.append((boxes, classes))
        gen = torch.Generator().manual_seed(_seed_int(self.seed, epoch, index, 303))
        return self._assemble(crops, targets, gen)

    # --------------------------------------------------------------------------- windows

    def _network_boxes(self, fi: int, sx: float, sy: float):
        f = self.frames[fi]
        keep = f.visible >= self.cfg.min_visible_fraction
        b = (f.boxes[keep] + 0.5) * np.array([sx, sy, sx, sy])
        return b, f.classes[keep]

    def _window(self, fi: int, rng: np.random.Generator):
        """A (big) window around the seam or the background: the image ``(R, R, 3) uint8`` with
        R = ceil(1.5 S) and its boxes ``(K, 4)`` network px relative to it, classes ``(K,)``."""
        cfg = self.cfg
        img, sx, sy = self.scaled(fi)
        h, w = img.shape[:2]
        boxes, classes = self._network_boxes(fi, sx, sy)
        big = cfg.crop if not cfg.augment else int(math.ceil(cfg.crop * 1.5))
        centres = (boxes[:, :2] + boxes[:, 2:]) / 2
        background = len(boxes) == 0 or rng.random() < cfg.background_fraction
        if background:
            for _ in range(20):
                c = rng.uniform([0, 0], [w, h])
                x0, y0 = c - cfg.crop / 2
                inside = ((boxes[:, 2] > x0) & (boxes[:, 0] < x0 + cfg.crop) &
                          (boxes[:, 3] > y0) & (boxes[:, 1] < y0 + cfg.crop))
                if not inside.any():
                    break
        else:
            c = centres[rng.integers(len(centres))] + rng.uniform(-0.35, 0.35, 2) * cfg.crop
        c = np.clip(c, [min(cfg.crop / 2, w / 2), min(cfg.crop / 2, h / 2)],
                    [max(w - cfg.crop / 2, w / 2), max(h - cfg.crop / 2, h / 2)])
        ox, oy = int(round(c[0] - big / 2)), int(round(c[1] - big / 2))
        pad = ((max(0, -oy), max(0, oy + big - h)), (max(0, -ox), max(0, ox + big - w)), (0, 0))
        window = np.pad(img, pad, mode="constant", constant_values=114)
        window = window[oy + pad[0][0]:oy + pad[0][0] + big, ox + pad[1][0]:ox + pad[1][0] + big]
        return window, boxes - np.array([ox, oy, ox, oy]), classes

    def _assemble(self, windows, targets, gen: torch.Generator):
        cfg = self.cfg
        s = cfg.crop
        x = torch.from_numpy(np.stack(windows)).permute(0, 3, 1, 2).float() / 255.0
        b = x.shape[0]
        big = x.shape[-1]
        a = torch.eye(2).repeat(b, 1, 1)
        if cfg.augment:
            scale = torch.empty(b).uniform_(*cfg.scale_range, generator=gen)
            ang = torch.empty(b).uniform_(-cfg.rotate_deg, cfg.rotate_deg, generator=gen) * math.pi / 180
            flip = torch.rand(b, generator=gen) < cfg.flip_lr
            cos, sin = torch.cos(ang), torch.sin(ang)
            a = torch.stack((torch.stack((cos, -sin), -1), torch.stack((sin, cos), -1)), -2) * scale[:, None, None]
            a = a @ torch.diag_embed(torch.stack((torch.where(flip, -1.0, 1.0), torch.ones(b)), -1))
        a = a.double()
        # corner coordinates: p_out = A (p_in - c_in) + c_out; kornia works on pixel-centre indices
        c_in, c_out = big / 2, s / 2
        t = (c_out - 0.5) - a @ torch.full((b, 2, 1), c_in - 0.5, dtype=torch.float64)
        m = torch.cat((a, t), 2)
        if cfg.augment or big != s:
            from kornia.geometry.transform import warp_affine
            x = warp_affine(x, m.float(), (s, s), mode="bilinear", padding_mode="border", align_corners=True)
        rows = []
        for i, (boxes, classes) in enumerate(targets):
            if len(boxes) == 0:
                continue
            ctr = torch.from_numpy((boxes[:, :2] + boxes[:, 2:]) / 2)
            half = torch.from_numpy((boxes[:, 2:] - boxes[:, :2]) / 2)
            new_c = (a[i] @ (ctr - c_in).T).T + c_out
            # the marker as an axis-aligned ellipse inscribed in its box, mapped by A
            cov = a[i] @ torch.diag_embed(half ** 2) @ a[i].T             # (K, 2, 2)
            new_half = torch.sqrt(torch.diagonal(cov, dim1=-2, dim2=-1))
            x0y0, x1y1 = new_c - new_half, new_c + new_half
            area = (x1y1 - x0y0).prod(1)
            cx0y0, cx1y1 = x0y0.clamp(0, s), x1y1.clamp(0, s)
            inside = (cx1y1 - cx0y0).clamp(min=0).prod(1) / area.clamp(min=1e-9)
            ok = inside >= cfg.min_inside_fraction
            if ok.any():
                bb = torch.cat((cx0y0[ok], cx1y1[ok]), 1)
                cls = torch.from_numpy(classes)[ok].double()
                rows.append(torch.cat((torch.full((len(bb), 1), float(i), dtype=torch.float64), cls[:, None],
                                       (bb[:, :2] + bb[:, 2:]) / 2, bb[:, 2:] - bb[:, :2]), 1))
        tgt = torch.cat(rows).float() if rows else torch.zeros((0, 6))
        if cfg.augment:
            x = photometric(x, cfg, gen)
        return x.contiguous(), tgt


def photometric(x: torch.Tensor, cfg: DataConfig, gen: torch.Generator) -> torch.Tensor:
    """Gamma, contrast, brightness, blur and noise on ``x: (B, 3, H, W)`` in [0, 1]."""
    from kornia.enhance import adjust_brightness, adjust_contrast, adjust_gamma
    from kornia.filters import gaussian_blur2d
    b = x.shape[0]
    gamma = torch.exp(torch.empty(b).uniform_(math.log(cfg.gamma_range[0]), math.log(cfg.gamma_range[1]), generator=gen))
    contrast = torch.empty(b).uniform_(*cfg.contrast_range, generator=gen)
    bright = torch.empty(b).uniform_(-cfg.brightness, cfg.brightness, generator=gen)
    blur = torch.rand(b, generator=gen) < cfg.blur_prob
    sigma = torch.empty(b).uniform_(*cfg.blur_sigma, generator=gen)
    noise = torch.empty(b).uniform_(*cfg.noise_std, generator=gen)
    eps = torch.randn(x.shape, generator=gen)
    x = adjust_gamma(x, gamma)
    x = adjust_contrast(x, contrast)
    x = adjust_brightness(x, bright)
    if blur.any():
        sig = torch.stack((sigma[blur], sigma[blur]), -1)
        x[blur] = gaussian_blur2d(x[blur], (5, 5), sig)
    x = x + eps * noise[:, None, None, None]
    return x.clamp(0, 1)
