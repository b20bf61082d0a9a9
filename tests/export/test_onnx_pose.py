"""Pose-net ONNX export: single file, metadata contract, torch vs onnxruntime parity, bundle.json."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("onnx")
pytest.importorskip("onnxruntime")

from spacepose.errors import SpaceposeError  # noqa: E402
from spacepose.export.onnx_pose import (export_checkpoint, example_feeds, pose_metadata,  # noqa: E402
                                        write_pose_manifest)
from spacepose.models.pose_config import PoseNetConfig  # noqa: E402
from spacepose.models.pose_net import PoseNet  # noqa: E402
from spacepose.onnx_session import read_metadata  # noqa: E402
from spacepose.pose_inputs import pose_input_names  # noqa: E402

NET = PoseNetConfig(crop_size=(64, 64), n_points=128, k=8, n_levels=2, ratio=4, rgb_stem=8, rgb_widths=(16, 16),
                    rgb_bottleneck=16, rgb_out=8, point_stem=8, point_widths=(16, 16), point_bottleneck=16, head_width=16)
KP = np.random.default_rng(0).uniform(-2, 2, size=(8, 3))
GEOMETRY = {"mesh_scale": 1.0, "radius": 3.0, "bbox_min": [-2.5, -1.5, -0.3], "bbox_max": [2.5, 1.5, 1.0]}


@pytest.fixture(scope="module")
def checkpoint(tmp_path_factory) -> Path:
    torch.manual_seed(0)
    model = PoseNet(NET)
    path = tmp_path_factory.mktemp("ckpt") / "last.pt"
    torch.save({"kind": "pose", "model": model.state_dict(), "net_config": json.loads(json.dumps(dataclasses.asdict(NET))),
                "keypoints": KP.tolist(), "centre": [0.0, 0.0, 0.1], "target": "tdrs", "step": 7, "commit": "abc",
                "dataset": {"seed": 3, "size": 8, "distance_range_m": [10.0, 20.0]},
                "train_config": {"batch": 2, "depth_source": "gt_noisy"}}, path)
    return path


@pytest.fixture(scope="module")
def exported(checkpoint, tmp_path_factory):
    out = tmp_path_factory.mktemp("bundle") / "pose.onnx"
    return export_checkpoint(checkpoint, out, geometry=GEOMETRY)


def test_single_file_and_parity(exported):
    path = Path(exported["path"])
    assert sorted(p.name for p in path.parent.iterdir()) == ["bundle.json", "pose.onnx"]
    parity = exported["parity"]
    print(f"pose parity torch vs onnxruntime: {parity}")
    assert set(parity) == {"seg_logits", "kp_offsets", "ctr_offsets", "max"}
    assert parity["max"] < 1e-4
    import onnx

    ops = {n.op_type for n in onnx.load(str(path)).graph.node}
    assert not ops & {"ScatterND", "GridSample"}
    assert onnx.load(str(path)).opset_import[0].version == 17


def test_metadata_contract(exported):
    meta = read_metadata(exported["path"])
    assert meta["kind"] == "pose" and meta["target"] == "tdrs" and meta["n_keypoints"] == 8
    assert meta["n_points"] == 128 and meta["crop_size"] == [64, 64] and meta["k"] == 8 and meta["n_levels"] == 2
    np.testing.assert_allclose(meta["keypoints"], KP)
    assert meta["dataset"]["seed"] == 3 and meta["dataset"]["size"] == 8 and meta["training_commit"] == "abc"
    assert set(meta["inputs"]) == set(pose_input_names(2))
    assert meta["config"]["fusion"] == "both"


def test_bundle_manifest_pose_side(exported, tmp_path):
    data = json.loads(Path(exported["manifest"]).read_text())
    assert data["pose"]["n_points"] == 128 and data["pose"]["crop_size"] == [64, 64] and data["pose"]["offset_sign"] == 1
    assert data["target"]["name"] == "tdrs" and data["target"]["radius"] == 3.0
    assert data["distance_range_m"] == [10.0, 20.0]
    # merging keeps foreign sections
    (tmp_path / "bundle.json").write_text(json.dumps({"stereo": {"file": "stereo.onnx"}, "rig": {"focal_px": 1}}))
    write_pose_manifest(tmp_path, net_config=NET, keypoints=KP, centre=np.zeros(3), target="tdrs")
    merged = json.loads((tmp_path / "bundle.json").read_text())
    assert merged["stereo"] == {"file": "stereo.onnx"} and merged["rig"] == {"focal_px": 1} and "pose" in merged


def test_never_overwrites_without_force(checkpoint, exported):
    with pytest.raises(SpaceposeError, match="force"):
        export_checkpoint(checkpoint, exported["path"])


def test_metadata_rejects_wrong_keypoint_count():
    with pytest.raises(SpaceposeError, match="keypoints"):
        pose_metadata(NET, keypoints=KP[:5], centre=np.zeros(3), target="tdrs")


def test_example_feeds_match_graph_inputs():
    feeds = example_feeds(NET.input_spec())
    assert list(feeds) == pose_input_names(2)
    out = PoseNet(NET).eval().forward_dict(feeds)
    assert tuple(out["kp_offsets"].shape) == (1, 8, 128, 3)


def test_cli_export_pose(checkpoint, tmp_path, capsys):
    import argparse

    from spacepose.export import cli_export_pose

    parser = argparse.ArgumentParser()
    cli_export_pose.add_arguments(parser)
    args = parser.parse_args([str(checkpoint), "--out", str(tmp_path / "p.onnx"), "--no-manifest"])
    assert cli_export_pose.run(args) == 0
    text = capsys.readouterr().out
    assert "parity torch vs onnxruntime" in text and (tmp_path / "p.onnx").is_file()
    assert not (tmp_path / "bundle.json").exists()
