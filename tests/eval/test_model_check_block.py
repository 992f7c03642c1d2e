"""The report's camera-model check: counts over the solved test frames of the poses file's
model_check records, the sentence and the HTML paragraph; an older poses file without them."""
from dockfactory.eval.model_check import html_model_check, model_check_block, model_check_sentence

PRIOR = {"marginalise": True, "principal_point_fraction": 0.04, "k1": 0.2}


def _poses(checks: dict, prior=PRIOR) -> dict:
    frames = {fid: ({"ok": True, "model_check": c} if c is not None else {"ok": True}) for fid, c in checks.items()}
    frames["f9"] = {"ok": False, "reason": "too few markers"}
    return {"frames": frames, **({"lens_prior": prior} if prior is not None else {})}


def _rows(ids) -> list:
    return [{"frame_id": f, "ok": f != "f9"} for f in ids]


def test_counts_flagged_and_marginalised_solved_test_frames():
    checks = {"f0": {"explains": True, "marginalised": True}, "f1": {"explains": False, "marginalised": True},
              "f2": {"explains": False, "marginalised": False}, "f3": None}
    block = model_check_block(_poses(checks), _rows(["f0", "f1", "f2", "f3", "f9"]))
    assert block == {"solved": 4, "checked": 3, "flagged": 2, "marginalised": 2,
                     "flagged_frames": ["f1", "f2"], "lens_prior": PRIOR}
    text = model_check_sentence(block)
    assert "2 of 3 solved test frames flagged" in text and "(first: f1, f2)" in text
    assert "marginalised over the lens prior" in text
    html = "".join(html_model_check(block))
    assert "k1 0.2" in html and "principal_point_fraction 0.04" in html


def test_a_known_lens_says_nothing_is_marginalised():
    block = model_check_block(_poses({"f0": {"explains": True, "marginalised": False}}, {"marginalise": False}),
                              _rows(["f0"]))
    assert block["flagged"] == 0 and "taken as known" in model_check_sentence(block)


def test_an_older_poses_file_has_no_check():
    block = model_check_block(_poses({"f0": None}, prior=None), _rows(["f0"]))
    assert block["checked"] == 0 and block["lens_prior"] == {}
    assert model_check_sentence(block).startswith("No solve recorded")
