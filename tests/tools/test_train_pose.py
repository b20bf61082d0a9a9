"""train_pose: a few steps on a tiny rendered dataset, checkpoint/resume, cyclic LR, CLI parsing."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import pytest

torch = pytest.importorskip("torch")
sys.path.insert(0, str(Path(__file__).resolve().parent))  # --import-mode=importlib: find the helpers
from _pose_fixtures import pose_dataset, train_tiny  # noqa: E402

from spacepose.errors import SpaceposeError  # noqa: E402
from spacepose.tools.train_pose import (TrainPoseConfig, cyclic_scheduler, load_checkpoint,  # noqa: E402
                                        model_from_checkpoint, train_pose)


def test_cyclic_lr_three_cycles():
    opt = torch.optim.Adam([torch.nn.Parameter(torch.zeros(1))], lr=1e-5)
    sched = cyclic_scheduler(opt, steps=60, lr_min=1e-5, lr_max=1e-3, cycles=3)
    lrs = []
    for _ in range(60):
        lrs.append(sched.get_last_lr()[0])
        opt.step()
        sched.step()
    assert lrs[0] == pytest.approx(1e-5)
    peaks = [i for i in range(1, 59) if lrs[i] > lrs[i - 1] and lrs[i] > lrs[i + 1] or lrs[i] == pytest.approx(1e-3)]
    assert peaks == [10, 30, 50]
    assert max(lrs) == pytest.approx(1e-3) and lrs[20] == pytest.approx(1e-5) and lrs[40] == pytest.approx(1e-5)


def test_train_resume_and_checkpoint(tmp_path_factory, tmp_path):
    root = pose_dataset(tmp_path_factory)
    out = tmp_path / "run"
    ckpt_path = train_tiny(root, out, steps=2)
    ckpt = load_checkpoint(ckpt_path)
    assert ckpt["step"] == 2 and ckpt["kind"] == "pose" and len(ckpt["keypoints"]) == 8
    assert {"model", "optimizer", "scheduler", "rng", "net_config", "input_spec", "dataset"} <= set(ckpt)
    log = [json.loads(l) for l in (out / "log.jsonl").read_text().splitlines()]
    assert [e["step"] for e in log if "loss" in e] == [1, 2]
    assert all(e["loss"] == e["loss"] for e in log if "loss" in e)  # finite, not NaN
    cfg_doc = json.loads((out / "config.json").read_text())
    assert cfg_doc["train"]["depth_source"] == "gt_noisy" and cfg_doc["net"]["n_points"] == 128

    # a second run into the same folder needs --resume; resuming continues the step count
    with pytest.raises(SpaceposeError, match="resume"):
        train_tiny(root, out, steps=3)
    cfg = TrainPoseConfig(**{**json.loads((out / "config.json").read_text())["train"], "steps": 3})
    summary = train_pose(cfg, resume=True)
    assert summary["step"] == 3
    assert load_checkpoint(ckpt_path)["step"] == 3
    model, net_cfg = model_from_checkpoint(load_checkpoint(ckpt_path))
    assert net_cfg.n_points == 128 and not model.training
    with pytest.raises(SpaceposeError, match="differs"):
        train_pose(TrainPoseConfig(**{**cfg.__dict__, "steps": 4, "fusion": "none"}), resume=True)


def test_cli_arguments():
    from spacepose.tools import cli_train_pose

    parser = argparse.ArgumentParser()
    cli_train_pose.add_arguments(parser)
    args = parser.parse_args(["DS", "--steps", "5", "--depth-source", "gt_noisy", "--fusion", "rgb2pt",
                              "--attention", "vanilla", "--net", "n_points=256", "--net", "crop_size=[64,64]", "--resume"])
    assert args.steps == 5 and args.batch == 8 and args.workers == 1 and args.resume
    assert dict(args.net) == {"n_points": 256, "crop_size": [64, 64]}
    cfg = TrainPoseConfig(dataset="DS", out="o", net=dict(args.net), fusion=args.fusion, attention=args.attention)
    net = cfg.net_config()
    assert net.crop_size == (64, 64) and net.fusion == "rgb2pt" and net.attention == "vanilla"


@pytest.mark.slow
def test_init_from_a_shipped_graph_fine_tunes_with_frozen_batchnorm(tmp_path_factory, tmp_path):
    """train -> export -> recover-checkpoint -> train-pose --init: the BatchNorms (folded identities)
    keep their statistics through fine-tuning and its resume; the other weights move."""
    from spacepose.export.onnx_pose import export_checkpoint
    from spacepose.export.recover import checkpoint_from_graph
    from spacepose.tools.training_common import atomic_save

    root = pose_dataset(tmp_path_factory)
    base = train_tiny(root, tmp_path / "base", steps=1)
    graph = export_checkpoint(base, tmp_path / "pose.onnx", geometry={"mesh_scale": 1.0, "radius": 2.6,
                                                                       "bbox_min": [-2.5, -1.5, -0.3],
                                                                       "bbox_max": [2.5, 1.5, 1.0]})["path"]
    recovered = checkpoint_from_graph(graph)
    assert recovered["folded_bn"] and recovered["step"] == 1
    init = tmp_path / "recovered.pt"
    atomic_save(recovered, init)
    out = tmp_path / "ft"
    train_tiny(root, out, steps=2, init=str(init))
    ckpt = load_checkpoint(out / "last.pt")
    assert ckpt["folded_bn"] == recovered["folded_bn"]
    stats = [k for k in recovered["model"] if k.endswith("running_mean") or k.endswith("running_var")]
    assert stats and all(torch.equal(ckpt["model"][k], recovered["model"][k]) for k in stats)
    moved = [k for k in recovered["model"] if k.endswith("weight") and not torch.equal(ckpt["model"][k], recovered["model"][k])]
    assert moved
    cfg = TrainPoseConfig(**{**json.loads((out / "config.json").read_text())["train"], "steps": 3})
    train_pose(cfg, resume=True)
    again = load_checkpoint(out / "last.pt")
    assert again["step"] == 3 and all(torch.equal(again["model"][k], recovered["model"][k]) for k in stats)
    bad = TrainPoseConfig(**{**cfg.__dict__, "out": str(tmp_path / "bad"), "net": {**cfg.net, "head_width": 8}})
    with pytest.raises(SpaceposeError, match="differs"):
        train_pose(bad)


def test_symmetric_flip_training_and_its_validation_metric(tmp_path_factory, tmp_path):
    from spacepose.tools.pose_data import PoseDataConfig, PoseDataset
    from spacepose.tools.train_pose import validate_pose
    from spacepose.models.pose_loss import PoseLossConfig

    root = pose_dataset(tmp_path_factory)
    out = tmp_path / "sym"
    ckpt_path = train_tiny(root, out, steps=2, symmetric_flip="z")
    doc = json.loads((out / "config.json").read_text())
    assert doc["train"]["symmetric_flip"] == "z"
    cfg = TrainPoseConfig(**{**doc["train"], "steps": 3, "symmetric_flip": None})
    with pytest.raises(SpaceposeError, match="symmetric_flip"):
        train_pose(cfg, resume=True)
    model, net_cfg = model_from_checkpoint(load_checkpoint(ckpt_path))
    val = PoseDataset(root, "test", net_cfg.input_spec(), PoseDataConfig(depth_source="gt_noisy", augment=False),
                      limit=1, deterministic=True, radius_m=2.6)
    metrics = validate_pose(model, val, torch.device("cpu"), PoseLossConfig(offset_scale=net_cfg.xyz_scale), "z")
    assert "val_e_R_flip_median" in metrics
    assert "val_e_R_flip_median" not in validate_pose(model, val, torch.device("cpu"),
                                                      PoseLossConfig(offset_scale=net_cfg.xyz_scale))


def test_keypoint_floor_reference_predictors(tmp_path_factory, tmp_path):
    import numpy as np

    from spacepose.tools.keypoint_floor import _kp_l1, keypoint_floor

    root = pose_dataset(tmp_path_factory)
    ckpt = train_tiny(root, tmp_path / "kf", steps=1)
    result = keypoint_floor(root, checkpoint=ckpt, frames=3)
    assert set(result) == {"centre_only", "flip_x", "flip_y", "flip_z", "network", "frames"}
    assert result["frames"] >= 1 and all(np.isfinite(v) and v > 0 for v in result.values())
    target = np.random.default_rng(0).normal(size=(8, 20, 3))
    mask = np.ones(20, dtype=bool)
    assert _kp_l1(target, target, mask, 2.5) == 0.0
    assert _kp_l1(target + 1.0, target, mask, 2.5) == pytest.approx(8 * 3 / 2.5)
