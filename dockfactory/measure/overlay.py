"""The overlay of one measured image: detections, the layout reprojected with the solved pose and
camera (distortion included), and the pose in text."""
from __future__ import annotations

from dockfactory.core.cv import cv2
import numpy as np

from dockfactory.core.distortion import distort_normalized
from dockfactory.core.geometry import transform_points
from dockfactory.core.io import write_bytes_atomic

DET_BGR = {0: (40, 40, 255), 1: (255, 140, 30)}     # detections: red for A, blue for B
PROJ_BGR = (60, 230, 60)                             # reprojected layout markers
_LABEL = {"x": "X", "y": "Y", "z": "Z"}             # pose components as the overlay names them


def project_layout(record: dict, markers) -> np.ndarray:
    """(N, 2) pixels of every layout marker centre under the record's pose and camera: a
    calibrated camera's (``calibration``: its fx, fy, principal point and lens), else the solved
    one's (focal, the principal point and lens it estimated or assumed)."""
    cam_from_a = np.array(record["cam_from_a"])
    a_from_b = np.array(record["d_from_b"])
    pts = np.array([transform_points(cam_from_a if m.section == "A" else cam_from_a @ a_from_b,
                                     np.array([m.center_mm]))[0] for m in markers])
    cal = record.get("calibration")
    if cal is not None and "fx" in cal:
        xy = distort_normalized(pts[:, :2] / pts[:, 2:3], cal["distortion"])
        return xy * [cal["fx"], cal["fy"]] + cal["principal_point"]
    intr = record.get("intrinsics") or {}
    size = record["image_size"]
    cx, cy = intr.get("cx", (size[0] - 1) / 2.0), intr.get("cy", (size[1] - 1) / 2.0)
    coeffs = [intr.get(k, 0.0) for k in ("k1", "k2", "p1", "p2")]
    xy = distort_normalized(pts[:, :2] / pts[:, 2:3], coeffs)
    return xy * record["focal_px"] + [cx, cy]


def _text_lines(record: dict, name: str) -> list[str]:
    """The overlay's text: the image name, the pose with its 1-sigma standard deviations, or, when
    the record carries a conformity decision (measure --acceptance), each component's value +- U
    (k = 2) and its decision; the camera line."""
    if not record["ok"]:
        return [name, f"NO POSE ({record.get('category', '')}): {record.get('reason', '')}"[:110]]
    p, cov = record["pose"], np.array(record["covariance"])
    camera = (f"camera {record.get('camera_model', 'pinhole')}  f {record['focal_px']:.0f} px  "
              f"rms A {record['rmse_px']['A']:.2f} B {record['rmse_px']['B']:.2f} px")
    conf = record.get("conformity")
    if conf and conf.get("components"):
        k = conf.get("k", 2)
        parts = [f"{_LABEL.get(n.split('_')[0], n.split('_')[0])} {c['value']:.3f} +- {c['U']:.3f} {n.split('_')[1]} {c['decision']}"
                 for n, c in conf["components"].items() if c.get("value") is not None and c.get("U") is not None]
        return [f"{name}: {conf['decision']} (+- U, k = {k:g})", "  ".join(parts), camera]
    std = np.sqrt(np.diag(cov))
    return [name, f"X {p['x_mm']:.2f} +- {std[0]:.2f} mm   Y {p['y_mm']:.2f} +- {std[1]:.2f} mm   "
                  f"alpha {p['alpha_deg']:.3f} +- {std[3]:.3f} deg (+- 1 sigma)", camera]


def text_scale(lines: list[str], width_px: int, scale: float) -> float:
    """The largest font scale, at most ``scale``, at which every line of OpenCV's simplex font
    fits ``width_px`` less a margin of 8 px each side, its dark outline (3 px) included (never
    under a third of ``scale``)."""
    widest = max(cv2.getTextSize(line, cv2.FONT_HERSHEY_SIMPLEX, scale, 3)[0][0] for line in lines)
    room = max(width_px - 16, 1)
    return scale if widest <= room else max(0.97 * scale * room / widest, scale / 3)


def _shrunk(image_rgb: np.ndarray, size: float) -> np.ndarray:
    """BGR copy of the image at ``size`` times its resolution (area-averaged; resized before the
    channels are swapped: OpenCV resizes a channel-reversed view 30x slower)."""
    h, w = image_rgb.shape[:2]
    if size != 1:
        image_rgb = cv2.resize(image_rgb, (max(1, round(w * size)), max(1, round(h * size))),
                               interpolation=cv2.INTER_AREA)
    return cv2.cvtColor(image_rgb, cv2.COLOR_RGB2BGR)


def _at(uv, sx: float, sy: float) -> tuple[int, int]:
    """Image px (OpenCV) -> the nearest pixel of the overlay scaled by (sx, sy)."""
    return int(round((uv[0] + 0.5) * sx - 0.5)), int(round((uv[1] + 0.5) * sy - 0.5))


def draw_measurement(image_rgb: np.ndarray, detections: list, record: dict, markers, out,
                     size: float = 1.0) -> None:
    """Write the overlay PNG ``out`` (atomically), ``size`` times the image's resolution
    (0.5: a quarter of the pixels, four times faster to encode; a live view)."""
    if not 0 < size <= 1:
        raise ValueError(f"overlay size must be in (0, 1], got {size}")
    img = _shrunk(image_rgb, size)
    sx, sy = img.shape[1] / image_rgb.shape[1], img.shape[0] / image_rgb.shape[0]
    scale = max(1, round(max(img.shape[:2]) / 640))
    for d in detections:
        cv2.circle(img, _at(d["center_px"], sx, sy), 6 * scale, DET_BGR.get(d["class_id"], (255, 255, 255)),
                   scale, cv2.LINE_AA)
    if record["ok"]:
        for u, v in project_layout(record, markers):
            if np.isfinite(u) and np.isfinite(v):
                cv2.drawMarker(img, _at((u, v), sx, sy), PROJ_BGR, cv2.MARKER_CROSS, 10 * scale, scale)
    # ASCII: a lone surrogate crashed OpenCV
    lines = [t.encode("ascii", "backslashreplace").decode("ascii") for t in _text_lines(record, str(out.stem))]
    font = text_scale(lines, img.shape[1], 0.5 * scale)
    for k, line in enumerate(lines):
        y = round((18 + 20 * k) * font / 0.5)
        cv2.putText(img, line, (8, y), cv2.FONT_HERSHEY_SIMPLEX, font, (0, 0, 0), 3 * scale, cv2.LINE_AA)
        cv2.putText(img, line, (8, y), cv2.FONT_HERSHEY_SIMPLEX, font, (255, 255, 255), scale, cv2.LINE_AA)
    ok, png = cv2.imencode(".png", img, [cv2.IMWRITE_PNG_COMPRESSION, 1])   # fast: a live view
    if not ok:
        raise RuntimeError(f"{out}: PNG encoding failed")
    write_bytes_atomic(out, png.tobytes())
