"""Dataset writer: layout, labels, determinism across shards, resume, refusal of foreign folders."""

from __future__ import annotations

import json
from collections import Counter

import numpy as np
import pytest

from spacepose.calibration.rig import load_rig, paper_rig
from spacepose.cli import main
from spacepose.errors import DatasetError
from spacepose.imageio import read_image, read_pfm
from spacepose.tools.dataset import (
    FRAME_FILES,
    MANIFEST,
    RenderConfig,
    frame_complete,
    parse_shard,
    regime_of,
    render_dataset,
    require_depth,
    split_of,
    stores_depth,
)
from spacepose.tools.targets import TargetError

SIZE = (160, 120)


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    root = tmp_path_factory.mktemp("render") / "ds"
    summary = render_dataset(root, RenderConfig(count=10, size=SIZE, seed=7), workers=1)
    return root, summary


class TestLayout:
    def test_files_and_labels(self, dataset):
        root, summary = dataset
        assert summary["rendered"] == 10 and summary["labels"] == 10
        lines = [json.loads(line) for line in (root / "labels.jsonl").read_text().splitlines()]
        assert [line["frame"] for line in lines] == [f"{i:06d}" for i in range(10)]
        w, h = SIZE
        for label in lines:
            name = label["frame"]
            assert frame_complete(root, name)
            left, right = read_image(root / "left" / f"{name}.png"), read_image(root / "right" / f"{name}.png")
            assert left.shape == right.shape == (h, w, 3) and left.dtype == np.uint8
            mask = read_image(root / "mask" / f"{name}.png") > 0
            disparity = read_pfm(root / "disparity" / f"{name}.pfm")
            depth = read_pfm(root / "depth" / f"{name}.pfm")
            np.testing.assert_array_equal(disparity > 0, mask)
            fx = 1600 * w / 1280
            np.testing.assert_allclose(disparity[mask], fx * 1.0 / depth[mask], rtol=1e-5)
            assert mask.sum() == label["mask_pixels"] > 0
            R = np.array(label["R"])
            np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-9)
            assert 10 <= label["t"][2] <= 50
            assert label["regime"] in ("sun", "albedo", "penumbra", "mixed")
            assert label["degradations"] and label["split"] in ("train", "test")
            assert len(label["sun_dir"]) == 3 and len(label["q_wxyz"]) == 4
        assert Counter(line["split"] for line in lines)["test"] == 1

    def test_rig_and_manifest(self, dataset):
        root, _ = dataset
        assert load_rig(root / "rig.yaml").allclose(paper_rig(*SIZE))
        manifest = json.loads((root / MANIFEST).read_text())
        assert manifest["target"] == "tdrs" and manifest["seed"] == 7 and manifest["count"] == 10 and manifest["size"] == list(SIZE)


class TestDeterminism:
    def test_shards_render_the_same_frames(self, dataset, tmp_path):
        root, _ = dataset
        other = tmp_path / "sharded"
        config = RenderConfig(count=10, size=SIZE, seed=7)
        first = render_dataset(other, config, shard=(2, 3), workers=1)
        assert first["rendered"] == 3 and first["labels"] == 3
        for k in (1, 3):
            render_dataset(other, config, shard=(k, 3), workers=1)
        for folder in FRAME_FILES:
            for i in range(10):
                name = f"{i:06d}{FRAME_FILES[folder]}"
                assert (other / folder / name).read_bytes() == (root / folder / name).read_bytes(), (folder, name)
        assert (other / "labels.jsonl").read_text() == (root / "labels.jsonl").read_text()

    def test_resume_skips_complete_frames_and_redoes_broken_ones(self, dataset):
        root, _ = dataset
        before = (root / "left" / "000004.png").read_bytes()
        (root / "meta" / "000004.json").unlink()  # as if killed while writing frame 4
        summary = render_dataset(root, RenderConfig(count=10, size=SIZE, seed=7), workers=1)
        assert summary["rendered"] == 1 and summary["skipped"] == 9 and summary["labels"] == 10
        assert (root / "left" / "000004.png").read_bytes() == before

    def test_split_is_exactly_9_to_1_and_regimes_equal(self):
        splits = Counter(split_of(3, i) for i in range(1000))
        assert splits == {"train": 900, "test": 100}
        regimes = Counter(regime_of(3, i) for i in range(1000))
        assert set(regimes.values()) == {250}


class TestNoDepth:
    """``--no-depth``: the same frames without ``depth/``, recorded in the manifest, kept on resume."""

    def test_same_frames_without_depth_maps(self, dataset, tmp_path):
        root, _ = dataset
        other = tmp_path / "nodepth"
        summary = render_dataset(other, RenderConfig(count=10, size=SIZE, seed=7, depth_maps=False), workers=1)
        assert summary["rendered"] == 10 and summary["labels"] == 10
        assert not (other / "depth").exists() and not (other / "depth").is_dir()
        for folder in FRAME_FILES:
            if folder == "depth":
                continue
            for i in range(10):
                name = f"{i:06d}{FRAME_FILES[folder]}"
                assert (other / folder / name).read_bytes() == (root / folder / name).read_bytes(), (folder, name)
        assert (other / "labels.jsonl").read_text() == (root / "labels.jsonl").read_text()
        assert json.loads((other / MANIFEST).read_text())["depth_maps"] is False
        assert "depth_maps" not in json.loads((root / MANIFEST).read_text())   # old manifests unchanged
        assert stores_depth(root) and not stores_depth(other)
        require_depth(root)
        with pytest.raises(DatasetError, match="--no-depth"):
            require_depth(other)
        # a frame is complete without its depth map, and resuming renders nothing
        assert frame_complete(other, "000003", depth_maps=False) and not frame_complete(other, "000003")
        again = render_dataset(other, RenderConfig(count=10, size=SIZE, seed=7, depth_maps=False), workers=1)
        assert again["rendered"] == 0 and again["skipped"] == 10 and again["labels"] == 10

    def test_resume_must_match_the_option(self, dataset, tmp_path):
        root, _ = dataset
        with pytest.raises(DatasetError, match="depth_maps"):
            render_dataset(root, RenderConfig(count=10, size=SIZE, seed=7, depth_maps=False), workers=1)
        other = tmp_path / "nd"
        render_dataset(other, RenderConfig(count=2, size=SIZE, seed=7, depth_maps=False), workers=1)
        with pytest.raises(DatasetError, match="depth_maps"):
            render_dataset(other, RenderConfig(count=2, size=SIZE, seed=7), workers=1)
        assert not (other / "depth").exists()

    def test_cli_flag(self, tmp_path, capsys):
        root = tmp_path / "cli_nd"
        assert main(["render", str(root), "--count", "2", "--size", "160x120", "--seed", "1", "--workers", "1",
                     "--no-depth"]) == 0
        assert len((root / "labels.jsonl").read_text().splitlines()) == 2
        assert not (root / "depth").exists() and len(list((root / "disparity").glob("*.pfm"))) == 2

    def test_photometric_calibration_refuses_a_set_without_depth(self, tmp_path):
        from spacepose.tools.calibrate_photo import score_frames

        root = tmp_path / "photo_nd"
        render_dataset(root, RenderConfig(count=2, size=SIZE, seed=7, depth_maps=False), workers=1)
        with pytest.raises(DatasetError, match="--no-depth"):
            score_frames(root, None, "train", 1)


class TestBadInput:
    def test_foreign_folder(self, tmp_path):
        (tmp_path / "holiday.jpg").write_bytes(b"x")
        with pytest.raises(DatasetError, match="not empty"):
            render_dataset(tmp_path, RenderConfig(count=2, size=SIZE), workers=1)
        assert not (tmp_path / MANIFEST).exists()

    def test_other_dataset(self, dataset):
        root, _ = dataset
        with pytest.raises(DatasetError, match="another dataset"):
            render_dataset(root, RenderConfig(count=10, size=SIZE, seed=8), workers=1)
        with pytest.raises(DatasetError, match="another dataset"):
            render_dataset(root, RenderConfig(target="mro", count=10, size=SIZE, seed=7), workers=1)

    def test_missing_or_corrupt_mesh(self, tmp_path):
        with pytest.raises(TargetError):
            render_dataset(tmp_path / "a", RenderConfig(target=str(tmp_path / "none.stl"), count=2, size=SIZE), workers=1)
        bad = tmp_path / "bad.stl"
        bad.write_bytes(b"garbage")
        with pytest.raises(TargetError):
            render_dataset(tmp_path / "b", RenderConfig(target=str(bad), count=2, size=SIZE), workers=1)
        assert not (tmp_path / "a").exists() and not (tmp_path / "b").exists()

    def test_depth_range_that_cannot_fit(self, tmp_path):
        with pytest.raises(DatasetError, match="cannot fit"):
            render_dataset(tmp_path / "c", RenderConfig(count=2, size=SIZE, depth_range=(3.0, 6.0)), workers=1)

    @pytest.mark.parametrize("text", ["0/4", "5/4", "1-4", "a/b"])
    def test_bad_shard(self, text):
        with pytest.raises(DatasetError, match="shard"):
            parse_shard(text)

    def test_bad_config(self):
        with pytest.raises(DatasetError):
            RenderConfig(count=0)


class TestCli:
    def test_render_with_workers_and_mro(self, tmp_path, capsys):
        root = tmp_path / "cli"
        rc = main(["render", str(root), "--target", "mro", "--count", "4", "--size", "160x120", "--seed", "1", "--workers", "2"])
        assert rc == 0
        assert len((root / "labels.jsonl").read_text().splitlines()) == 4
        assert "rendered 4" in capsys.readouterr().out

    def test_errors_are_clear(self, tmp_path, capsys):
        assert main(["render", str(tmp_path / "x"), "--target", str(tmp_path / "missing.stl"), "--count", "2"]) == 2
        assert "not found" in capsys.readouterr().err
        assert main(["render", str(tmp_path / "y"), "--count", "2", "--depth", "2", "4"]) == 2
        assert "cannot fit" in capsys.readouterr().err
        assert main(["render", str(tmp_path / "z"), "--count", "2", "--shard", "3/2"]) == 2
