"""Tests of spacepose.tools.flip_data, spacepose.tools.train_flip and spacepose.export.onnx_flip."""

import dataclasses
import json
import sys
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "runtime"))  # the runtime tests' bundle helpers

from spacepose.cli import main  # noqa: E402
from spacepose.flip import flipped_pose  # noqa: E402
from spacepose.flip_views import view_frame  # noqa: E402
from spacepose.silhouette import splat_mask  # noqa: E402
from spacepose.tools.flip_data import (FlipSampleConfig, augment_views, load_samples, make_flip_samples,  # noqa: E402
                                       perturb_pose, save_samples, stereo_window, wrong_pose)
from spacepose.registration import rotation_angle_deg  # noqa: E402


def _plate_points(seed=0):
    """The synthetic dataset's target stand-in: a plate with a tab on +x (its z flip puts the tab on -x)."""
    rng = np.random.default_rng(seed)
    body = np.stack([rng.uniform(-1.0, 1.0, 3000), rng.uniform(-0.6, 0.6, 3000), np.zeros(3000)], 1)
    tab = np.stack([rng.uniform(1.0, 1.5, 600), rng.uniform(-0.15, 0.15, 600), np.zeros(600)], 1)
    return np.vstack([body, tab])


def test_exact_samples_put_the_true_outline_where_the_label_says(synthetic_dataset):
    from spacepose.calibration.rig import load_rig
    from spacepose.tools.labels import read_labels

    pts = _plate_points().astype(np.float32)
    exact = FlipSampleConfig(size=32, rot_sigma_deg=0.0, wide_prob=0.0, lateral_sigma_m=0.0, range_sigma_m=0.0,
                             side_range=(1.0, 1.0), centre_jitter=0.0)
    s = make_flip_samples(synthetic_dataset, pts, np.zeros(3), split="train", per_frame=3, seed=0, config=exact)
    frames = read_labels(synthetic_dataset, "train", require=("R", "t"))
    K = load_rig(synthetic_dataset / "rig.yaml").M1
    assert s["views"].shape == (3 * len(frames), 3, 32, 32) and set(s["labels"]) <= {0.0, 1.0}
    assert 0 < s["labels"].sum() < len(s["labels"])
    for k in range(len(s["labels"])):
        rec = frames[s["frame"][k]]
        truth = (np.asarray(rec.R), np.asarray(rec.t))
        flip = flipped_pose(*truth, np.zeros(3), "z")
        slot_truth, slot_flip = (1, 2) if s["labels"][k] == 1.0 else (2, 1)
        # the window is the winner's (the truth or its flip, unperturbed here): one of the two holds
        matches = []
        for winner in (truth, flip):
            frame = view_frame(K, *stereo_window(pts, *winner, K, 1.0, None, exact), 32)
            matches.append(np.array_equal(s["views"][k, slot_truth], splat_mask(pts, *truth, frame)[0])
                           and np.array_equal(s["views"][k, slot_flip], splat_mask(pts, *flip, frame)[0]))
        assert any(matches), k
        assert (s["views"][k, 1] != s["views"][k, 2]).any()
    info = {"x": 1}
    save_samples(s, synthetic_dataset.parent / "flip.npz", info)
    back = load_samples(synthetic_dataset.parent / "flip.npz")
    np.testing.assert_array_equal(back["views"][:, 1:], s["views"][:, 1:])
    np.testing.assert_allclose(back["views"][:, 0], s["views"][:, 0], atol=2e-3)


def test_perturbation_and_augmentation_stay_in_their_bounds():
    rng = np.random.default_rng(0)
    R, t = np.eye(3), np.array([1.0, 0.0, 30.0])
    cfg = FlipSampleConfig()
    angles = [rotation_angle_deg(perturb_pose(R, t, rng, cfg)[0], R) for _ in range(300)]
    assert max(angles) < cfg.rot_wide_deg + 4 * cfg.rot_sigma_deg and np.median(angles) < 2 * cfg.rot_sigma_deg
    views = np.zeros((4, 3, 32, 32), np.float32)
    views[:, 0] = 1.0
    views[:, 1, 8:24, 8:24] = 1.0
    out = augment_views(views, rng)
    np.testing.assert_array_equal(out[:, 1:], views[:, 1:])
    assert out[:, 0].min() >= 0.0 and out[:, 0].max() <= 2.0 and not np.array_equal(out[:, 0], views[:, 0])


def test_wrong_poses_are_far_from_the_truth_and_its_flip_and_keep_the_centre_in_place():
    from spacepose.registration import exp_so3

    rng = np.random.default_rng(1)
    centre = np.array([0.1, -0.2, 0.35])
    for _ in range(200):
        R, t = exp_so3(rng.normal(size=3)), np.array([0.0, 0.0, 25.0]) + rng.normal(size=3)
        R2, t2 = wrong_pose(R, t, centre, "z", rng)
        np.testing.assert_allclose(R2 @ R2.T, np.eye(3), atol=1e-9)
        assert rotation_angle_deg(R2, R) >= 30.0 - 1e-6
        assert rotation_angle_deg(R2, flipped_pose(R, t, centre, "z")[0]) >= 30.0 - 1e-6
        np.testing.assert_allclose(R2 @ centre + t2, R @ centre + t, atol=1e-9)


def test_neither_samples_are_labelled_one_half(synthetic_dataset):
    pts = _plate_points().astype(np.float32)
    cfg = FlipSampleConfig(size=32, neither_prob=0.5)
    s = make_flip_samples(synthetic_dataset, pts, np.zeros(3), split="train", per_frame=8, seed=0, config=cfg)
    half = s["labels"] == 0.5
    assert 0 < half.sum() < len(half) and set(np.unique(s["labels"][~half])) <= {0.0, 1.0}
    plain = make_flip_samples(synthetic_dataset, pts, np.zeros(3), split="train", per_frame=8, seed=0,
                              config=FlipSampleConfig(size=32))
    assert not (plain["labels"] == 0.5).any()


def test_evaluate_reports_how_sure_it_is_when_neither_pose_is_right():
    from spacepose.tools.train_flip import evaluate

    class Fixed(torch.nn.Module):
        def __init__(self, logits):
            super().__init__()
            self.logits = torch.tensor(logits, dtype=torch.float32)

        def forward(self, views):
            return self.logits[views[:, 0, 0, 0].long()]

    logits = [5.0, -5.0, 6.0, 0.1, -9.0]     # samples 0-1 have a right pose, 2-4 none
    views = np.zeros((5, 3, 4, 4), np.float32)
    views[:, 0, 0, 0] = np.arange(5)
    labels = np.array([1.0, 1.0, 0.5, 0.5, 0.5], np.float32)
    out = evaluate(Fixed(logits), views, labels, np.array(["a"] * 5))
    assert out["all"]["n"] == 2 and out["all"]["accuracy"] == 0.5
    assert out["all"]["neither"] == 3 and out["all"]["neither_sure"] == pytest.approx(2 / 3)


def test_evaluate_reports_which_decisions_hold_under_other_tone_curves():
    """tone_kept: of the samples decided at 0.995, the share still decided the same way with the grey plane raised
    to 2 and to 1/2 (the run-time check decide_tone_gamma 2)."""
    from spacepose.tools.train_flip import evaluate

    class Grey(torch.nn.Module):                      # logit = 20 (g - 0.5), g the grey plane's first pixel
        def forward(self, views):
            return 20.0 * (views[:, 0, 0, 0] - 0.5)

    views = np.zeros((5, 3, 4, 4), np.float32)
    # 1.0: sure at every tone; 0.9: 8 -> 6.2 / 9.0, holds; 0.8: 6 -> 2.8 at g 2, does not; 0.5: undecided;
    # 0.1: sure the other way (-8), and at 0.01 / 0.316 (-9.8 / -3.7) not at g 1/2
    views[:, 0] = np.array([1.0, 0.9, 0.8, 0.5, 0.1], np.float32)[:, None, None]
    out = evaluate(Grey(), views, np.ones(5, np.float32), np.array(["a", "a", "b", "b", "b"]))
    assert out["all"]["decided"] == pytest.approx(4 / 5) and out["all"]["tone_kept"] == pytest.approx(2 / 4)
    assert out["a"]["tone_kept"] == 1.0 and out["b"]["tone_kept"] == 0.0


def test_evaluate_counts_the_wrong_decisions_the_runtime_would_make():
    """kept_wrong / kept_neither: decisions at 0.995 that hold at the tone powers 2 and 1/2 (what the runtime
    reports) on the wrong pose, or on a pair where neither pose is right; a wrong decision that the tone check
    refuses is not counted."""
    from spacepose.tools.train_flip import evaluate

    class Grey(torch.nn.Module):                      # logit = 20 (g - 0.5), as above
        def forward(self, views):
            return 20.0 * (views[:, 0, 0, 0] - 0.5)

    views = np.zeros((6, 3, 4, 4), np.float32)
    # 1.0 and 0.9 hold (pose A); 0.8 is decided but refused by the tone check; 0.5 undecided; 1.0 again, neither
    views[:, 0] = np.array([1.0, 0.9, 0.8, 0.5, 0.1, 1.0], np.float32)[:, None, None]
    labels = np.array([1.0, 0.0, 0.0, 0.0, 0.0, 0.5], np.float32)   # 0.9 and 0.8 decide A where B is right
    out = evaluate(Grey(), views, labels, np.array(["a"] * 6))
    assert out["all"]["kept_wrong"] == 1 and out["all"]["kept_neither"] == 1
    right = evaluate(Grey(), views[:5], np.array([1.0, 1.0, 1.0, 0.0, 0.0], np.float32), np.array(["a"] * 5))
    assert right["all"]["kept_wrong"] == 0 and "kept_neither" not in right["all"]


def test_the_tone_loss_asks_the_toned_logit_to_be_as_sure_on_the_same_side():
    from spacepose.tools.train_flip import TONE_CLIP, tone_loss

    a = torch.tensor([1.0, 5.0, 20.0, -3.0, 4.0], requires_grad=True)
    b = torch.tensor([1.0, 2.0, 6.0, 3.0, 7.0], requires_grad=True)
    loss = tone_loss(a, b)
    # short by 0, 3, 2 (20 clips to 8), 6 (the other side), 0 (surer is fine)
    assert TONE_CLIP == 8.0 and float(loss.detach()) == pytest.approx((0 + 9 + 4 + 36 + 0) / 5)
    loss.backward()
    assert a.grad is None or not a.grad.any()                    # the logit as rendered is the target, held constant
    assert b.grad.tolist() == pytest.approx([0.0, -1.2, -0.8, 2.4, 0.0])


@pytest.fixture(scope="module")
def plate_bundle(tmp_path_factory):
    from _bundle_fixtures import make_bundle, manifest

    pts = _plate_points()
    target = dict(manifest()["target"], silhouette_points=pts.tolist())
    return make_bundle(tmp_path_factory.mktemp("plate") / "b", manifest_overrides={"target": target})


def test_train_resume_and_export(synthetic_dataset, plate_bundle, tmp_path):
    from spacepose.onnx_session import make_session

    out = tmp_path / "run"
    args = ["train-flip", str(synthetic_dataset), "--val", str(synthetic_dataset), "--out", str(out), "--bundle",
            str(plate_bundle), "--size", "32", "--batch", "4", "--per-frame", "2", "--val-frames", "4",
            "--ckpt-every", "3", "--val-every", "3"]
    assert main(args + ["--steps", "3"]) == 0
    assert main(args + ["--steps", "3"]) == 2                     # refuses to overwrite without --resume
    assert main(args + ["--steps", "6", "--resume", "--per-frame", "3"]) == 2   # not the cache's settings
    assert main(args + ["--steps", "6", "--resume", "--neither-prob", "0.2"]) == 2
    assert main(args + ["--steps", "6", "--resume"]) == 0
    ckpt = torch.load(out / "last.pt", weights_only=False)
    assert ckpt["step"] == 6 and ckpt["kind"] == "flip"
    log = [json.loads(line) for line in (out / "log.jsonl").read_text().splitlines()]
    assert [e["step"] for e in log if "val" in e] == [3, 6] and 0.0 <= log[-1]["val"]["all"]["accuracy"] <= 1.0

    tuned = tmp_path / "tuned"     # a fine-tune from those weights, with neither samples
    assert main(args[:5] + [str(tuned)] + args[6:] + ["--steps", "1", "--init", str(out / "last.pt"),
                                                      "--neither-prob", "0.5", "--val-frames", "8", "--seed", "5"]) == 0
    first = torch.load(tuned / "last.pt", weights_only=False)
    assert first["step"] == 1 and first["train_config"]["neither_prob"] == "0.5"
    weights = [k for k, v in ckpt["model"].items() if k.endswith("weight") and v.ndim >= 2]
    moved = [float((first["model"][k] - ckpt["model"][k]).abs().max()) for k in weights]
    assert weights and max(moved) < 0.05    # one step from the initial weights, not a fresh draw (another seed)
    assert main(args[:5] + [str(tmp_path / "bad")] + args[6:] + ["--steps", "1", "--neither-prob", "1.5"]) == 2
    assert main(args[:5] + [str(tmp_path / "bad2")] + args[6:] + ["--steps", "1", "--tone-consistency", "-1"]) == 2
    toned = tmp_path / "toned"     # the tone loss trains too, and validation reports tone_kept
    assert main(args[:5] + [str(toned)] + args[6:] + ["--steps", "3", "--tone-consistency", "0.5"]) == 0
    toned_log = [json.loads(line) for line in (toned / "log.jsonl").read_text().splitlines()]
    assert "tone_kept" in toned_log[-1]["val"]["all"]
    assert torch.load(toned / "last.pt", weights_only=False)["train_config"]["tone_consistency"] == "0.5"

    bundle = tmp_path / "bundle"
    bundle.mkdir()
    (bundle / "bundle.json").write_text(json.dumps({"flip_classifier": {"decide_prob": 0.97, "size": 99}}))
    assert main(["export-flip", str(out / "last.pt"), "--out", str(bundle / "flip.onnx")]) == 0
    section = json.loads((bundle / "bundle.json").read_text())["flip_classifier"]
    assert section == {"decide_prob": 0.97, "size": 32, "file": "flip.onnx", "axis": "z"}
    assert main(["export-flip", str(out / "last.pt"), "--out", str(bundle / "flip.onnx")]) == 2   # no --force
    from spacepose.models.flip_net import FlipNet, FlipNetConfig
    from spacepose.onnx_session import session_metadata

    cfg = FlipNetConfig(**{k: tuple(v) if isinstance(v, list) else v for k, v in ckpt["net_config"].items()})
    net = FlipNet(cfg).eval()
    net.load_state_dict(ckpt["model"])
    session = make_session(bundle / "flip.onnx", threads=1)
    meta = session_metadata(session)
    assert meta["kind"] == "flip" and meta["size"] == 32 and meta["axis"] == "z" and meta["steps"] == 6
    v = np.random.default_rng(3).uniform(0, 1, size=(3, 3, 32, 32)).astype(np.float32)
    got = session.run(["logit"], {"views": v})[0]
    with torch.no_grad():
        np.testing.assert_allclose(got, net(torch.from_numpy(v)).numpy(), atol=1e-4)
    swapped = np.ascontiguousarray(v[:, [0, 2, 1]])
    np.testing.assert_allclose(session.run(["logit"], {"views": swapped})[0], -got, atol=1e-5)


def test_a_graph_recovered_to_a_checkpoint_fine_tunes_with_frozen_batchnorms(synthetic_dataset, plate_bundle,
                                                                              tmp_path):
    """recover-checkpoint on a flip graph gives the trained weights back (parity with the graph); train-flip --init
    from it keeps the folded BatchNorms' statistics, also across --resume, and refuses another net config."""
    from spacepose.export.onnx_flip import parity_check
    from spacepose.models.flip_net import FlipNet, FlipNetConfig

    args = ["train-flip", str(synthetic_dataset), "--val", str(synthetic_dataset), "--bundle", str(plate_bundle),
            "--size", "32", "--batch", "4", "--per-frame", "2", "--val-frames", "4", "--ckpt-every", "100",
            "--val-every", "100"]
    assert main(args + ["--out", str(tmp_path / "a"), "--steps", "2"]) == 0
    graph = tmp_path / "b" / "flip.onnx"
    graph.parent.mkdir()
    assert main(["export-flip", str(tmp_path / "a" / "last.pt"), "--out", str(graph)]) == 0
    assert main(["recover-checkpoint", str(graph), "--out", str(tmp_path / "rec.pt")]) == 0
    rec = torch.load(tmp_path / "rec.pt", weights_only=False)
    assert rec["kind"] == "flip" and rec["folded_bn"] and rec["step"] == 2 and rec["parity"] < 1e-4
    net = FlipNet(FlipNetConfig(**{k: tuple(v) if isinstance(v, list) else v for k, v in rec["net_config"].items()}))
    net.load_state_dict(rec["model"])
    assert parity_check(net.eval(), graph) < 1e-4

    tuned = tmp_path / "tuned"
    assert main(args + ["--out", str(tuned), "--steps", "4", "--stop-step", "2", "--init", str(tmp_path / "rec.pt"),
                        "--tone-consistency", "0.5"]) == 0
    assert main(args + ["--out", str(tuned), "--steps", "4", "--resume"]) == 0
    out = torch.load(tuned / "last.pt", weights_only=False)
    assert out["step"] == 4 and out["folded_bn"] == rec["folded_bn"]
    stats = [k for k in rec["model"] if k.endswith(("running_mean", "running_var"))]
    assert stats and all(torch.equal(out["model"][k], rec["model"][k]) for k in stats)
    moved = [k for k in rec["model"] if k.endswith("weight") and not torch.equal(out["model"][k], rec["model"][k])]
    assert moved                                                  # the rest did train
    assert main(args + ["--out", str(tmp_path / "bad"), "--steps", "1", "--init", str(tmp_path / "rec.pt"),
                        "--size", "64"]) == 2                     # another net config


def test_a_stopped_and_resumed_run_is_the_uninterrupted_run(synthetic_dataset, plate_bundle, tmp_path):
    def args(out):
        return ["train-flip", str(synthetic_dataset), "--val", str(synthetic_dataset), "--out", str(out), "--bundle",
                str(plate_bundle), "--size", "32", "--batch", "4", "--per-frame", "2", "--val-frames", "4",
                "--ckpt-every", "100", "--val-every", "100", "--steps", "6"]

    assert main(args(tmp_path / "whole")) == 0
    assert main(args(tmp_path / "parts") + ["--stop-step", "4"]) == 0
    stopped = torch.load(tmp_path / "parts" / "last.pt", weights_only=False)
    assert stopped["step"] == 4
    log = [json.loads(line) for line in (tmp_path / "parts" / "log.jsonl").read_text().splitlines()]
    assert [e["step"] for e in log if "val" in e] == [4]          # the stopped checkpoint is validated
    assert main(args(tmp_path / "parts") + ["--resume"]) == 0
    whole = torch.load(tmp_path / "whole" / "last.pt", weights_only=False)
    parts = torch.load(tmp_path / "parts" / "last.pt", weights_only=False)
    assert parts["step"] == whole["step"] == 6
    assert parts["scheduler"]["last_epoch"] == whole["scheduler"]["last_epoch"]
    for name, value in whole["model"].items():
        torch.testing.assert_close(parts["model"][name], value, rtol=0, atol=1e-6)
    different = [n for n, v in stopped["model"].items() if v.is_floating_point() and not torch.equal(v, whole["model"][n])]
    assert different                                              # steps 5 and 6 did move the weights
    assert main(args(tmp_path / "bad") + ["--stop-step", "-1"]) == 2


def test_export_refuses_a_checkpoint_of_another_kind(tmp_path):
    torch.save({"kind": "pose"}, tmp_path / "x.pt")
    assert main(["export-flip", str(tmp_path / "x.pt"), "--out", str(tmp_path / "flip.onnx")]) == 2
    assert not (tmp_path / "flip.onnx").exists()


def test_more_datasets_add_their_own_cached_samples(synthetic_dataset, plate_bundle, tmp_path):
    from spacepose.tools.flip_data import load_samples, samples_info

    out = tmp_path / "more"
    args = ["train-flip", str(synthetic_dataset), "--more", str(synthetic_dataset), "--val", str(synthetic_dataset),
            "--out", str(out), "--bundle", str(plate_bundle), "--size", "32", "--batch", "4", "--per-frame", "2",
            "--val-frames", "4", "--steps", "1", "--ckpt-every", "1", "--val-every", "1", "--seed", "3"]
    assert main(args) == 0
    first, second = load_samples(out / "train_samples.npz"), load_samples(out / "train_samples_1.npz")
    assert len(second["labels"]) == len(first["labels"]) > 0
    assert samples_info(out / "train_samples_1.npz")["seed"] == 1003      # its own draw of poses
    assert not np.array_equal(first["views"], second["views"])
