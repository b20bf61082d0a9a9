"""Tests of spacepose.tools.dataset_card on a hand-made labels file."""

from __future__ import annotations

import json

import numpy as np
import pytest

from spacepose.errors import DatasetError
from spacepose.imageio import write_image
from spacepose.tools import dataset_card


def _make_dataset(root, n=12):
    (root / "left").mkdir(parents=True)
    rng = np.random.default_rng(0)
    regimes = ["sun", "albedo", "penumbra", "mixed"]
    with (root / "labels.jsonl").open("w") as fh:
        for i in range(n):
            name = f"{i:06d}"
            write_image(root / "left" / f"{name}.png", rng.integers(0, 255, (48, 64, 3), dtype=np.uint8))
            rec = {
                "frame": name,
                "split": "test" if i % 4 == 0 else "train",
                "R": np.eye(3).tolist(),
                "t": [0.0, 0.0, 10.0 + 3.0 * i],
                "q_wxyz": [1, 0, 0, 0],
                "regime": regimes[i % 4],
                "degradations": {"speckle": {"sigma": 0.1}} if i % 2 else {"gaussian_blur": {"sigma": 1.0}},
                "sun_dir": [0, 0, 1],
            }
            fh.write(json.dumps(rec) + "\n")


def test_summary_counts_and_camera_position(tmp_path):
    _make_dataset(tmp_path)
    labels = dataset_card.read_labels(tmp_path)
    summary = dataset_card.summarise(labels)
    assert summary["n_frames"] == 12
    assert summary["splits"]["test"]["n"] == 3
    assert summary["splits"]["train"]["regimes"] == {"albedo": 3, "mixed": 3, "penumbra": 3}
    assert sum(summary["splits"]["train"]["z_hist"]) == 9  # z 13..43, all inside 10..50 m
    # identity rotation, t = (0,0,z): camera sits at -z on the body z axis
    np.testing.assert_allclose(labels[1].camera_in_body, [0.0, 0.0, -13.0])
    assert "speckle" in dataset_card.format_summary(summary)


def test_plots_and_contact_sheets_written(tmp_path):
    _make_dataset(tmp_path / "ds")
    labels = dataset_card.read_labels(tmp_path / "ds")
    figs = dataset_card.plot_distributions(labels, tmp_path / "card")
    sheets = dataset_card.contact_sheets(tmp_path / "ds", labels, tmp_path / "card", per_regime=2)
    assert {p.name for p in figs} == {"fig11_distance.png", "fig12_camera_positions.png"}
    assert len(sheets) == 4 and all(p.stat().st_size > 0 for p in figs + sheets)


def test_bad_inputs(tmp_path):
    with pytest.raises(DatasetError, match="not a spacepose dataset"):
        dataset_card.read_labels(tmp_path)
    (tmp_path / "labels.jsonl").write_text('{"frame": "a"}\n')
    with pytest.raises(DatasetError, match="malformed"):
        dataset_card.read_labels(tmp_path)
    (tmp_path / "labels.jsonl").write_text("\n")
    with pytest.raises(DatasetError, match="no frames"):
        dataset_card.read_labels(tmp_path)
