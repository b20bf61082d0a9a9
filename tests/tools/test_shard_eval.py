"""shard_eval: slices, commands, compact floats, and the merged rows equal to one eval-pose over the same frames."""

from __future__ import annotations

import gzip
import json
import math
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))  # --import-mode=importlib: find the helpers
from _pose_fixtures import pose_dataset  # noqa: E402

from spacepose.errors import DatasetError  # noqa: E402
from spacepose.tools.shard_eval import compact, main, shard_commands, shard_eval, shard_slices, write_rows  # noqa: E402


@pytest.mark.parametrize("frames, workers", [(10, 3), (3, 8), (1, 1), (16, 16), (17, 4)])
def test_slices_cover_the_frames_once_in_order(frames, workers):
    slices = shard_slices(frames, workers)
    assert len(slices) == min(frames, workers) and all(n > 0 for _, n in slices)
    starts = [s for s, _ in slices]
    assert starts == sorted(starts) and starts[0] == 0
    assert [s + n for s, n in slices[:-1]] == starts[1:] and sum(n for _, n in slices) == frames
    assert max(n for _, n in slices) - min(n for _, n in slices) <= 1
    assert shard_slices(0, 4) == []
    with pytest.raises(ValueError):
        shard_slices(5, 0)


def test_commands_offset_by_skip(tmp_path):
    cmds = shard_commands(Path("D"), tmp_path, [(0, 5), (5, 4)], split="train", skip=100, bundle=Path("B"))
    assert len(cmds) == 2 and all(c[:3] == [sys.executable, "-m", "spacepose.cli"] for c in cmds)
    second = cmds[1]
    assert second[3:5] == ["eval-pose", "D"]
    assert second[second.index("--skip") + 1] == "105" and second[second.index("--limit") + 1] == "4"
    assert second[second.index("--threads") + 1] == "1" and second[second.index("--bundle") + 1] == "B"
    assert second[second.index("--out") + 1] == str(tmp_path / "shard_01")
    assert "--bundle" not in shard_commands(Path("D"), tmp_path, [(0, 1)], split="test", skip=0, bundle=None)[0]


def test_compact_and_deterministic_bytes(tmp_path):
    doc = {"a": 0.123456789, "b": [1.0e-9 / 3, float("nan"), 7, True, "x"], "c": {"d": 12345678.9}}
    small = compact(doc)
    assert small["a"] == 0.123457 and small["b"][0] == float(f"{1e-9 / 3:.6g}") and math.isnan(small["b"][1])
    assert small["b"][2:] == [7, True, "x"] and small["c"]["d"] == 12345700.0
    write_rows(doc, tmp_path / "one.json.gz")
    write_rows(doc, tmp_path / "two.json.gz")
    assert (tmp_path / "one.json.gz").read_bytes() == (tmp_path / "two.json.gz").read_bytes()   # no time stamp
    assert json.loads(gzip.decompress((tmp_path / "one.json.gz").read_bytes()))["a"] == 0.123457


@pytest.mark.slow
def test_merged_rows_equal_one_evaluation(tmp_path_factory, tmp_path):
    from spacepose.tools.eval_pose import evaluate_pose

    root = pose_dataset(tmp_path_factory)
    out = tmp_path / "rows.json.gz"
    doc = shard_eval(root, out, split="train", skip=1, workers=3, work=tmp_path / "work")
    whole = evaluate_pose(root, None, split="train", skip=1, overlays=0, threads=1)
    assert doc["workers"] == 3 and len(list((tmp_path / "work").glob("shard_*.log"))) == 3
    merged = json.loads(gzip.decompress(out.read_bytes()))
    assert [r["frame"] for r in merged["frames"]] == [r["frame"] for r in whole["frames"]]
    for got, want in zip(merged["frames"], whole["frames"]):
        assert got["status"] == want["status"] and got["valid"] == want["valid"]
        for key in ("e_t", "e_R", "confidence", "distance"):
            assert got[key] == pytest.approx(want[key], rel=1e-5, nan_ok=True)
    assert merged["overall"]["frames"] == len(whole["frames"]) and merged["split"] == "train"
    with pytest.raises(DatasetError, match="exists"):
        shard_eval(root, out, split="train", workers=2)
    with pytest.raises(DatasetError, match="no train frames"):
        shard_eval(root, tmp_path / "none.json.gz", split="train", skip=10_000)
    with pytest.raises(SystemExit, match="exists"):
        main([str(root), "--out", str(out)])
    with pytest.raises(DatasetError, match=r"shard 0 of 2 failed \(exit [1-9]"):     # a shard's error, not a hang
        shard_eval(root, tmp_path / "bad.json.gz", bundle=tmp_path / "no_bundle", split="train", limit=2, workers=2)
    assert not (tmp_path / "bad.json.gz").exists()
