"""open_gates: an open copy of a bundle (gates open, registration decision closed, no floor); the source untouched."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from spacepose.bundle import DEFAULT_BUNDLE_DIR, load_bundle
from spacepose.errors import BundleError
from spacepose.tools.open_gates import OPEN_GATES, main, write_open_bundle


def test_open_copy_of_the_default_bundle(tmp_path):
    src = Path(DEFAULT_BUNDLE_DIR)
    before = (src / "bundle.json").read_bytes()
    dst = write_open_bundle(src, tmp_path / "open")
    assert (src / "bundle.json").read_bytes() == before                  # nothing the user gave is changed
    doc, orig = json.loads((dst / "bundle.json").read_text()), json.loads(before)
    for section, values in OPEN_GATES.items():
        for key, value in values.items():
            assert doc[section][key] == value
        untouched = {k: v for k, v in orig[section].items() if k not in values}
        assert {k: doc[section][k] for k in untouched} == untouched
    assert "min_valid" in orig["confidence"] and "min_valid" not in doc["confidence"]
    assert {k: v for k, v in doc["confidence"].items()} == {k: v for k, v in orig["confidence"].items()
                                                              if k != "min_valid"}
    for name in ("stereo.onnx", "pose.onnx", "flip.onnx"):
        assert (dst / name).read_bytes() == (src / name).read_bytes()
    model = load_bundle(dst)                                             # a valid bundle, gates open
    assert model.silhouette.max_chamfer_px == 100.0 and model.flip_classifier.decide_prob == 2.0
    assert model.confidence.min_valid == 0.0 and model.registration.min_margin == 0.99


def test_refuses_to_overwrite_or_to_open_a_non_bundle(tmp_path):
    (tmp_path / "taken").mkdir()
    with pytest.raises(BundleError, match="exists"):
        write_open_bundle(DEFAULT_BUNDLE_DIR, tmp_path / "taken")
    with pytest.raises(BundleError, match="not a bundle"):
        write_open_bundle(tmp_path / "taken", tmp_path / "x")
    (tmp_path / "bare").mkdir()
    (tmp_path / "bare" / "bundle.json").write_text(json.dumps({"silhouette": {}}))
    with pytest.raises(BundleError, match="flip_classifier, registration"):
        write_open_bundle(tmp_path / "bare", tmp_path / "y")
    assert not (tmp_path / "y").exists()
    with pytest.raises(SystemExit, match="exists"):
        main([str(DEFAULT_BUNDLE_DIR), str(tmp_path / "taken")])
