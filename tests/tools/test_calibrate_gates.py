"""calibrate_gates: the proposed thresholds keep the most poses with no flip and no wrong pose."""

import json

import pytest

from spacepose.tools.calibrate_gates import gate_table, main, propose

ROWS = [
    {"valid": True, "confidence": 0.9, "flip_margin": 0.04, "e_t": 0.05, "e_R": 2.0},
    {"valid": True, "confidence": 0.85, "flip_margin": 0.03, "e_t": 0.08, "e_R": 3.0},
    {"valid": True, "confidence": 0.95, "flip_margin": 0.004, "e_t": 0.10, "e_R": 178.0},   # a flip, small margin
    {"valid": True, "confidence": 0.55, "flip_margin": 0.06, "e_t": 2.0, "e_R": 40.0},      # wrong, low confidence
    {"valid": False, "confidence": 0.0, "flip_margin": None, "e_t": None, "e_R": None},
]


def test_table_counts_and_proposal():
    table = gate_table(ROWS, [0.0, 0.6], [0.0, 0.01], max_e_t=0.5, max_e_r=20.0)
    open_gates = next(r for r in table if r["min_confidence"] == 0.0 and r["min_flip_margin"] == 0.0)
    assert (open_gates["kept"], open_gates["flips"], open_gates["wrong"]) == (4, 1, 2)
    best = propose(table)
    assert (best["min_confidence"], best["min_flip_margin"], best["kept"]) == (0.6, 0.01, 2)
    assert propose([r for r in table if r["flips"]]) is None


def test_the_gate_reads_the_decision_confidence_where_a_report_has_it():
    # since session 30 "confidence" is the pose's accuracy confidence; the gate is on the decision's own
    rows = [dict(r, decision_confidence=r["confidence"], confidence=1.0 - r["confidence"]) for r in ROWS]
    assert gate_table(rows, [0.0, 0.6], [0.0, 0.01], 0.5, 20.0) == gate_table(ROWS, [0.0, 0.6], [0.0, 0.01], 0.5, 20.0)


def test_depth_tolerance_gate():
    rows = [dict(r, depth_tolerance_m=tau) for r, tau in zip(ROWS, [0.2, 0.3, 0.25, 2.0, None])]
    rows[0]["flip_margin"] = 0.01  # now only the depth tolerance separates the wrong far pose at 0.06
    table = gate_table(rows, [0.0], [0.0, 0.01], max_e_t=0.5, max_e_r=20.0, taus=[0.5, float("inf")])
    near = next(r for r in table if r["min_flip_margin"] == 0.01 and r["max_tau_m"] == 0.5)
    assert (near["kept"], near["flips"], near["wrong"]) == (2, 0, 0)
    far = next(r for r in table if r["min_flip_margin"] == 0.01 and r["max_tau_m"] == float("inf"))
    assert (far["kept"], far["wrong"]) == (3, 1)
    assert propose(table)["max_tau_m"] == 0.5


def test_cli_refuses_test_split_and_writes_json(tmp_path, capsys):
    report = tmp_path / "r.json"
    report.write_text(json.dumps({"split": "test", "frames": ROWS}))
    with pytest.raises(SystemExit, match="train"):
        main([str(report)])
    report.write_text(json.dumps({"split": "train", "frames": ROWS}))
    assert main([str(report), "--out", str(tmp_path / "g.json")]) == 0
    assert json.loads((tmp_path / "g.json").read_text())["proposed"]["kept"] == 2
    assert "proposed: min_confidence" in capsys.readouterr().out
    import gzip

    packed = tmp_path / "r.json.gz"                       # how older reports are stored
    packed.write_bytes(gzip.compress(report.read_bytes()))
    assert main([str(packed), "--out", str(tmp_path / "g2.json")]) == 0
    assert json.loads((tmp_path / "g2.json").read_text())["proposed"]["kept"] == 2


OUTLINE_ROWS = [
    {"valid": True, "outline_chamfer_px": 0.7, "outline_margin_px": 0.8, "e_t": 0.1, "e_R": 2.0},
    {"valid": True, "outline_chamfer_px": 1.1, "outline_margin_px": 0.5, "e_t": 0.2, "e_R": 3.0},
    {"valid": True, "outline_chamfer_px": 0.9, "outline_margin_px": 0.15, "e_t": 0.2, "e_R": 179.0},  # flip, small gap
    {"valid": True, "outline_chamfer_px": 1.9, "outline_margin_px": 0.9, "e_t": 0.3, "e_R": 176.0},   # flip, poor fit
    {"valid": True, "outline_chamfer_px": None, "outline_margin_px": None, "e_t": 0.1, "e_R": 1.0},   # stage off
    {"valid": False, "outline_chamfer_px": 0.5, "outline_margin_px": 2.0, "e_t": None, "e_R": None},
]


def test_outline_table_and_proposal(tmp_path, capsys):
    from spacepose.tools.calibrate_gates import outline_gate_table, propose_outline

    table = outline_gate_table(OUTLINE_ROWS, [1.2, 2.0], [0.1, 0.3], max_e_t=0.5, max_e_r=20.0)
    wide = next(r for r in table if r["max_chamfer_px"] == 2.0 and r["min_margin_px"] == 0.1)
    assert (wide["kept"], wide["flips"]) == (4, 2)
    best = propose_outline(table)
    assert (best["max_chamfer_px"], best["min_margin_px"], best["kept"]) == (1.2, 0.3, 2)
    assert best["e_R_mean"] == pytest.approx(2.5)
    report = tmp_path / "r.json"
    report.write_text(json.dumps({"split": "train", "frames": OUTLINE_ROWS}))
    assert main([str(report), "--outline", "--margins", "0.1", "0.3", "--out", str(tmp_path / "g.json")]) == 0
    assert json.loads((tmp_path / "g.json").read_text())["proposed"]["min_margin_px"] == 0.3
    assert "proposed: max_chamfer_px" in capsys.readouterr().out


def _row(chamfer, margin, score, e_r, background=0.0, pixels=100):
    return {"valid": True, "outline_chamfer_px": chamfer, "outline_margin_px": margin, "outline_image_score": score,
            "outline_image_background": background, "outline_image_pixels": pixels, "e_t": 0.2, "e_R": e_r}


IMAGE_ROWS = [
    _row(0.7, 0.8, 0.05, 2.0),                     # kept by its margin
    _row(1.1, 0.3, 0.3, 3.0),                      # the image backs it
    _row(1.0, 0.25, 0.08, 178.0),                  # flip, weak vote
    _row(1.0, 0.05, 0.5, 177.0),                   # flip, tiny margin
    _row(1.0, 0.3, 0.4, 2.0, background=0.3),      # lit sky: no vote
    _row(1.0, 0.3, None, 2.0, background=None),    # no vote taken
    _row(2.5, 0.3, 0.9, 2.0),                      # the outline misfits
    _row(0.8, 0.9, -0.4, 176.0),                   # flip with a large margin that the image refutes
    _row(0.8, 0.3, 0.6, 175.0, pixels=5),          # flip backed by five pixels only
]


def test_image_table_and_proposal(tmp_path, capsys):
    from spacepose.tools.calibrate_gates import image_gate_table, propose_image

    table = image_gate_table(IMAGE_ROWS, 1.5, 0.5, [0.0, 0.2], [0.05, 0.1], 0.02, max_e_t=0.5, max_e_r=20.0,
                             pixels=[0, 16])
    loose = next(r for r in table if (r["image_min_margin_px"], r["image_min_score"], r["image_min_pixels"]) == (0.0, 0.05, 0))
    assert (loose["kept"], loose["by_image"], loose["vetoed"], loose["flips"]) == (5, 4, 1, 3)
    best = propose_image(table)
    assert (best["image_min_margin_px"], best["image_min_score"], best["image_min_pixels"]) == (0.2, 0.1, 16)
    assert (best["kept"], best["by_image"], best["vetoed"], best["flips"]) == (2, 1, 1, 0)
    assert best["e_R_mean"] == pytest.approx(2.5)
    report = tmp_path / "r.json"
    report.write_text(json.dumps({"split": "train", "frames": IMAGE_ROWS}))
    assert main([str(report), "--image", "--margins", "0.0", "0.2", "--scores", "0.05", "0.1", "--pixels", "0", "16",
                 "--out", str(tmp_path / "g.json")]) == 0
    assert json.loads((tmp_path / "g.json").read_text())["proposed"]["image_min_pixels"] == 16
    assert "proposed: image_min_margin_px 0.2" in capsys.readouterr().out
    # a veto score of 0 also refuses the margin decision whose image is dark (score 0)
    dark = IMAGE_ROWS + [_row(0.8, 0.9, 0.0, 150.0)]
    by_veto = {r["image_veto_score"]: r for r in image_gate_table(dark, 1.5, 0.5, [0.2], [0.1], 0.02, max_e_t=0.5,
                                                                  max_e_r=20.0, pixels=[16], vetoes=[-0.1, 0.0, 0.1])}
    assert sorted(by_veto) == [-0.1, 0.0]    # a veto score not below the min score is skipped
    # two reports pool their frames: the dark flip, on its own in the second, is kept at -0.1 and refused at 0
    extra = tmp_path / "extra.json"
    extra.write_text(json.dumps({"split": "train", "frames": [_row(0.8, 0.9, 0.0, 150.0)]}))
    assert main([str(report), str(extra), "--image", "--margins", "0.2", "--scores", "0.1", "--pixels", "16",
                 "--vetoes", "-0.1", "0", "--out", str(tmp_path / "pooled.json")]) == 0
    pooled = json.loads((tmp_path / "pooled.json").read_text())
    assert pooled["report"] == [str(report), str(extra)] and pooled["proposed"]["image_veto_score"] == 0.0
    assert "10 of 10 train frames valid" in capsys.readouterr().out
    # the image route's own chamfer gate: a looser fit the image backs is kept, the margin route's is not
    loose_fit = [_row(1.8, 0.3, 0.4, 3.0), _row(1.8, 0.9, 0.05, 4.0), _row(2.4, 0.3, 0.4, 177.0)]
    by_gate = {r["image_max_chamfer_px"]: r for r in image_gate_table(
        loose_fit, 1.5, 0.5, [0.2], [0.1], 0.02, max_e_t=0.5, max_e_r=20.0, pixels=[16], chamfers=[0.0, 2.0, 2.5])}
    assert [(by_gate[c]["kept"], by_gate[c]["flips"]) for c in (0.0, 2.0, 2.5)] == [(0, 0), (1, 0), (2, 1)]
    # min_flip_pixels: a margin decision whose pose and flip differ in a handful of pixels is refused
    few = [_row(0.7, 0.8, 0.0, 177.0, pixels=7), _row(0.7, 0.8, 0.2, 2.0, pixels=60), _row(0.7, 0.8, None, 3.0)]
    by_floor = {r["min_flip_pixels"]: r for r in image_gate_table(
        few, 1.5, 0.5, [0.2], [0.1], 0.02, max_e_t=0.5, max_e_r=20.0, pixels=[16], flip_pixels=[0, 16])}
    assert (by_floor[0]["kept"], by_floor[0]["flips"]) == (3, 1)
    assert (by_floor[16]["kept"], by_floor[16]["flips"]) == (2, 0)   # the row without a vote is not refused
    assert (by_veto[-0.1]["flips"], by_veto[-0.1]["vetoed"]) == (1, 1)
    assert (by_veto[0.0]["flips"], by_veto[0.0]["vetoed"], by_veto[0.0]["kept"]) == (0, 2, 2)


def _flip_row(chamfer, margin, e_r, prob, e_sym=None, score=None, pixels=100):
    row = _row(chamfer, margin, score, e_r, background=None if score is None else 0.0, pixels=pixels)
    return {**row, "flip_prob": prob, "e_R_sym": e_r if e_sym is None else e_sym}


FLIP_ROWS = [
    _flip_row(0.7, 0.8, 2.0, 0.98),                  # the outline decides it, the classifier agrees
    _flip_row(0.7, 0.8, 178.0, 0.03, e_sym=2.0),     # the outline decides a flip, the classifier disagrees
    _flip_row(1.0, 0.1, 3.0, 0.995),                 # open; the classifier backs the winner
    _flip_row(1.0, 0.2, 176.0, 0.004, e_sym=4.0),    # open; the winner is a flip and the classifier says so
    _flip_row(1.0, 0.2, 3.0, 0.02),                  # open; the classifier is wrong (not sure enough at 0.99)
    _flip_row(2.2, 0.1, 2.0, 0.999),                 # a looser fit: only the wider chamfer gate keeps it
    _flip_row(1.0, 0.3, 3.0, 0.999, score=-0.2),     # open; the image refutes the winner, so nothing decides
    _flip_row(1.0, 0.3, 3.0, None),                  # no classifier score: not in the table
]


def test_flip_table_and_proposal(tmp_path, capsys):
    from spacepose.tools.calibrate_gates import flip_gate_table, propose_flip

    fixed = {"max_chamfer_px": 1.5, "min_margin_px": 0.5, "image_margin": 0.2, "image_score": 0.1, "image_pixels": 16,
             "image_veto": 0.0, "image_chamfer": 2.0, "flip_pixels": 16, "max_background": 0.02}
    table = flip_gate_table(FLIP_ROWS, [0.95, 0.99], [-1.0, 0.05], [1.5, 2.5], max_e_t=0.5, max_e_r=20.0, **fixed)
    by = {(r["decide_prob"], r["veto_prob"], r["max_chamfer_px"]): r for r in table}
    loose = by[(0.95, -1.0, 1.5)]
    assert (loose["kept"], loose["decided"], loose["for_flip"], loose["vetoed"], loose["flips"]) == (5, 3, 2, 0, 2)
    strict = by[(0.99, 0.05, 1.5)]
    assert (strict["kept"], strict["decided"], strict["vetoed"], strict["flips"]) == (3, 2, 1, 0)
    best = propose_flip(table)
    assert (best["decide_prob"], best["veto_prob"], best["max_chamfer_px"]) == (0.99, 0.05, 2.5)
    assert (best["kept"], best["flips"], best["wrong"]) == (4, 0, 0)
    assert best["within"] == 0 and loose["within"] == 0     # every row is 0.2 m off
    # within the bar (0.10 m, 2 deg) at 0.05 m: rows 1 and 6 (e_R 2.0), not row 3 (3.0) nor row 4's flip side
    # (e_R_sym 4.0); the loose gates keep row 1, and row 2 only as a flip, which is never within
    near = [{**r, "e_t": 0.05} for r in FLIP_ROWS]
    by_near = {(r["decide_prob"], r["veto_prob"], r["max_chamfer_px"]): r for r in flip_gate_table(
        near, [0.95, 0.99], [-1.0, 0.05], [1.5, 2.5], max_e_t=0.5, max_e_r=20.0, **fixed)}
    assert by_near[(0.99, 0.05, 2.5)]["within"] == 2 and by_near[(0.95, -1.0, 1.5)]["within"] == 1
    # the classifier's own limits: it decides no frame whose depth tolerance or polish is over them (or unknown);
    # a frame the outline decides (row 1) is still kept
    limited = [{**r, "depth_tolerance_m": 0.9 if i == 2 else 0.4, "polish_deg": None if i == 5 else 1.0}
               for i, r in enumerate(FLIP_ROWS)]
    by_lim = {(r["decide_prob"], r["veto_prob"], r["max_chamfer_px"]): r for r in flip_gate_table(
        limited, [0.99], [0.05], [2.5], max_e_t=0.5, max_e_r=20.0, **fixed, max_depth_tolerance_m=0.7,
        max_polish_deg=2.0)}
    assert (by_lim[(0.99, 0.05, 2.5)]["kept"], by_lim[(0.99, 0.05, 2.5)]["decided"]) == (2, 1)  # rows 1 and 4's flip
    unlimited = {(r["decide_prob"], r["veto_prob"], r["max_chamfer_px"]): r for r in flip_gate_table(
        limited, [0.99], [0.05], [2.5], max_e_t=0.5, max_e_r=20.0, **fixed)}
    assert unlimited[(0.99, 0.05, 2.5)]["kept"] == 4
    capsys.readouterr()
    (tmp_path / "lim.json").write_text(json.dumps({"split": "train", "frames": limited}))
    assert main([str(tmp_path / "lim.json"), "--flip", "--decides", "0.99", "--flip-vetoes", "0.05", "--flip-chamfers",
                 "2.5", "--flip-max-tau", "0.7", "--flip-max-polish", "2", "--out", str(tmp_path / "lim_out.json")]) == 0
    lim_out = json.loads((tmp_path / "lim_out.json").read_text())
    assert lim_out["max_depth_tolerance_m"] == 0.7 and lim_out["proposed"]["kept"] == 2
    assert "| 0.990 | 0.05 | 2.5 | 2 | 1 |" in capsys.readouterr().out
    assert best["e_R_mean"] == pytest.approx((2.0 + 3.0 + 4.0 + 2.0) / 4)   # the flip's error is e_R_sym
    assert propose_flip([{**r, "flips": 1} for r in table]) is None
    report = tmp_path / "r.json"
    report.write_text(json.dumps({"split": "train", "frames": FLIP_ROWS}))
    assert main([str(report), "--flip", "--decides", "0.95", "0.99", "--flip-vetoes", "-1", "0.05",
                 "--flip-chamfers", "1.5", "2.5", "--out", str(tmp_path / "g.json")]) == 0
    written = json.loads((tmp_path / "g.json").read_text())
    assert written["proposed"]["decide_prob"] == 0.99 and written["proposed"]["veto_prob"] == 0.05
    assert "7 of 8 train frames with a pose and a classifier score" in capsys.readouterr().out
