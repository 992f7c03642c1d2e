"""Channel/spatial attention blocks compared in the paper's ablation.

Each maps ``x: (B, C, H, W) float32`` to a tensor of the same shape. The model inserts the
chosen block after the last backbone C3, before SPPF (see ``detector.model``).
Blocks: ``se`` (Squeeze-and-Excitation), ``eca`` (Efficient Channel Attention), ``cbam``, ``a2`` (double
attention), ``none`` (identity).

Why and how: docs/detector.md, "Attention blocks".
"""
from __future__ import annotations

import math

import torch
from torch import nn

ATTENTIONS = ("none", "se", "eca", "cbam", "a2")


class SE(nn.Module):
    def __init__(self, c: int, reduction: int = 16):
        super().__init__()
        hidden = max(c // reduction, 1)
        self.fc = nn.Sequential(nn.Linear(c, hidden, bias=False), nn.ReLU(inplace=True),
                                nn.Linear(hidden, c, bias=False), nn.Sigmoid())

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        w = self.fc(x.mean(dim=(2, 3)))
        return x * w[:, :, None, None]


def eca_kernel_size(c: int, gamma: float = 2.0, b: float = 1.0) -> int:
    t = int(abs((math.log2(c) + b) / gamma))
    return t if t % 2 else t + 1


class ECA(nn.Module):
    def __init__(self, c: int):
        super().__init__()
        k = eca_kernel_size(c)
        self.conv = nn.Conv1d(1, 1, kernel_size=k, padding=k // 2, bias=False)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        y = x.mean(dim=(2, 3))[:, None, :]           # (B, 1, C)
        w = torch.sigmoid(self.conv(y))[:, 0]         # (B, C)
        return x * w[:, :, None, None]


class CBAM(nn.Module):
    def __init__(self, c: int, reduction: int = 16, kernel: int = 7):
        super().__init__()
        hidden = max(c // reduction, 1)
        self.mlp = nn.Sequential(nn.Conv2d(c, hidden, 1, bias=False), nn.ReLU(inplace=True),
                                 nn.Conv2d(hidden, c, 1, bias=False))
        self.spatial = nn.Conv2d(2, 1, kernel, padding=kernel // 2, bias=False)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        avg = self.mlp(x.mean(dim=(2, 3), keepdim=True))
        mx = self.mlp(x.amax(dim=(2, 3), keepdim=True))
        x = x * torch.sigmoid(avg + mx)
        s = torch.cat((x.mean(dim=1, keepdim=True), x.amax(dim=1, keepdim=True)), 1)
        return x * torch.sigmoid(self.spatial(s))


class DoubleAttention(nn.Module):
    """A^2 block with c_m = c_n = C / 4 (at least 8), residual output."""

    def __init__(self, c: int, c_m: int | None = None, c_n: int | None = None):
        super().__init__()
        self.c_m = c_m or max(c // 4, 8)
        self.c_n = c_n or max(c // 4, 8)
        self.conv_a = nn.Conv2d(c, self.c_m, 1)
        self.conv_b = nn.Conv2d(c, self.c_n, 1)
        self.conv_v = nn.Conv2d(c, self.c_n, 1)
        self.proj = nn.Conv2d(self.c_m, c, 1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        b, c, h, w = x.shape
        a = self.conv_a(x).reshape(b, self.c_m, h * w)                            # (B, m, N)
        att_maps = torch.softmax(self.conv_b(x).reshape(b, self.c_n, h * w), dim=-1)  # over space
        att_vecs = torch.softmax(self.conv_v(x).reshape(b, self.c_n, h * w), dim=1)   # over c_n
        g = torch.bmm(a, att_maps.transpose(1, 2))                                # (B, m, n)
        z = torch.bmm(g, att_vecs).reshape(b, self.c_m, h, w)                     # (B, m, H, W)
        return x + self.proj(z)


def make_attention(name: str, c: int) -> nn.Module:
    """The attention block ``name`` (one of ATTENTIONS) for ``c`` channels."""
    if name == "none":
        return nn.Identity()
    if name == "se":
        return SE(c)
    if name == "eca":
        return ECA(c)
    if name == "cbam":
        return CBAM(c)
    if name == "a2":
        return DoubleAttention(c)
    raise ValueError(f"attention must be one of {', '.join(ATTENTIONS)}, got {name!r}")
