"""YOLOv5's loss: target assignment, CIoU box loss, objectness with IoU target, class BCE.

Targets are ``(M, 6) float32`` rows ``[image_index, class_id, cx, cy, w, h]`` in px of the
network input (corner convention, see ``detector.model``).

Assignment (YOLOv5 ``build_targets``): at each level a target goes to every anchor whose width
and height ratios are within ``1/anchor_t .. anchor_t``, in its own grid cell and the two
neighbouring cells closest to its centre (offset 0.5). Loss per level: ``1 - CIoU`` averaged
over assigned cells; objectness BCE against the (detached, clamped) IoU, weighted per level
(4.0, 1.0, 0.4; with P2 4.0, 1.0, 0.25, 0.06); class BCE on assigned cells. Gains box 0.05,
cls 0.5, obj 1.0, scaled as YOLOv5 does (box x 3/nl, cls x nc/80 x 3/nl,
obj x (image_size/640)^2 x 3/nl); the total is multiplied by the batch size.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import torch
from torch import nn


@dataclass(frozen=True)
class LossGains:
    box: float = 0.05
    cls: float = 0.5
    obj: float = 1.0
    anchor_t: float = 4.0


def bbox_ciou(box1: torch.Tensor, box2: torch.Tensor, eps: float = 1e-7) -> torch.Tensor:
    """Complete IoU of ``box1, box2: (N, 4)`` [cx, cy, w, h] row by row -> (N,)."""
    (x1, y1, w1, h1), (x2, y2, w2, h2) = box1.unbind(-1), box2.unbind(-1)
    b1_x1, b1_x2, b1_y1, b1_y2 = x1 - w1 / 2, x1 + w1 / 2, y1 - h1 / 2, y1 + h1 / 2
    b2_x1, b2_x2, b2_y1, b2_y2 = x2 - w2 / 2, x2 + w2 / 2, y2 - h2 / 2, y2 + h2 / 2
    inter = (torch.min(b1_x2, b2_x2) - torch.max(b1_x1, b2_x1)).clamp(0) * \
            (torch.min(b1_y2, b2_y2) - torch.max(b1_y1, b2_y1)).clamp(0)
    union = w1 * h1 + w2 * h2 - inter + eps
    iou = inter / union
    cw = torch.max(b1_x2, b2_x2) - torch.min(b1_x1, b2_x1)
    ch = torch.max(b1_y2, b2_y2) - torch.min(b1_y1, b2_y1)
    c2 = cw ** 2 + ch ** 2 + eps
    rho2 = (x2 - x1) ** 2 + (y2 - y1) ** 2
    v = (4 / math.pi ** 2) * (torch.atan(w2 / (h2 + eps)) - torch.atan(w1 / (h1 + eps))) ** 2
    with torch.no_grad():
        alpha = v / (v - iou + (1 + eps))
    return iou - (rho2 / c2 + v * alpha)


class YoloLoss:
    """Callable: ``loss(preds, targets) -> (total (1,), parts (3,) [box, obj, cls] detached)``.

    ``preds``: the training output of ``Detect``, per level ``(B, na, H, W, 5 + nc)``.
    """

    def __init__(self, anchors: torch.Tensor, strides, num_classes: int, image_size: int,
                 gains: LossGains = LossGains()):
        self.anchors = torch.as_tensor(anchors, dtype=torch.float32)   # (nl, na, 2) px
        self.strides = [float(s) for s in strides]
        self.nl, self.na = self.anchors.shape[:2]
        self.nc = num_classes
        self.gains = gains
        self.balance = {3: [4.0, 1.0, 0.4]}.get(self.nl, [4.0, 1.0, 0.25, 0.06, 0.02])
        self.box_gain = gains.box * 3 / self.nl
        self.cls_gain = gains.cls * self.nc / 80 * 3 / self.nl
        self.obj_gain = gains.obj * (image_size / 640) ** 2 * 3 / self.nl
        self.bce = nn.BCEWithLogitsLoss()

    def __call__(self, preds, targets: torch.Tensor):
        if targets.ndim != 2 or targets.shape[1] != 6:
            raise ValueError(f"targets must be (M, 6) [image, class, cx, cy, w, h], got {tuple(targets.shape)}")
        lbox = torch.zeros(())
        lobj = torch.zeros(())
        lcls = torch.zeros(())
        tcls, tbox, indices, anch = self.build_targets(preds, targets)
        for i, pi in enumerate(preds):
            b, a, gj, gi = indices[i]
            tobj = torch.zeros(pi.shape[:4], dtype=pi.dtype)
            n = b.shape[0]
            if n:
                ps = pi[b, a, gj, gi]
                pxy = ps[:, :2].sigmoid() * 2 - 0.5
                pwh = (ps[:, 2:4].sigmoid() * 2) ** 2 * anch[i]
                iou = bbox_ciou(torch.cat((pxy, pwh), 1), tbox[i])
                lbox = lbox + (1.0 - iou).mean()
                tobj[b, a, gj, gi] = iou.detach().clamp(0).to(tobj.dtype)
                if self.nc > 1:
                    t = torch.zeros_like(ps[:, 5:])
                    t[torch.arange(n), tcls[i]] = 1.0
                    lcls = lcls + self.bce(ps[:, 5:], t)
            lobj = lobj + self.bce(pi[..., 4], tobj) * self.balance[i]
        bs = preds[0].shape[0]
        lbox, lobj, lcls = lbox * self.box_gain, lobj * self.obj_gain, lcls * self.cls_gain
        return (lbox + lobj + lcls) * bs, torch.stack((lbox, lobj, lcls)).detach()

    def build_targets(self, preds, targets: torch.Tensor):
        na, nt = self.na, targets.shape[0]
        tcls, tbox, indices, anch = [], [], [], []
        gain = torch.ones(7)
        ai = torch.arange(na, dtype=torch.float32).view(na, 1).repeat(1, nt)
        targets = torch.cat((targets.float().repeat(na, 1, 1), ai[..., None]), 2)  # (na, nt, 7)
        g = 0.5
        off = torch.tensor([[0, 0], [1, 0], [0, 1], [-1, 0], [0, -1]], dtype=torch.float32) * g
        for i, p in enumerate(preds):
            h, w = p.shape[2:4]
            anchors = self.anchors[i] / self.strides[i]          # grid units
            gain[2:6] = 1.0 / self.strides[i]
            t = targets * gain
            if nt:
                r = t[..., 4:6] / anchors[:, None]
                keep = torch.max(r, 1 / r).max(2)[0] < self.gains.anchor_t
                t = t[keep]
                gxy = t[:, 2:4]
                gxi = torch.tensor([w, h], dtype=torch.float32) - gxy
                j, k = ((gxy % 1 < g) & (gxy > 1)).T
                l, m = ((gxi % 1 < g) & (gxi > 1)).T
                sel = torch.stack((torch.ones_like(j), j, k, l, m))
                t = t.repeat((5, 1, 1))[sel]
                offsets = (torch.zeros_like(gxy)[None] + off[:, None])[sel]
            else:
                t = targets[0]
                offsets = 0
            bc, gxy, gwh, a = t.split((2, 2, 2, 1), 1)
            a = a.long().view(-1)
            b, c = bc.long().T
            gij = (gxy - offsets).long()
            gi = gij[:, 0].clamp(0, w - 1)
            gj = gij[:, 1].clamp(0, h - 1)
            indices.append((b, a, gj, gi))
            tbox.append(torch.cat((gxy - torch.stack((gi, gj), 1), gwh), 1))
            anch.append(anchors[a])
            tcls.append(c)
        return tcls, tbox, indices, anch
