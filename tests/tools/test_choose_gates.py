"""choose_gates: the fixed rule on rows whose answer is known (flips and wrong poses bar cells and their
neighbours, the floor acts first, the classifier loosens only on enough rows, small gains keep the reference)."""

from __future__ import annotations

import gzip
import json

import pytest

from spacepose.errors import BundleError, DatasetError
from spacepose.tools import choose_gates
from spacepose.tools.choose_gates import GRID, load_rows, main, reference_gates, write_candidate

#: a small grid (the full one replays ~7,000 outline and image cells: 40 s on 4,000 rows, too slow for a test)
SMALL = {**{k: (v[0],) for k, v in GRID.items()}, "min_margin_px": GRID["min_margin_px"],
         "image_score": (0.05, 0.1), "decide_prob": (0.97, 0.99, 0.995), "veto_prob": (-1.0, 0.05, 0.1),
         "flip_chamfer": (1.0, 1.5, 2.0)}


def choose(*args, **kwargs):
    """The rule on the small grid, the outline margin free to loosen (``margin_rows`` 0) unless a test says."""
    return choose_gates.choose(*args, grid=SMALL, **{"margin_rows": 0, **kwargs})

GATES = {"silhouette": {"max_chamfer_px": 1.5, "min_margin_px": 1.0, "image_min_margin_px": 0.1,
                        "image_min_score": 0.1, "image_veto_score": -0.5, "image_max_chamfer_px": 2.0,
                        "image_min_pixels": 16, "min_flip_pixels": 16, "polish": 1},
         "flip_classifier": {"decide_prob": 0.995, "veto_prob": 0.05, "max_chamfer_px": 1.5, "max_polish_deg": 2.0,
                             "max_depth_tolerance_m": 1.0, "file": "flip.onnx"},
         "confidence": {"bias": 1.0, "slope": 1.0, "position_m": 0.1, "rotation_deg": 2.0, "min_valid": 0.08}}


def bundle(tmp_path, **changes):
    doc = json.loads(json.dumps(GATES))
    for (section, key), value in changes.items():
        doc[section][key] = value
    folder = tmp_path / "bundle"
    folder.mkdir()
    (folder / "bundle.json").write_text(json.dumps(doc))
    (folder / "flip.onnx").write_bytes(b"graph")
    return folder


def pose(margin, *, e_t=0.05, e_r=1.0, prob=0.5, chamfer=1.2, confidence=0.5):
    """A row with the gates open: its outline fit, the classifier's probability and its errors."""
    return {"valid": True, "e_t": e_t, "e_R": e_r, "e_R_sym": min(e_r, 180.0 - e_r), "confidence": confidence,
            "flip_prob": prob, "outline_chamfer_px": chamfer, "outline_margin_px": margin,
            "outline_image_score": float("nan"), "outline_image_background": 0.0, "outline_image_pixels": 0.0,
            "depth_tolerance_m": 0.3, "polish_deg": 0.5}


def rows():
    right = [pose(0.8) for _ in range(20)]          # kept once min_margin_px <= 0.8
    flip = [pose(0.35, e_r=179.0)]                   # a flip once min_margin_px <= 0.3
    wrong = [pose(0.6, e_t=0.8, e_r=3.0)]            # wrong (0.8 m) once min_margin_px <= 0.5
    floor = [pose(5.0, e_r=178.0, confidence=0.01)]  # a flip every gate keeps, under the confidence floor
    kept = [pose(2.0) for _ in range(10)]            # kept by every cell
    return right + flip + wrong + floor + kept + [{"valid": False}]


def test_rule_on_known_rows(tmp_path):
    b = bundle(tmp_path)
    gates, fixed, floor = reference_gates(b)
    assert gates["image_margin"] == 0.1 and gates["flip_chamfer"] == 1.5 and floor == 0.08
    assert fixed["max_depth_tolerance_m"] == 1.0 and fixed["image_pixels"] == 16
    choice = choose(rows(), b)
    assert choice.reference["within"] == 10 and choice.reference["flips"] == 0 and choice.reference["wrong"] == 0
    assert choice.chosen["within"] == 30 and choice.chosen["wrong"] == 0 and choice.chosen["flips"] == 0
    # 0.7 is the loosest margin without the wrong pose; nothing else moves (the nearest cell to the reference)
    assert choice.changed == {"min_margin_px": (1.0, 0.7)} and not choice.classifier_may_loosen
    assert all(r["flips"] == 0 and r["wrong"] == 0 and r["min_margin_px"] >= 0.7 for r in choice.top)
    # the classifier's gates never loosened on few rows
    assert all(r["decide_prob"] >= 0.995 and r["veto_prob"] >= 0.05 and r["flip_chamfer"] <= 1.5 for r in choice.top)


def test_flip_neighbours_and_classifier_rows(tmp_path):
    b = bundle(tmp_path)
    data = [r for r in rows() if r.get("e_t") != 0.8]            # no wrong pose: only the flip at margin 0.35
    choice = choose(data, b)
    # 0.3 keeps the flip; 0.4 is its grid neighbour, so 0.5 is the loosest safe margin... and the nearest to 1.0
    # among the cells with all 20 right poses is 0.7
    assert choice.chosen["min_margin_px"] == 0.7
    assert not any(r["min_margin_px"] <= 0.4 for r in choice.top)
    # poses the classifier would decide at 0.97: only taken when there are enough rows
    sure = data + [pose(0.1, prob=0.98) for _ in range(30)]
    assert choose(sure, b).chosen["decide_prob"] == 0.995
    loose = choose(sure, b, classifier_rows=10)
    assert loose.classifier_may_loosen and loose.chosen["decide_prob"] == 0.97 and loose.chosen["within"] == 60


def test_small_gains_keep_the_reference_and_errors(tmp_path):
    b = bundle(tmp_path)
    few = [pose(0.8)] + [pose(2.0) for _ in range(40)]           # one more within: 41 against 40 (2.5 %)
    choice = choose(few, b)
    assert choice.chosen["min_margin_px"] == 1.0 and choice.changed == {}
    assert choose(few, b, min_gain=0.0).chosen["min_margin_px"] == 0.7
    assert choice.chosen_safe
    # on fewer rows than margin_rows the outline margin only tightens (session 37: 0.2 px let a flip through)
    held = choose(few, b, min_gain=0.0, margin_rows=4000)
    assert not held.margin_may_loosen and held.chosen["min_margin_px"] == 1.0
    assert all(r["min_margin_px"] >= 1.0 for r in held.top)
    # another graph's rows with a wrong pose every cell but the strictest keeps: nothing safe gains, the reference's
    # gates stay, and the choice says they are not safe for this graph
    bad = [pose(2.0) for _ in range(10)] + [pose(2.0, e_t=0.9)]
    unsafe = choose(bad, b, reference_rows=[pose(2.0) for _ in range(10)])
    assert unsafe.reference["wrong"] == 0 and unsafe.chosen["wrong"] == 1 and not unsafe.chosen_safe
    assert unsafe.changed == {}
    with pytest.raises(DatasetError, match="open rows"):
        choose([{"valid": False}], b)
    with pytest.raises(BundleError, match="not a bundle"):
        choose(rows(), tmp_path)
    other = tmp_path / "other"
    other.mkdir()
    (other / "bundle.json").write_text(json.dumps({"silhouette": GATES["silhouette"], "flip_classifier": {}}))
    with pytest.raises(BundleError, match="decide_prob"):
        reference_gates(other)


def test_candidate_bundle_and_cli(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(choose_gates, "GRID", SMALL)
    with pytest.raises(ValueError, match="must name the gates"):
        choose_gates.choose(rows(), tmp_path, grid={"min_margin_px": (1.0,)})
    b = bundle(tmp_path)
    path = tmp_path / "rows.json.gz"
    path.write_bytes(gzip.compress(json.dumps({"frames": rows()}).encode()))
    (tmp_path / "list.json").write_text(json.dumps(rows()))
    assert len(load_rows([path, tmp_path / "list.json"])) == 2 * len(rows())
    out, cand = tmp_path / "choice.json", tmp_path / "cand"
    assert main([str(path), "--bundle", str(b), "--out", str(out), "--write-bundle", str(cand),
                 "--margin-rows", "0"]) == 0
    assert "moved: {'min_margin_px': (1.0, 0.7)}" in capsys.readouterr().out
    assert json.loads(out.read_text())["chosen"]["min_margin_px"] == 0.7
    doc, old = json.loads((cand / "bundle.json").read_text()), json.loads((b / "bundle.json").read_text())
    assert doc["silhouette"]["min_margin_px"] == 0.7 and old["silhouette"]["min_margin_px"] == 1.0
    assert {k: v for k, v in doc["silhouette"].items() if k != "min_margin_px"} == {
        k: v for k, v in old["silhouette"].items() if k != "min_margin_px"}
    assert doc["flip_classifier"] == old["flip_classifier"] and (cand / "flip.onnx").read_bytes() == b"graph"
    with pytest.raises(BundleError, match="exists"):
        write_candidate(b, cand, choose(rows(), b))
    (tmp_path / "bad.json").write_text(json.dumps({"x": 1}))
    with pytest.raises(SystemExit, match="holds no rows"):
        main([str(tmp_path / "bad.json"), "--bundle", str(b)])
