"""The README tour's own-parts path end to end, without Blender: a user's CAD parts (the shipped
octagonal section, A as glTF, B as STL), their calibrated camera (an OpenCV YAML: principal point
off centre, barrel distortion) and their markers' measured coordinates (a CSV, as a CMM writes
it) make a dataset (painted through the real post-processing: tests/pipeline_data.py), and its
frames measured with that calibration, that layout and the painted camera's own noise card give
every pose within 4 of its own standard deviations of its label (measured on these painted frames:
within 1.1 of them)."""
from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from cli_run import run_cli
from dockfactory.core.calibration_files import Calibration, write_calibration

CAMERA = Calibration(1280, 960, 2211.2, 2211.2, 651.8, 472.3, (-0.092, 0.118, 3.1e-4, -2.4e-4, 0.0))


# end to end (about 6 s idle): its steps have quicker tests in the fast lane: the parts' files
# (tests/core/test_mesh_files.py), `layout from-csv` (tests/core/test_layout_csv.py), measuring painted
# 1280 x 960 frames of a calibrated camera with --calibration within their labels
# (tests/app/test_measure_stream.py::test_a_calibrated_camera_streamed_is_measured_as_its_images) and
# the calibration's solve within its uncertainty (tests/app/test_measure_calibration.py)
@pytest.mark.slow
def test_parts_a_calibration_and_a_csv_from_render_to_measure(repo_root, tmp_path, capsys):
    from pipeline_data import write_painted_dataset
    shutil.copytree(repo_root / "configs" / "parts", tmp_path / "parts")
    write_calibration(CAMERA, tmp_path / "cam.yaml", "opencv-yaml")
    text = (repo_root / "configs" / "octagon_part.toml").read_text().replace("frames = 40", "frames = 4")
    (tmp_path / "mine.toml").write_text(text + '\n[camera]\ndistance_mm = [1600.0, 1900.0]\n\n[camera_units]\n'
                                        'calibration = "cam.yaml"\n\n[conditions]\nlow_light = 0\nocclusion = 0\n'
                                        'glare = 0\n\n[repeatability]\nposes = 0\n\n[render]\nkeep_exr = false\n')
    write_painted_dataset(tmp_path / "ds", tmp_path / "mine.toml")
    rows = ["id,section,x,y,z,nx,ny,nz,diameter"]   # the markers as measured by a CMM (to 1 um)
    for m in json.loads((tmp_path / "ds" / "layout.json").read_text())["markers"]:
        rows.append(",".join([m["id"], m["section"], *(f"{v:.3f}" for v in m["center_mm"]),
                              *(f"{v:.5f}" for v in m["normal"]), str(m["diameter_mm"])]))
    (tmp_path / "markers.csv").write_text("\n".join(rows) + "\n")
    assert run_cli(["layout", "from-csv", tmp_path / "markers.csv", "--out", tmp_path / "layout.json"], capsys)[0] == 0
    # the painted frames' discs are binary (no ring, no antialiasing): a camera of their own, its
    # centres about 0.1 px noisy (7x the shipped card's), so its card is measured first, as a user
    # measures one for a camera of their own (docs: `dockfactory noise-card`)
    shutil.copy(repo_root / "models" / "yolov5n_se_rings_markers.pt", tmp_path / "w.pt")
    assert run_cli(["noise-card", tmp_path / "ds", "--weights", tmp_path / "w.pt", "--split", "train", "--quiet"],
                   capsys)[0] == 0
    assert json.loads((tmp_path / "w.noise.json").read_text())["centre_noise_px"] > 0.03
    images = sorted((tmp_path / "ds" / "images").glob("*.png"))
    code, _, err = run_cli(["measure", *images, "--layout", tmp_path / "layout.json", "--calibration",
                            tmp_path / "cam.yaml", "--weights", tmp_path / "w.pt", "--out", tmp_path / "m",
                            "--workers", "1", "--threads", "1", "--backend", "torch", "--overlay-size", "0", "--quiet"],
                           capsys)
    assert code == 0, err
    errors = []
    for rec in json.loads((tmp_path / "m" / "measurements.json").read_text())["images"]:
        fid = rec["image"].split("/")[-1][:6]
        truth = json.loads((tmp_path / "ds" / "labels" / f"{fid}.json").read_text())["pose_b_in_d"]
        std = np.sqrt(np.diag(rec["covariance"]))[[0, 1, 3]]
        errors.append([(rec["pose"][k] - truth[k]) / s for k, s in zip(("x_mm", "y_mm", "alpha_deg"), std)])
        assert rec["calibration"]["principal_point"] == [651.8, 472.3]
    assert len(errors) == 4 and np.abs(errors).max() < 4.0, errors
