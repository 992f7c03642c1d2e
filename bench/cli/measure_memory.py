"""Peak memory (RSS) of ``dockfactory measure`` on one image, each case in a fresh process.

    python -m bench.cli.measure_memory [--image FRAME.png --layout LAYOUT.json] [--backend auto]

Cases: no image to decode (a missing file: the process, torch and the detector alone), a normal
1280 x 960 frame, the largest image the default limit allows (8160 x 6120 = 49.9 megapixels, the
frame scaled up) and a PNG whose header claims 65000 x 65000 px (refused from its header).
Each case runs ``python -m dockfactory measure IMAGE --workers 1 --threads 1`` in a child whose
peak RSS is read with os.wait4 (the measuring process itself: --workers 1 measures in it).
Without --image a painted 1280 x 960 frame is made (tests/pipeline_data.py, no Blender).
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import struct
import subprocess
import sys
import tempfile
import time
import zlib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
LARGEST = (8160, 6120)   # under the default --max-megapixels 50


CONFIG = """
[dataset]
name = "measure-memory"
seed = 11
frames = 1
train_fraction = 0.5

[conditions]
normal = 1

[image]
width = 1280
height = 960

[render]
keep_exr = false
"""


def painted_frame(folder: Path) -> tuple[Path, Path]:
    """(a painted 1280 x 960 frame, its layout): tests/pipeline_data.py, the tests' measure frames."""
    from tests.pipeline_data import write_painted_dataset
    (folder / "c.toml").write_text(CONFIG)
    root = folder / "dataset"
    write_painted_dataset(root, folder / "c.toml")
    return sorted((root / "images").glob("*.png"))[0], root / "layout.json"


def header_only_png(path: Path, w: int, h: int) -> Path:
    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0))
                     + chunk(b"IDAT", zlib.compress(b"\0" * 64)) + chunk(b"IEND", b""))
    return path


def peak_rss(image: Path, layout: Path, out: Path, backend: str) -> dict:
    """Peak RSS (MB), wall time and the record of one measure run on ``image`` in a child."""
    cmd = [sys.executable, "-m", "dockfactory", "measure", str(image), "--layout", str(layout), "--out", str(out),
           "--workers", "1", "--threads", "1", "--backend", backend, "--quiet"]
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    stderr = proc.stderr.read().decode(errors="replace")
    proc.stderr.close()
    doc = out / "measurements.json"
    rec = json.loads(doc.read_text())["images"][0] if doc.exists() else {}
    return {"peak_rss_mb": round(usage.ru_maxrss / 1024, 1), "wall_s": round(wall, 2),
            "exit": os.waitstatus_to_exitcode(status), "ok": rec.get("ok"), "category": rec.get("category"),
            "stderr": stderr.strip()[-200:]}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--image", help="a 1280 x 960 frame (default: a painted one)")
    p.add_argument("--layout", help="its layout.json (with --image)")
    p.add_argument("--backend", default="auto", choices=("auto", "torch", "onnx"))
    args = p.parse_args()
    import cv2
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        frame, layout = (Path(args.image), Path(args.layout)) if args.image else painted_frame(tmp)
        big = tmp / "largest.png"
        cv2.imwrite(str(big), cv2.resize(cv2.imread(str(frame)), LARGEST, interpolation=cv2.INTER_LINEAR),
                    [cv2.IMWRITE_PNG_COMPRESSION, 1])
        h0, w0 = cv2.imread(str(frame)).shape[:2]
        cases = [("no image decoded (a missing file: process, imports)", tmp / "missing.png"),
                 (f"normal {w0}x{h0} ({w0 * h0 / 1e6:.2f} MP)", frame),
                 (f"largest allowed {LARGEST[0]}x{LARGEST[1]} ({LARGEST[0] * LARGEST[1] / 1e6:.2f} MP)", big),
                 ("header claims 65000x65000 (refused)", header_only_png(tmp / "claims.png", 65000, 65000))]
        print(f"machine: {platform.node()}, {os.cpu_count()} cores, {platform.machine()}, Python "
              f"{platform.python_version()}; load average {os.getloadavg()[0]:.2f}")
        print(f"{'case':<52} {'peak RSS MB':>11} {'wall s':>7}  result")
        for k, (name, image) in enumerate(cases):
            r = peak_rss(image, layout, tmp / f"out{k}", args.backend)
            result = "pose" if r["ok"] else f"no pose: {r['category']}"
            print(f"{name:<52} {r['peak_rss_mb']:>11.1f} {r['wall_s']:>7.2f}  {result} (exit {r['exit']})"
                  + (f" stderr: {r['stderr']}" if r["stderr"] else ""))


if __name__ == "__main__":
    main()
