"""The judge's docking-run solve is told the detector's edge widths: ``solve_frame`` returns the
widths of the centres its fit used (none for a centre without one), and ``solve_run`` hands them
to ``solver.solve_sequence`` (a thin disc widens the run's Y std). Synthetic run, seeded."""
import numpy as np

from dockfactory.eval.solve_frames import solve_frame, solve_run
from dockfactory.solver.synthetic import default_layout, docking_run

LAYOUT = default_layout()
CLASSES = np.array([0 if m.section == "A" else 1 for m in LAYOUT])


def _centres(scene, rng, edge):
    uv = np.vstack([scene.uv_a, scene.uv_b]) + 0.05 * rng.standard_normal((len(LAYOUT), 2))
    return CLASSES, uv, None, None, edge


def test_frame_widths_are_the_used_centres_with_a_width():
    rng = np.random.default_rng(7)
    run = docking_run(rng, 2)
    edge = np.full(len(LAYOUT), 0.8)
    edge[[0, 5]] = np.nan
    record, used, widths = solve_frame(LAYOUT, run.frames[0].image_centre, _centres(run.frames[0], rng, edge),
                                       None, "pinhole")
    assert record["ok"] and set(widths) <= set(used)
    assert set(used) - set(widths) == {LAYOUT[0].id, LAYOUT[5].id} and all(w == 0.8 for w in widths.values())
    assert solve_frame(LAYOUT, run.frames[0].image_centre, _centres(run.frames[0], rng, None), None, "pinhole")[2] == {}


def _run_records(run, rng, zoomed: int | None = None, zoom: float = 1.0):
    """Each frame solved alone (gated); frame ``zoomed``'s centres scaled about the image centre
    by ``zoom`` (the camera zoomed between frames: the frame fits alone with another focal)."""
    frames, used = {}, {}
    for k, sc in enumerate(run.frames):
        classes, uv, *_ = _centres(sc, rng, None)
        if k == zoomed:
            uv = sc.image_centre + zoom * (uv - sc.image_centre)
        frames[str(k)], used[str(k)], _ = solve_frame(LAYOUT, sc.image_centre, (classes, uv, None, None, None),
                                                      0.05, "pinhole")
        assert frames[str(k)]["ok"]
    return frames, used


def test_run_gate_leaves_out_a_frame_from_another_camera():
    """A run of 6 frames, one zoomed 3 % (it fits alone): the joint solve cannot explain it at the
    known 0.05 px; it is left out with the reason and the other five are solved again, each
    explained. Before the gate every frame of the run was ok."""
    rng = np.random.default_rng(11)
    run = docking_run(rng, 6)
    frames, used = _run_records(run, rng, zoomed=3, zoom=1.03)
    out = solve_run(LAYOUT, run.frames[0].image_centre, list(frames), frames, used, 0.05, "pinhole")
    assert not out["3"]["ok"] and out["3"]["category"] == "misfit"
    assert "with the run's shared intrinsics" in out["3"]["reason"] and "\n" not in out["3"]["reason"]
    others = [out[k] for k in frames if k != "3"]
    assert all(r["ok"] and r["fit_test"]["explains"] and r["run_frames"] == 5 for r in others)


def test_run_gate_passes_a_clean_run_and_counts_the_shared_intrinsics():
    rng = np.random.default_rng(12)
    run = docking_run(rng, 6)
    frames, used = _run_records(run, rng)
    out = solve_run(LAYOUT, run.frames[0].image_centre, list(frames), frames, used, 0.05, "pinhole")
    assert all(r["ok"] and r["fit_test"]["explains"] for r in out.values())
    # 14 points: 28 residuals, two poses (12) and a sixth of the focal per frame
    assert all(abs(r["fit_test"]["dof"] - (28 - 12 - 1 / 6)) < 1e-3 for r in out.values())
