"""YOLOv5 v6/v7 detector (scales n and s) with an optional attention block and P2 head.

Box decoding (YOLOv5 v6/v7): ``xy = (2 sigmoid(t_xy) - 0.5 + grid) * stride``,
``wh = (2 sigmoid(t_wh))^2 * anchor``. Coordinates of the network are continuous pixel
coordinates of its input with (0, 0) at the top-left *corner* of the top-left pixel (the
conversion from/to the OpenCV convention lives in ``detector.infer``).

With ``p2=True`` a fourth output at stride 4 is added: the P3 output is reduced (1x1 Conv),
upsampled, concatenated with the stride-4 backbone feature and passed through a C3.

Why and how: docs/detector.md, "The network".
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import torch
from torch import nn

from dockfactory.core.names import CLASS_NAMES  # noqa: F401  (re-exported)
from dockfactory.detector.attention import ATTENTIONS, make_attention
from dockfactory.detector.blocks import C3, SPPF, Conv, fuse_conv_bn

SCALES = {"n": (0.33, 0.25), "s": (0.33, 0.50)}  # depth multiple, width multiple
# YOLOv5's COCO anchors (P3, P4, P5), px at the network input; replaced by k-means anchors.
DEFAULT_ANCHORS = (((10, 13), (16, 30), (33, 23)), ((30, 61), (62, 45), (59, 119)),
                   ((116, 90), (156, 198), (373, 326)))
DEFAULT_ANCHORS_P2 = (((5, 6), (8, 14), (15, 11)),) + DEFAULT_ANCHORS


MAX_CLASSES = 1000   # a head beyond this is no marker detector (and would take gigabytes)


@dataclass(frozen=True)
class ModelConfig:
    """What defines the network. ``anchors``: per level 3 (w, h) pairs in input px."""
    scale: str = "n"
    attention: str = "se"
    num_classes: int = 2
    p2: bool = False
    anchors: tuple = DEFAULT_ANCHORS

    def __post_init__(self):
        if self.scale not in SCALES:
            raise ValueError(f"model scale must be one of {', '.join(SCALES)}, got {self.scale!r}")
        if self.attention not in ATTENTIONS:
            raise ValueError(f"attention must be one of {', '.join(ATTENTIONS)}, got {self.attention!r}")
        if isinstance(self.num_classes, bool) or not isinstance(self.num_classes, int) \
                or not 1 <= self.num_classes <= MAX_CLASSES:
            raise ValueError(f"num_classes must be an integer in [1, {MAX_CLASSES}], got {self.num_classes!r}")
        levels = 4 if self.p2 else 3
        a = torch.as_tensor(self.anchors, dtype=torch.float64) if self.anchors else None
        if a is None or a.shape != (levels, 3, 2) or not bool((a > 0).all()):
            raise ValueError(f"anchors must be {levels} levels x 3 positive (w, h) pairs, got {self.anchors!r}")
        object.__setattr__(self, "anchors", tuple(tuple((float(w), float(h)) for w, h in lvl)
                                                  for lvl in a.tolist()))

    @property
    def strides(self) -> tuple[int, ...]:
        return (4, 8, 16, 32) if self.p2 else (8, 16, 32)

    def to_dict(self) -> dict:
        d = asdict(self)
        d["anchors"] = [[list(p) for p in lvl] for lvl in self.anchors]
        return d

    @classmethod
    def from_dict(cls, d: dict) -> "ModelConfig":
        unknown = set(d) - {f for f in cls.__dataclass_fields__}
        if unknown:
            raise ValueError(f"unknown model config keys: {sorted(unknown)}")
        d = dict(d)
        if "anchors" in d:
            d["anchors"] = tuple(tuple(tuple(p) for p in lvl) for lvl in d["anchors"])
        return cls(**d)


def make_divisible(x: float, divisor: int = 8) -> int:
    return int(math.ceil(x / divisor) * divisor)


class Detect(nn.Module):
    """Per level a 1x1 conv to na * (5 + nc) channels.

    Training: a list of raw maps ``(B, na, H_i, W_i, 5 + nc)``.
    Eval: ``(B, N, 5 + nc)`` decoded rows ``[cx, cy, w, h, obj, cls...]`` (px, probabilities),
    N = sum(na * H_i * W_i).
    """

    def __init__(self, nc: int, anchors, strides, ch):
        super().__init__()
        self.nc, self.no = nc, nc + 5
        self.nl, self.na = len(strides), len(anchors[0])
        self.register_buffer("stride", torch.tensor(strides, dtype=torch.float32))
        self.register_buffer("anchors", torch.tensor(anchors, dtype=torch.float32))  # (nl, na, 2) px
        self.m = nn.ModuleList(nn.Conv2d(c, self.no * self.na, 1) for c in ch)
        self.export = False  # eval output without the training maps (for ONNX)

    def initialize_biases(self, image_size: int = 640) -> None:
        """YOLOv5's prior: about 8 objects per image_size^2 image, class prior 0.6 / (nc - 0.99)."""
        for conv, s in zip(self.m, self.stride.tolist()):
            b = conv.bias.detach().view(self.na, -1)
            b[:, 4] += math.log(8 / (image_size / s) ** 2)
            b[:, 5:] += math.log(0.6 / (self.nc - 0.99))
            conv.bias.data.copy_(b.view(-1))

    def forward(self, xs: list[torch.Tensor]):
        raw = []
        for i, x in enumerate(xs):
            b, _, h, w = x.shape
            raw.append(self.m[i](x).view(b, self.na, self.no, h, w).permute(0, 1, 3, 4, 2).contiguous())
        if self.training:
            return raw
        return self.decode(raw)

    def decode(self, raw: list[torch.Tensor]) -> torch.Tensor:
        out = []
        for i, p in enumerate(raw):
            b, na, h, w, no = p.shape
            yv, xv = torch.meshgrid(torch.arange(h, dtype=p.dtype, device=p.device),
                                    torch.arange(w, dtype=p.dtype, device=p.device), indexing="ij")
            grid = torch.stack((xv, yv), -1).view(1, 1, h, w, 2)
            anchor = self.anchors[i].to(p.dtype).view(1, na, 1, 1, 2)
            y = p.sigmoid()
            xy = (y[..., :2] * 2 - 0.5 + grid) * self.stride[i]
            wh = (y[..., 2:4] * 2) ** 2 * anchor
            out.append(torch.cat((xy, wh, y[..., 4:]), -1).view(b, -1, no))
        return torch.cat(out, 1)


class YOLOv5(nn.Module):
    """``x: (B, 3, H, W) float32`` in [0, 1], H and W multiples of the largest stride (32)."""

    def __init__(self, cfg: ModelConfig):
        super().__init__()
        self.cfg = cfg
        gd, gw = SCALES[cfg.scale]

        def ch(c):
            return make_divisible(c * gw, 8)

        def dep(n):
            return max(round(n * gd), 1)

        # backbone
        self.b0 = Conv(3, ch(64), 6, 2, 2)            # P1/2
        self.b1 = Conv(ch(64), ch(128), 3, 2)         # P2/4
        self.b2 = C3(ch(128), ch(128), dep(3))
        self.b3 = Conv(ch(128), ch(256), 3, 2)        # P3/8
        self.b4 = C3(ch(256), ch(256), dep(6))
        self.b5 = Conv(ch(256), ch(512), 3, 2)        # P4/16
        self.b6 = C3(ch(512), ch(512), dep(9))
        self.b7 = Conv(ch(512), ch(1024), 3, 2)       # P5/32
        self.b8 = C3(ch(1024), ch(1024), dep(3))
        self.attn = make_attention(cfg.attention, ch(1024))
        self.b9 = SPPF(ch(1024), ch(1024), 5)
        # neck (PAN)
        self.up = nn.Upsample(scale_factor=2, mode="nearest")
        self.h10 = Conv(ch(1024), ch(512), 1, 1)
        self.h13 = C3(ch(512) * 2, ch(512), dep(3), shortcut=False)
        self.h14 = Conv(ch(512), ch(256), 1, 1)
        self.h17 = C3(ch(256) * 2, ch(256), dep(3), shortcut=False)   # P3 out
        self.h18 = Conv(ch(256), ch(256), 3, 2)
        self.h20 = C3(ch(256) * 2, ch(512), dep(3), shortcut=False)   # P4 out
        self.h21 = Conv(ch(512), ch(512), 3, 2)
        self.h23 = C3(ch(512) * 2, ch(1024), dep(3), shortcut=False)  # P5 out
        outs = [ch(256), ch(512), ch(1024)]
        if cfg.p2:
            self.p2_reduce = Conv(ch(256), ch(128), 1, 1)
            self.p2_c3 = C3(ch(128) * 2, ch(128), dep(3), shortcut=False)  # P2 out
            outs = [ch(128)] + outs
        self.detect = Detect(cfg.num_classes, cfg.anchors, cfg.strides, outs)
        self.detect.initialize_biases()

    def forward(self, x: torch.Tensor):
        if x.ndim != 4 or x.shape[1] != 3:
            raise ValueError(f"input must be (B, 3, H, W), got {tuple(x.shape)}")
        if x.shape[2] % 32 or x.shape[3] % 32:
            raise ValueError(f"input height and width must be multiples of 32, got {tuple(x.shape[2:])}")
        p2 = self.b2(self.b1(self.b0(x)))
        p3 = self.b4(self.b3(p2))
        p4 = self.b6(self.b5(p3))
        p5 = self.b9(self.attn(self.b8(self.b7(p4))))
        h10 = self.h10(p5)
        h13 = self.h13(torch.cat((self.up(h10), p4), 1))
        h14 = self.h14(h13)
        h17 = self.h17(torch.cat((self.up(h14), p3), 1))
        h20 = self.h20(torch.cat((self.h18(h17), h14), 1))
        h23 = self.h23(torch.cat((self.h21(h20), h10), 1))
        feats = [h17, h20, h23]
        if self.cfg.p2:
            feats = [self.p2_c3(torch.cat((self.up(self.p2_reduce(h17)), p2), 1))] + feats
        return self.detect(feats)

    def fuse(self) -> "YOLOv5":
        """Fold BatchNorm into the convolutions (eval/inference only); returns self."""
        for m in self.modules():
            if isinstance(m, Conv) and hasattr(m, "bn"):
                m.conv = fuse_conv_bn(m.conv, m.bn)
                delattr(m, "bn")
                m.forward = m.forward_fused
        return self


def build_model(cfg: ModelConfig, seed: int = 0) -> YOLOv5:
    """A freshly initialised model; its initial weights depend on ``seed`` only."""
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        return YOLOv5(cfg)


def count_parameters(model: nn.Module) -> int:
    return sum(p.numel() for p in model.parameters())
