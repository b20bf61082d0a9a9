"""restyle: a photometric copy of a dataset that keeps every label and never touches its source."""

import json

import numpy as np
import pytest

from spacepose.errors import DatasetError
from spacepose.imageio import read_image
from spacepose.tools.restyle import apply_style, main, restyle_dataset, sample_style


def test_style_bounds_and_identity():
    rng = np.random.default_rng(0)
    styles = [sample_style(rng, 1280) for _ in range(200)]
    assert all(0.5 <= s["gamma"] <= 2.0 and 0.6 <= s["gain"] <= 1.6 and 0.0 <= s["blur_px"] <= 2.4 for s in styles)
    assert max(s["blur_px"] for s in styles) > 1.2           # blur scales with the width
    image = np.random.default_rng(1).integers(0, 256, size=(20, 30, 3), dtype=np.uint8)
    identity = {"gamma": 1.0, "tint": [1.0, 1.0, 1.0], "gain": 1.0, "blur_px": 0.0, "noise": 0.0}
    np.testing.assert_array_equal(apply_style(image, identity, rng), image)
    dark = apply_style(image, {**identity, "gamma": 2.0}, rng)
    assert dark.mean() < image.mean() and dark.shape == image.shape and dark.dtype == np.uint8
    grey = apply_style(image[..., 0], {**identity, "gain": 0.5}, rng)
    np.testing.assert_allclose(grey, np.round(image[..., 0] * 0.5), atol=1)
    with pytest.raises(DatasetError):
        apply_style(image.astype(np.float32), identity, rng)


def test_restyle_copies_labels_and_geometry(synthetic_dataset, tmp_path):
    before = {p: p.read_bytes() for p in synthetic_dataset.rglob("*") if p.is_file()}
    dst = tmp_path / "restyled"
    assert restyle_dataset(synthetic_dataset, dst, seed=3, split="test") == 4
    src_lines = [json.loads(l) for l in (synthetic_dataset / "labels.jsonl").read_text().splitlines()]
    lines = [json.loads(l) for l in (dst / "labels.jsonl").read_text().splitlines()]
    assert [l["frame"] for l in lines] == [l["frame"] for l in src_lines if l["split"] == "test"]
    for line in lines:
        src_line = next(l for l in src_lines if l["frame"] == line["frame"])
        assert line["R"] == src_line["R"] and line["t"] == src_line["t"] and "gamma" in line["restyle"]
        name = line["frame"] + ".png"
        for view in ("left", "right"):
            a, b = read_image(synthetic_dataset / view / name), read_image(dst / view / name)
            assert a.shape == b.shape and not np.array_equal(a, b)
        assert (dst / "disparity" / (line["frame"] + ".pfm")).read_bytes() == \
            (synthetic_dataset / "disparity" / (line["frame"] + ".pfm")).read_bytes()
    assert (dst / "rig.yaml").read_bytes() == (synthetic_dataset / "rig.yaml").read_bytes()
    assert json.loads((dst / "dataset.json").read_text())["restyled_from"]["seed"] == 3
    assert {p: p.read_bytes() for p in synthetic_dataset.rglob("*") if p.is_file()} == before
    # the same seed gives the same copy; an existing copy is kept without --force
    with pytest.raises(DatasetError, match="exists"):
        restyle_dataset(synthetic_dataset, dst, seed=3)
    again = tmp_path / "again"
    assert main([str(synthetic_dataset), str(again), "--seed", "3", "--split", "test"]) == 0
    assert (again / "left" / "000006.png").read_bytes() == (dst / "left" / "000006.png").read_bytes()
    with pytest.raises(SystemExit, match="overwrite its source"):
        main([str(synthetic_dataset), str(synthetic_dataset), "--seed", "1", "--force"])
    with pytest.raises(SystemExit, match="not a dataset"):
        main([str(tmp_path), str(tmp_path / "x"), "--seed", "1"])
