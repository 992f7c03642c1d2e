"""The stand-in's ``torchvision.ops.nms`` against ultralytics' own plain-torch NMS
(``ultralytics.utils.nms.TorchNMS.nms``, documented there as matching torchvision exactly) on
seeded random boxes: the kept indices must be identical.

    .venv/bin/python -m bench.solver.ultralytics_shim.nms_check ULTRALYTICS_DIR WORK_DIR
"""
import os
import sys
from pathlib import Path

import torch

HERE = Path(__file__).resolve().parent


def main(argv: list[str]) -> int:
    if len(argv) != 2 or not (Path(argv[0]) / "ultralytics" / "__init__.py").is_file():
        print("usage: nms_check.py ULTRALYTICS_DIR WORK_DIR (an unpacked ultralytics wheel)", file=sys.stderr)
        return 2
    from bench.solver.pose_train import prepare   # settings in WORK_DIR, torchvision metadata, the shim on the path
    prepare(Path(argv[1]), Path(argv[0]), None)
    from torchvision.ops import nms
    from ultralytics.utils.nms import TorchNMS
    g = torch.Generator().manual_seed(0)
    same = cases = 0
    for _ in range(200):
        n = int(torch.randint(1, 400, (1,), generator=g))
        xy, wh = torch.rand(n, 2, generator=g) * 300, torch.rand(n, 2, generator=g) * 60 + 1
        boxes, scores = torch.cat([xy, xy + wh], 1), torch.rand(n, generator=g)
        for thr in (0.3, 0.5, 0.7):
            same += torch.equal(nms(boxes, scores, thr), TorchNMS.nms(boxes, scores, thr))
            cases += 1
    print(f"stand-in nms == ultralytics TorchNMS.nms in {same} of {cases} seeded cases "
          f"(1-400 boxes, IoU 0.3 / 0.5 / 0.7); YOLO_CONFIG_DIR {os.environ['YOLO_CONFIG_DIR']}")
    return 0 if same == cases else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
